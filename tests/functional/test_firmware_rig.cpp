// The board's own rig calibration on the simulated board: a double press, a wand waved for
// some seconds, the rig found, kept on flash, safe from power cuts, and the drift self-check.
#include <cmath>

#include <gtest/gtest.h>

#include "firmware_app/firmware/rig_store.hpp"
#include "tests/functional/firmware_on_sim_board.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/support/rig_knock.hpp"

namespace edgetrack::app {
namespace {

/// Mean number of markers stereo finds per frame over \a frames frames.
double markersPerFrame(Firmware& firmware, int frames) {
    std::size_t markers = 0;
    for (int f = 0; f < frames; ++f) {
        firmware.step();
        markers += firmware.markerPipeline().markers().size();
    }
    return static_cast<double>(markers) / frames;
}

void doublePress(sim::SimBoard& sim, Firmware& firmware) {
    sim.button.press(sim.clock.now(), 100 * kMs);
    sim.button.press(sim.clock.now() + 250 * kMs, 100 * kMs);
    runFrames(firmware, 50);
}

#ifdef EDGETRACK_SLOW_TARGET
constexpr double kWandSeconds = 8.0; // qemu and the sanitizers run many times slower
#else
constexpr double kWandSeconds = 15.0;
#endif

} // namespace

TEST(FirmwareRigCalibration, ADoublePressAndAWandMendAKnockedRigAndKeepItOnFlash) {
    auto sim = makeBoard("wand", 1);
    const StereoRig truth = sim->world.rig();
    // The cameras were knocked: the rig the board starts with is 0.5 degrees and 2 mm off.
    const StereoRig believed = test::knockedRig(truth, 2.0, 0.5);
    FirmwareConfig config;
    config.rig.duration_s = kWandSeconds;
    Firmware firmware(config, sim->board, believed);
    ASSERT_TRUE(firmware.isValid()) << firmware.error();
    firmware.start();
    EXPECT_NE(firmware.flashReport().find("configured rig (no rig on flash"), std::string::npos)
        << firmware.flashReport();
    // The wand's three markers: with the wrong rig, stereo finds few (the epipolar test
    // refuses them) and the self-check says the rig drifted.
    const double before = markersPerFrame(firmware, 200);
    EXPECT_LT(before, 1.5);

    doublePress(*sim, firmware);
    ASSERT_EQ(firmware.state(), FirmwareState::RigCalibrating) << firmware.lastEvent();
    const std::uint64_t ledChanges = sim->statusLed.changes();
    runFrames(firmware, 100);
    EXPECT_GE(sim->statusLed.changes() - ledChanges, 4u) << "two flashes a second";
    // Collecting the wand allocates nothing per frame: its storage was sized at start-up.
    {
        sim::SimUdpSender::Datagram datagram;
        test::AllocationGuard guard;
        for (int f = 0; f < 300; ++f) {
            firmware.step();
            while (sim->udp.takeSent(datagram)) {
            }
        }
        EXPECT_EQ(guard.allocations(), 0u);
        ASSERT_EQ(firmware.state(), FirmwareState::RigCalibrating);
    }
    while (firmware.state() == FirmwareState::RigCalibrating)
        firmware.step();
    ASSERT_EQ(firmware.state(), FirmwareState::RigFinishing) << firmware.lastEvent();
    EXPECT_NE(firmware.lastEvent().find("rig calibration ended by its duration"), std::string::npos)
        << firmware.lastEvent();
    // The solver runs beside the frame loop, which goes on with the old rig.
    const auto begin = std::chrono::steady_clock::now();
    while (firmware.state() == FirmwareState::RigFinishing) {
        stepBesideTheWorker(firmware);
        ASSERT_LT(std::chrono::steady_clock::now() - begin, kFinishingTimeout);
    }
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking);
    std::cout << "[          ] " << firmware.lastEvent() << "\n";
    EXPECT_NE(firmware.lastEvent().find(": new rig in use"), std::string::npos)
        << firmware.lastEvent();
    EXPECT_NE(firmware.lastEvent().find("saved to flash"), std::string::npos);
    EXPECT_EQ(firmware.counters().rigCalibrationsAdopted, 1u);
    EXPECT_TRUE(sim->statusLed.isOn()) << "a good rig: the LED stays on for 1.5 s";
    EXPECT_LT(test::cameraOneTurn_deg(firmware.rig(), truth), 0.01);
    EXPECT_LT(test::cameraOneShift_mm(firmware.rig(), truth), 0.1);

    // Tracking with the new rig: stereo finds the whole wand again.
    const double after = markersPerFrame(firmware, 200);
    std::cout << "[          ] markers per frame: " << before << " with the knocked rig, " << after
              << " with the new one\n";
    EXPECT_GT(after, 2.5);
    EXPECT_LT(firmware.epipolarRms_px(), 0.2);

