// Cost of object calibration: three 30-marker cubes, and the crowd of six objects (75 markers in
// view), turned in front of the rig.
//
//   bench_calibration [--benchmark_repetitions=5]
//
// BM_CalibrationFrame is the online stage's typical frame once the models have formed;
// BM_CalibrationSession runs whole 30-s sessions from an empty calibration and reports the mean,
// 99th percentile and worst frame (for three_cubes the start, when every marker in view is one
// object and the clustering works on its densest graph; for the crowd a check for duplicates by
// layout late in the session, with 14 objects alive); BM_Completion is the completion stage of a
// 30-s session, which runs once when the session ends, off the frame loop.
#include <algorithm>
#include <chrono>
#include <optional>
#include <string_view>
#include <vector>

#include <benchmark/benchmark.h>

#include "core/calibration_session.hpp"
#include "core/object_calibrator.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"

using namespace edgetrack;

namespace {

constexpr std::size_t kFrames = 3000;

struct Recording {
    std::vector<double> time_s;
    std::vector<std::vector<Vec3>> points;
};

Recording record(const char* sceneName) {
    std::optional<sim::Scene> scene = sim::makeScene(sceneName, 1);
    const sim::World world(std::move(*scene), 1);
    sim::Random random(7);
    sim::Observation observation;
    Recording r;
    for (std::size_t f = 0; f < kFrames; ++f) {
        world.observe(f, observation);
        r.time_s.push_back(observation.time_s);
        r.points.emplace_back();
        sim::pointsFromObservation(observation, sim::LevelNoise{}, random, r.points.back());
    }
    return r;
}

/// Each scene's frames, rendered once.
const Recording& recordingOf(const char* sceneName) {
    static const Recording threeCubes = record("three_cubes");
    static const Recording crowd = record("crowd");
    return std::string_view(sceneName) == "crowd" ? crowd : threeCubes;
}

void BM_CalibrationFrame(benchmark::State& state, const char* sceneName) {
    const Recording& r = recordingOf(sceneName);
    const CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    const std::size_t warmUp = 1500;
    for (std::size_t f = 0; f < warmUp; ++f)
        calibrator.update(r.time_s[f], r.points[f]);
    std::size_t f = warmUp;
    double markers = 0.0;
    for (auto _ : state) {
        if (f == kFrames) {
            state.PauseTiming();
            calibrator.reset();
            for (f = 0; f < warmUp; ++f)
                calibrator.update(r.time_s[f], r.points[f]);
            state.ResumeTiming();
        }
        calibrator.update(r.time_s[f], r.points[f]);
        markers += static_cast<double>(r.points[f].size());
        ++f;
    }
    state.counters["markers_per_frame"] =
        benchmark::Counter(markers, benchmark::Counter::kAvgIterations);
    state.counters["objects"] = static_cast<double>(calibrator.objectCount());
}
BENCHMARK_CAPTURE(BM_CalibrationFrame, three_cubes, "three_cubes")->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_CalibrationFrame, crowd, "crowd")->Unit(benchmark::kMicrosecond);

void BM_CalibrationSession(benchmark::State& state, const char* sceneName) {
    const Recording& r = recordingOf(sceneName);
    const CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<double> frame_us(kFrames);
    double mean = 0.0, p99 = 0.0, worst = 0.0;
    std::size_t worstFrame = 0;
    for (auto _ : state) {
        calibrator.reset();
        for (std::size_t f = 0; f < kFrames; ++f) {
            const auto start = std::chrono::steady_clock::now();
            calibrator.update(r.time_s[f], r.points[f]);
            frame_us[f] =
                std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start)
                    .count();
        }
        const auto it = std::max_element(frame_us.begin(), frame_us.end());
        worst = *it;
        worstFrame = static_cast<std::size_t>(it - frame_us.begin());
        std::vector<double> sorted = frame_us;
        std::sort(sorted.begin(), sorted.end());
        p99 = sorted[sorted.size() * 99 / 100];
        mean = 0.0;
        for (double t : frame_us)
            mean += t;
        mean /= static_cast<double>(kFrames);
    }
    state.counters["frame_mean_us"] = mean;
    state.counters["frame_p99_us"] = p99;
    state.counters["frame_worst_us"] = worst;
    state.counters["worst_frame"] = static_cast<double>(worstFrame);
    state.counters["models"] = static_cast<double>(calibrator.objectCount());
}
BENCHMARK_CAPTURE(BM_CalibrationSession, three_cubes, "three_cubes")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3);
BENCHMARK_CAPTURE(BM_CalibrationSession, crowd, "crowd")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3);

void BM_Completion(benchmark::State& state, const char* sceneName) {
    const Recording& r = recordingOf(sceneName);
    CalibrationSession session(CalibrationConfig{}, CompletionConfig{}, kFrames, kFrames * 128);
    for (std::size_t f = 0; f < kFrames; ++f)
        session.update(r.time_s[f], r.points[f]);
    std::size_t models = 0;
    for (auto _ : state)
        models = session.complete().size();
    state.counters["models"] = static_cast<double>(models);
}
BENCHMARK_CAPTURE(BM_Completion, three_cubes, "three_cubes")
    ->Unit(benchmark::kMillisecond)
    ->Iterations(3);
BENCHMARK_CAPTURE(BM_Completion, crowd, "crowd")->Unit(benchmark::kMillisecond)->Iterations(3);

} // namespace

BENCHMARK_MAIN();
