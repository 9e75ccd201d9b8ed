// Per-frame cost of model-based tracking, in steady state and with every body lost.
//
//   bench_tracking [--benchmark_filter=...] [--benchmark_repetitions=3]
//
// Frames are the simulator's points (noise 0.05 mm, markers hidden as the cameras would miss
// them) plus random spurious points in the working volume. Models are the true layouts with every
// pair co-visible, which gives the search more candidates than calibrated models do.
//   BM_TwoCubes/spurious:        the paper's case, two 30-marker cubes
//   BM_Crowd/bodies/spurious:    the first N bodies of a six-body crowd (two 7 cm and two 5 cm
//                                cubes, a sphere and a toy car; about 60 markers in view)
// Each runs steady (bodies followed by prediction) and lost (history forgotten before every
// frame, so every body is searched for).
#include <optional>
#include <vector>

#include <benchmark/benchmark.h>

#include "core/model_tracker.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"
#include "tests/support/sim_models.hpp"

using namespace edgetrack;

namespace {

constexpr std::size_t kFrames = 1000;

struct Recording {
    std::vector<MarkerModel> models;
    std::vector<double> time_s;
    std::vector<std::vector<Vec3>> points;
};

sim::Scene twoCubes() {
    sim::Scene scene = *sim::makeScene("three_cubes", 1);
    scene.objects.pop_back();
    return scene;
}

/// The crowd with its three-marker wand (below the four markers a model needs) replaced by a
/// second 5 cm cube, and only its first \a bodies bodies.
sim::Scene crowd(std::size_t bodies) {
    sim::Scene scene = *sim::makeScene("crowd", 1);
    scene.objects[5].object = scene.objects[2].object;
    scene.objects.resize(bodies);
    return scene;
}

Recording record(sim::Scene scene, int spurious) {
    Recording r;
    r.models = test::truthModels(scene);
    const sim::World world(std::move(scene), 1);
    sim::Random random(7);
    sim::Observation observation;
    for (std::size_t f = 0; f < kFrames; ++f) {
        world.observe(f, observation);
        r.time_s.push_back(observation.time_s);
        r.points.emplace_back();
        sim::pointsFromObservation(observation, sim::LevelNoise{}, random, r.points.back());
        for (int i = 0; i < spurious; ++i)
            r.points.back().push_back(Vec3(random.uniform(-200.0, 320.0),
                                           random.uniform(-170.0, 170.0),
                                           random.uniform(450.0, 750.0)));
    }
    return r;
}

void run(benchmark::State& state, const Recording& r, bool lost) {
    ModelTracker tracker(r.models, ModelTrackingConfig{});
    for (std::size_t f = 0; f < 50; ++f)
        tracker.update(r.time_s[f], r.points[f]);
    std::size_t f = 50;
    double markers = 0.0, found = 0.0, frames = 0.0;
    const ModelTrackingCounters before = tracker.counters();
    for (auto _ : state) {
        if (f == kFrames) {
            // The recording starts again: a jump that the next frame's search recovers from.
            state.PauseTiming();
            f = 50;
            tracker.reset();
            state.ResumeTiming();
        }
        if (lost)
            tracker.reset();
        tracker.update(r.time_s[f], r.points[f]);
        markers += static_cast<double>(r.points[f].size());
        for (const TrackedBody& body : tracker.bodies())
            found += body.found() ? 1.0 : 0.0;
        frames += 1.0;
        ++f;
    }
    const ModelTrackingCounters& c = tracker.counters();
    state.counters["points"] = markers / frames;
    state.counters["bodies"] = static_cast<double>(r.models.size());
    state.counters["found"] = found / frames;
    state.counters["budget_out"] =
        static_cast<double>(c.budgetExhausted - before.budgetExhausted) / frames;
}

void BM_TwoCubes(benchmark::State& state) {
    static std::vector<std::optional<Recording>> cache(4);
    const auto spurious = static_cast<int>(state.range(0));
    const auto slot = static_cast<std::size_t>(state.range(0) / 20);
    if (!cache[slot])
        cache[slot] = record(twoCubes(), spurious);
    run(state, *cache[slot], state.range(1) != 0);
}
BENCHMARK(BM_TwoCubes)
    ->ArgNames({"spurious", "lost"})
    ->ArgsProduct({{0, 20}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);

void BM_Crowd(benchmark::State& state) {
    static std::vector<std::optional<Recording>> cache(7 * 8);
    const auto bodies = static_cast<std::size_t>(state.range(0));
    const auto spurious = static_cast<int>(state.range(1));
    const std::size_t slot = bodies * 8 + static_cast<std::size_t>(spurious / 20);
    if (!cache[slot])
        cache[slot] = record(crowd(bodies), spurious);
    run(state, *cache[slot], state.range(2) != 0);
}
BENCHMARK(BM_Crowd)
    ->ArgNames({"bodies", "spurious", "lost"})
    ->ArgsProduct({{1, 2, 4, 6}, {0, 20, 60, 100}, {0, 1}})
    ->Unit(benchmark::kMicrosecond);

} // namespace

BENCHMARK_MAIN();
