// Benchmark: the simulated cameras' rendering rate of 1280x800 frame pairs on one core.
#include <cstdint>
#include <vector>

#include <benchmark/benchmark.h>

#include "hal/sim/world.hpp"

namespace {

void renderPairs(benchmark::State& state, const char* sceneName) {
    const edgetrack::sim::World world(*edgetrack::sim::makeScene(sceneName, 1), 1);
    const auto& rig = world.scene().rig;
    const edgetrack::sim::FrameRenderer renderer(
        rig.width_px, rig.height_px, world.scene().background_dn, world.scene().noiseSigma_dn, 1);
    std::vector<std::uint8_t> image0(static_cast<std::size_t>(rig.width_px * rig.height_px));
    std::vector<std::uint8_t> image1(image0.size());
    edgetrack::sim::Observation observation;
    std::uint64_t frame = 0;
    for (auto _ : state) {
        world.observe(frame, observation);
        renderer.render(image0, rig.width_px, 0, observation, 1.0, frame);
        renderer.render(image1, rig.width_px, 1, observation, 1.0, frame);
        benchmark::DoNotOptimize(image0.data());
        benchmark::DoNotOptimize(image1.data());
        ++frame;
    }
    state.counters["pairs_per_s"] =
        benchmark::Counter(static_cast<double>(state.iterations()), benchmark::Counter::kIsRate);
}

void BM_RenderPair_TwoCubes(benchmark::State& state) {
    renderPairs(state, "two_cubes");
}
void BM_RenderPair_Crowd(benchmark::State& state) {
    renderPairs(state, "crowd");
}
void BM_RenderPair_Stress(benchmark::State& state) {
    renderPairs(state, "stress");
}
BENCHMARK(BM_RenderPair_TwoCubes)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RenderPair_Crowd)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_RenderPair_Stress)->Unit(benchmark::kMillisecond);

} // namespace

BENCHMARK_MAIN();
