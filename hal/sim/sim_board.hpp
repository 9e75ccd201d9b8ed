// The simulated board: every hal device backed by the simulator, wired together (like SITL).
#pragma once

#include <memory>

#include "hal/hal.hpp"
#include "hal/sim/devices.hpp"
#include "hal/sim/sim_camera_pair.hpp"
#include "hal/sim/world.hpp"

namespace edgetrack::sim {

/// \brief Options of the simulated board.
struct SimBoardOptions {
    bool realTime = false;
    int cameraBufferPairs = 4;
    std::size_t flashSize = 1u << 20;
    std::size_t flashEraseBlock = 4096;
    std::size_t rigFlashSize = 64u << 10;
    std::size_t canTransmitQueue = 16;
};

/**
 * \brief Owns one of each simulated device and hands out the hal::Board view of them.
 *
 * Tests keep the concrete devices (sim::SimFlash and so on) to inject faults and read outputs.
 */
class SimBoard {
public:
    SimBoard(Scene scene, std::uint64_t seed, const SimBoardOptions& options = {})
        : world(std::move(scene), seed)
        , clock(options.realTime)
        , cameras(world, clock, ledRing, options.cameraBufferPairs)
        , button(clock)
        , statusLed(clock)
        , flash(options.flashSize, options.flashEraseBlock)
        , rigFlash(options.rigFlashSize, options.flashEraseBlock)
        , can(clock, options.canTransmitQueue)
        , board{clock, cameras, ledRing, button, statusLed, flash, rigFlash, can, udp} {}

    World world;
    SimClock clock;
    SimLedRing ledRing;
    SimCameraPair cameras;
    SimButton button;
    SimStatusLed statusLed;
    SimFlash flash;
    SimFlash rigFlash;
    SimCanBus can;
    SimUdpSender udp;
    hal::Board board;
};

} // namespace edgetrack::sim
