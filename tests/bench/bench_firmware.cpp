// Benchmark of the firmware's frame processing on the simulated board, with and without a burst
// of spurious blobs: the time budget of one frame (10 ms at 100 Hz) against what a frame costs.
#include <memory>

#include <benchmark/benchmark.h>

#include "firmware_app/firmware/firmware.hpp"
#include "hal/sim/sim_board.hpp"
#include "tests/support/sim_models.hpp"

namespace edgetrack::app {
namespace {

/// The firmware's own processing of one frame (blobs, stereo, tracking, output), timed by its
/// stage counters: the simulated cameras' rendering, which a real board does not do, is left out.
void BM_FirmwareFrame(benchmark::State& state) {
    const char* scene = state.range(0) == 0 ? "two_cubes" : "crowd";
    const int burst = static_cast<int>(state.range(1));
    auto sim = std::make_unique<sim::SimBoard>(*sim::makeScene(scene, 9), 9);
    FirmwareConfig config;
    config.can.enabled = true;
    Firmware firmware(config, sim->board, sim->world.rig());
    firmware.start();
    std::vector<NamedModel> models;
    for (MarkerModel& m : test::truthModels(sim->world.scene()))
        models.push_back({std::move(m), "truth"});
    (void)firmware.replaceModels(std::move(models));
    for (int f = 0; f < 100; ++f)
        firmware.step();
    sim->cameras.setSpuriousBurst(burst);
    hal::CanFrame frame;
    sim::SimUdpSender::Datagram datagram;
    double worst_us = 0.0;
    std::uint64_t found = 0;
    std::uint64_t frames = 0;
    for (auto _ : state) {
        firmware.step();
        const double us = firmware.stageTime(Stage::Frame).last_us;
        worst_us = std::max(worst_us, us);
        state.SetIterationTime(us * 1e-6);
        for (const TrackedBody& b : firmware.bodies())
            found += b.found() ? 1u : 0u;
        ++frames;
        while (sim->can.peerReceive(frame)) {
        }
        while (sim->udp.takeSent(datagram)) {
        }
    }
    state.counters["worst_us"] = worst_us;
    state.counters["bodies_found"] =
        frames ? static_cast<double>(found) / static_cast<double>(frames) : 0.0;
    state.counters["blobs_refused"] = static_cast<double>(firmware.counters().blobOverflow);
    state.counters["over_budget"] = static_cast<double>(firmware.counters().framesOverBudget);
}
BENCHMARK(BM_FirmwareFrame)
    ->ArgNames({"crowd", "spurious"})
    ->Args({0, 0})
    ->Args({0, 500})
    ->Args({1, 0})
    ->Args({1, 500})
    ->UseManualTime()
    ->Unit(benchmark::kMicrosecond);

} // namespace
} // namespace edgetrack::app

BENCHMARK_MAIN();