    // On flash, and in use after a restart.
    RigStore store(sim->rigFlash);
    const Result<StoredRig> stored = store.load();
    ASSERT_TRUE(stored) << stored.error().message;
    EXPECT_LT(test::cameraOneTurn_deg(stored->rig, firmware.rig()), 1e-9);
    firmware.stop();
    Firmware restarted(config, sim->board, believed);
    restarted.start();
    EXPECT_NE(restarted.flashReport().find("rig from flash slot A (save #1)"), std::string::npos)
        << restarted.flashReport();
    EXPECT_LT(test::cameraOneTurn_deg(restarted.rig(), truth), 0.01);
}

TEST(FirmwareRigCalibration, AKnockedRigRaisesTheDriftWarning) {
    auto sim = makeBoard("wand", 2);
    FirmwareConfig config;
    // The cameras moved by 0.1 degrees: markers still match, but off their epipolar lines.
    Firmware firmware(config, sim->board, test::knockedRig(sim->world.rig(), 0.3, 0.1));
    firmware.start();
    runFrames(firmware, 300);
    EXPECT_GT(firmware.epipolarRms_px(), config.rig.driftWarning_px) << firmware.lastEvent();
    EXPECT_EQ(firmware.counters().rigDriftWarnings, 1u);
    EXPECT_NE(firmware.statusReport().find("rig drift warnings"), std::string::npos);

    Firmware calm(config, sim->board, sim->world.rig());
    calm.start();
    runFrames(calm, 300);
    EXPECT_LT(calm.epipolarRms_px(), 0.2);
    EXPECT_EQ(calm.counters().rigDriftWarnings, 0u);
}

TEST(FirmwareRigCalibration, AWandSessionWithoutTheWandLeavesTheRigAlone) {
    auto sim = makeBoard("two_cubes", 1);
    FirmwareConfig config;
    config.rig.duration_s = 2.0;
    Firmware firmware(config, sim->board, sim->world.rig());
    firmware.start();
    doublePress(*sim, firmware);
    ASSERT_EQ(firmware.state(), FirmwareState::RigCalibrating);
    while (firmware.state() == FirmwareState::RigCalibrating)
        firmware.step();
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking);
    EXPECT_NE(firmware.lastEvent().find("too few to calibrate; rig unchanged"), std::string::npos)
        << firmware.lastEvent();
    EXPECT_EQ(firmware.counters().rigCalibrationsFailed, 1u);
    EXPECT_FALSE(RigStore(sim->rigFlash).load());
}

TEST(FirmwareRigCalibration, APowerCutAtEveryWriteOfARigSaveLeavesTheOldOrTheNewRig) {
    const StereoRig oldRig = test::knockedRig(sim::makeRig({}), 1.0, 0.2);
    const StereoRig newRig = sim::makeRig({});
    std::uint64_t operations = 0;
    {
        sim::SimFlash flash(64u << 10, 4096);
        RigStore store(flash);
        ASSERT_TRUE(store.save(oldRig, 0.3));
        const std::uint64_t before = flash.operations();
        ASSERT_TRUE(store.save(newRig, 0.05));
        operations = flash.operations() - before;
    }
    ASSERT_GE(operations, 3u) << "erase, payload, header";
    for (double torn : {0.0, 0.5, 1.0}) {
        int oldLoads = 0, newLoads = 0;
        for (std::uint64_t cut = 0; cut <= operations; ++cut) {
            sim::SimFlash flash(64u << 10, 4096);
            RigStore store(flash);
            ASSERT_TRUE(store.save(test::knockedRig(newRig, 5.0, 1.0), 0.9));
            ASSERT_TRUE(store.save(oldRig, 0.3));
            flash.cutPowerAfter(cut, torn);
            EXPECT_EQ(static_cast<bool>(store.save(newRig, 0.05)), cut >= operations);
            flash.restorePower();
            const Result<StoredRig> loaded = RigStore(flash).load();
            ASSERT_TRUE(loaded) << "cut " << cut << ": " << loaded.error().message;
            const bool isOld = test::cameraOneTurn_deg(loaded->rig, oldRig) < 1e-9 &&
                               loaded->reprojectionRms_px == 0.3;
            const bool isNew = test::cameraOneTurn_deg(loaded->rig, newRig) < 1e-9 &&
                               loaded->reprojectionRms_px == 0.05;
            EXPECT_TRUE(isOld || isNew) << "cut " << cut << ", torn " << torn;
            oldLoads += isOld;
            newLoads += isNew;
        }
        EXPECT_EQ(newLoads, torn == 1.0 ? 2 : 1) << "torn " << torn;
        EXPECT_EQ(oldLoads + newLoads, static_cast<int>(operations) + 1);
    }
}

} // namespace edgetrack::app
