// Benchmark: the NEON pixel-statistics pass over a 1280x800 frame beside a plain read of its bytes.
#include <cstdint>
#include <numeric>
#include <vector>

#include <benchmark/benchmark.h>

#include "core/pixel_stats.hpp"
#include "core/simd/neon.hpp"

namespace {

std::vector<std::uint8_t> makeFrame() {
    std::vector<std::uint8_t> frame(1280u * 800u);
    std::uint32_t state = 12345;
    for (auto& p : frame) {
        state = state * 1664525u + 1013904223u;
        p = static_cast<std::uint8_t>(state >> 24);
    }
    return frame;
}

void BM_MeasurePixels(benchmark::State& state) {
    const auto frame = makeFrame();
    for (auto _ : state)
        benchmark::DoNotOptimize(edgetrack::measurePixels(frame, 200));
    state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                            static_cast<std::int64_t>(frame.size()));
    state.SetLabel(edgetrack::simd::neonBackendName());
}
BENCHMARK(BM_MeasurePixels);

// The memory floor: summing the bytes touches each once and does the least work possible.
void BM_PlainRead(benchmark::State& state) {
    const auto frame = makeFrame();
    for (auto _ : state)
        benchmark::DoNotOptimize(std::accumulate(frame.begin(), frame.end(), std::uint64_t{0}));
    state.SetBytesProcessed(static_cast<std::int64_t>(state.iterations()) *
                            static_cast<std::int64_t>(frame.size()));
}
BENCHMARK(BM_PlainRead);

} // namespace

BENCHMARK_MAIN();
