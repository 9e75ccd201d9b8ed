// Functional tests of field calibration on the simulated board: the button, finishing, preview.
#include <algorithm>
#include <chrono>
#include <iostream>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "hal/linux/posix_udp_sender.hpp"
#include "tests/functional/firmware_on_sim_board.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/support/dbc.hpp"

namespace edgetrack::app {
namespace {

// A DTrack latency is plausible below this (us): these tests check that it is sent where clients
// read it, not how fast the loop runs (bench_firmware does). Under qemu or the sanitizers a frame
// of the online calibration stage takes tens of milliseconds of the host's time.
#ifdef EDGETRACK_SLOW_TARGET
constexpr std::uint32_t kPlausibleLatency_us = 1'000'000;
#else
constexpr std::uint32_t kPlausibleLatency_us = 50'000;
#endif

TEST(FirmwareOnSimBoard, ButtonCalibratesTheTwoCubesSavesThemAndTracksOverUdp) {
    auto sim = makeBoard("two_cubes", 7);
    LoopbackReceiver receiver;
    linux_hal::PosixUdpSender udp;
    ASSERT_TRUE(udp.isValid());
    hal::Board board{sim->clock, sim->cameras,  sim->ledRing, sim->button, sim->statusLed,
                     sim->flash, sim->rigFlash, sim->can,     udp};
    FirmwareConfig config;
    config.udp.destinations = {receiver.endpoint()};
    Firmware firmware(config, board, sim->world.rig());
    ASSERT_TRUE(firmware.isValid()) << firmware.error();
    firmware.start();
    EXPECT_NE(firmware.flashReport().find("no models on flash: slot A empty, slot B empty"),
              std::string::npos)
        << firmware.flashReport();
    runFrames(firmware, 20);
    EXPECT_TRUE(firmware.ready());
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking);

    // A short press (with contact bounce) starts the calibration; the status LED blinks.
    // It counts once the double-press time (0.4 s) has passed without a second press.
    sim->button.press(sim->clock.now(), 150 * kMs, 3);
    runFrames(firmware, 60);
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating) << firmware.lastEvent();
    const std::uint64_t ledChanges = sim->statusLed.changes();
    runFrames(firmware, 100);
    EXPECT_GE(sim->statusLed.changes() - ledChanges, 3u) << "2 Hz blink over one second";
    // The growing models go to the host as DTrack `3d` markers.
    std::size_t previewMarkers = 0;
    for (const ParsedDtrack& frame : receiver.drain())
        previewMarkers = std::max(previewMarkers, frame.markers.size());

    // The user turns the cubes until the models settle; the calibration then ends on its own.
    while (firmware.state() == FirmwareState::Calibrating)
        firmware.step();
    // The models are completed and saved beside the frame loop, which goes on without a stall.
    ASSERT_EQ(firmware.state(), FirmwareState::Finishing) << firmware.lastEvent();
    const std::uint64_t overBudget = firmware.counters().framesOverBudget;
    const auto finishStart = std::chrono::steady_clock::now();
    std::size_t framesWhileFinishing = 0;
    double longestFrame_us = 0.0;
    while (firmware.state() == FirmwareState::Finishing) {
        stepBesideTheWorker(firmware);
        ++framesWhileFinishing;
        longestFrame_us = std::max(longestFrame_us, firmware.stageTime(Stage::Frame).last_us);
        ASSERT_LT(std::chrono::steady_clock::now() - finishStart, kFinishingTimeout);
    }
    std::cout << "[          ] " << framesWhileFinishing << " frames processed while finishing, "
              << firmware.counters().framesOverBudget - overBudget << " over budget, the longest "
              << longestFrame_us * 1e-3 << " ms\n";
    EXPECT_GT(framesWhileFinishing, 0u);
#ifndef EDGETRACK_SLOW_TARGET
    // Completion in the frame loop would make one frame of several hundred ms; another process
    // of a parallel test run may still preempt a frame now and then.
    EXPECT_LE(firmware.counters().framesOverBudget - overBudget, framesWhileFinishing / 100)
        << "frames over budget while the calibration finished";
    EXPECT_LT(longestFrame_us, 100'000.0);
#endif
    for (const ParsedDtrack& frame : receiver.drain())
        previewMarkers = std::max(previewMarkers, frame.markers.size());
    EXPECT_GE(previewMarkers, 10u);
    ASSERT_EQ(firmware.models().size(), 2u) << firmware.lastEvent();
    EXPECT_NE(firmware.lastEvent().find("ended by the models settled after"), std::string::npos)
        << firmware.lastEvent();
    std::cout << "[          ] " << firmware.lastEvent() << "\n";
    EXPECT_NE(firmware.lastEvent().find("2 new, 0 updated; 2 models ("), std::string::npos)
        << firmware.lastEvent();
    // How closely the session fixed each layout, under 0.1 mm for cubes seen for 11 s.
    EXPECT_NE(firmware.lastEvent().find("layouts fixed, RMS: body 0 to 0.0"), std::string::npos)
        << firmware.lastEvent();
    EXPECT_NE(firmware.lastEvent().find(", saved to flash"), std::string::npos)
        << firmware.lastEvent();
    // The status view's flash line says what flash holds now, not what start-up found.
    EXPECT_NE(firmware.flashReport().find("2 models saved to flash"), std::string::npos)
        << firmware.flashReport();
    EXPECT_EQ(firmware.flashReport().find("no models on flash"), std::string::npos)
        << firmware.flashReport();
    // Two cubes are two objects, not pieces of one.
    EXPECT_EQ(firmware.lastEvent().find("pieces of one object"), std::string::npos)
        << firmware.lastEvent();
    EXPECT_EQ(firmware.counters().untiedPieces, 0u);
    EXPECT_EQ(firmware.counters().calibrationsSaved, 1u);
    ModelStore store(sim->flash, MarkerSet::kCapacity);
    Result<StoredModels> stored = store.load();
    ASSERT_TRUE(stored) << stored.error().message;
    EXPECT_EQ(stored->models.size(), 2u);

    // Tracking resumes with the new models: DTrack frames with both bodies arrive and parse.
    std::map<std::uint64_t, std::vector<RigidTransform>> truthByFrame;
    // Frames in which both cubes show the tracker enough markers to find them from scratch (their
    // learnt S_min), in both cameras.
    std::size_t inViewNeeded = 0;
    for (const NamedModel& m : firmware.models())
        inViewNeeded = std::max<std::size_t>(inViewNeeded, m.model.sMin);
    std::set<std::uint64_t> bothInView;
    // Where the scene is when tracking resumes depends on how long the worker took (real time):
    // run on until both cubes have been in view long enough, at least 4 s.
    int steps = 0;
    for (; steps < 400 || (bothInView.size() < 120 && steps < 2000); ++steps) {
        firmware.step();
        const sim::Observation& seen = sim->cameras.lastObservation();
        truthByFrame[firmware.lastFrame()] = seen.objectPoses;
        std::array<std::size_t, 2> inView{};
        for (const sim::MarkerView& m : seen.markers)
            inView[static_cast<std::size_t>(m.object)] += m.visible[0] && m.visible[1] ? 1u : 0u;
        if (inView[0] >= inViewNeeded && inView[1] >= inViewNeeded)
            bothInView.insert(firmware.lastFrame());
    }
    const std::vector<ParsedDtrack> frames = receiver.drain();
    ASSERT_GE(frames.size(), static_cast<std::size_t>(steps) - 10) << "loopback UDP loses nothing";
    std::size_t withBoth = 0;
    std::size_t framesBothInView = 0;
    std::map<std::uint32_t, std::array<std::vector<std::pair<RigidTransform, RigidTransform>>, 2>>
        byBodyAndObject;
    for (const ParsedDtrack& frame : frames) {
        EXPECT_EQ(frame.calibrated, 2u);
        ASSERT_TRUE(frame.ts2.has_value());
        EXPECT_GT(frame.ts2->latency_us, 0u);
        EXPECT_LT(frame.ts2->latency_us, kPlausibleLatency_us);
        if (bothInView.contains(frame.frame)) {
            ++framesBothInView;
            withBoth += frame.bodies.size() == 2 ? 1u : 0u;
        }
        const auto truth = truthByFrame.find(frame.frame);
        if (truth == truthByFrame.end())
            continue;
        for (const DtrackBody& body : frame.bodies)
            for (std::size_t object = 0; object < 2; ++object)
                byBodyAndObject[body.id][object].push_back(
                    {body.T_rig_from_model, truth->second[object]});
    }
    std::cout << "[          ] both bodies sent in " << withBoth << " of " << framesBothInView
              << " frames with both cubes in view\n";
    EXPECT_GE(framesBothInView, 100u);
    EXPECT_GE(withBoth, framesBothInView * 9 / 10) << "both cubes whenever both are in view";
    // Each body is one cube: its pose is a fixed offset from that cube's true pose.
    ASSERT_EQ(byBodyAndObject.size(), 2u);
    std::set<std::size_t> objectsMatched;
    for (const auto& [id, perObject] : byBodyAndObject) {
        const double spread0 = worstOffsetSpread_mm(perObject[0]);
        const double spread1 = worstOffsetSpread_mm(perObject[1]);
        EXPECT_LT(std::min(spread0, spread1), 1.0) << "body " << id;
        objectsMatched.insert(spread0 < spread1 ? 0u : 1u);
    }
    EXPECT_EQ(objectsMatched.size(), 2u) << "the two bodies are the two cubes";
    EXPECT_EQ(sim->statusLed.isOn(), true)
        << "steady on while bodies are tracked; " << stateName(firmware.state()) << ", "
        << firmware.lastEvent();
}

TEST(FirmwareOnSimBoard, ASecondPressEndsTheCalibrationAndAnEmptyOneKeepsTheModels) {
    auto sim = makeBoard("two_cubes", 3);
    hal::Board& board = sim->board;
    // A short press counts once the double-press time has passed: 0.1 s here, so that the
    // session can end before anything is learnt.
    FirmwareConfig config;
    config.gpio.doublePress_s = 0.1;
    Firmware firmware(config, board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    sim->button.press(sim->clock.now(), 100 * kMs);
    runFrames(firmware, 25);
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating);
    // Ended after 0.3 s, before any object is established: nothing learnt, old models stay.
    sim->button.press(sim->clock.now(), 100 * kMs);
    runFrames(firmware, 25);
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking);
    EXPECT_NE(firmware.lastEvent().find("ended by the button after 0."), std::string::npos)
        << firmware.lastEvent();
    EXPECT_NE(firmware.lastEvent().find(": no object learnt; models unchanged"), std::string::npos)
        << firmware.lastEvent();
    EXPECT_EQ(firmware.models().size(), 2u);
    runFrames(firmware, 50);
    EXPECT_EQ(firmware.bodies().size(), 2u);
    EXPECT_TRUE(firmware.bodies()[0].found() || firmware.bodies()[1].found());
}

// Completion and the save run in a worker; a slow flash holds the save so that the test can look
// at the board while it finishes.
TEST(FirmwareOnSimBoard, WhileACalibrationFinishesTheLoopGoesOnAndPressesWaitForIt) {
    auto sim = makeBoard("two_cubes", 7);
    // Only the button ends this session: when the models settle depends on the simulation's last
    // bits (another run on aarch64).
    FirmwareConfig config;
    config.session.minDuration_s = 60.0;
    config.session.maxDuration_s = 60.0;
    Firmware firmware(config, sim->board, sim->world.rig());
    firmware.start();
    runFrames(firmware, 20);
    sim->button.press(sim->clock.now(), 100 * kMs);
    runFrames(firmware, 1200);
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating);
    sim->flash.holdOperations();
    sim->button.press(sim->clock.now(), 100 * kMs);
    const auto begin = std::chrono::steady_clock::now();
    auto stepWhile = [&](auto condition) {
        while (condition()) {
            stepBesideTheWorker(firmware);
            ASSERT_LT(std::chrono::steady_clock::now() - begin, kFinishingTimeout);
        }
    };
    stepWhile([&] { return firmware.state() == FirmwareState::Calibrating; });
    ASSERT_EQ(firmware.state(), FirmwareState::Finishing) << firmware.lastEvent();
    stepWhile([&] { return !sim->flash.operationWaiting(); });
    EXPECT_EQ(firmware.state(), FirmwareState::Finishing) << "the save waits for the flash";

    // Meanwhile frames are processed and the LED shows "finishing": on, dark a quarter second.
    const std::uint64_t framesBefore = firmware.counters().framesProcessed;
    int lit = 0;
    for (int f = 0; f < 300; ++f) {
        firmware.step();
        lit += sim->statusLed.isOn() ? 1 : 0;
    }
    EXPECT_EQ(firmware.counters().framesProcessed, framesBefore + 300);
    EXPECT_GT(lit, 200);
    EXPECT_LT(lit, 260);

    // A short press cannot start a calibration yet; a long press is kept for when it is done.
    sim->button.press(sim->clock.now(), 100 * kMs);
    runFrames(firmware, 60);
    EXPECT_EQ(firmware.state(), FirmwareState::Finishing);
    EXPECT_NE(firmware.lastEvent().find("still finishing"), std::string::npos)
        << firmware.lastEvent();
    const hal::Nanoseconds pressed = sim->clock.now();
    sim->button.press(pressed, 3500 * kMs);
    while (sim->clock.now() < pressed + 3600 * kMs)
        firmware.step();
    EXPECT_EQ(firmware.state(), FirmwareState::Finishing);
    EXPECT_NE(firmware.lastEvent().find("deleted once the calibration has finished"),
              std::string::npos)
        << firmware.lastEvent();

    sim->flash.releaseOperations();
    stepWhile([&] { return firmware.state() == FirmwareState::Finishing; });
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking);
    EXPECT_EQ(firmware.counters().calibrationsSaved, 1u);
    EXPECT_EQ(firmware.counters().modelDeletions, 1u);
    EXPECT_EQ(firmware.models().size(), 0u);
    EXPECT_NE(firmware.lastEvent().find("deleted by the long press meanwhile"), std::string::npos)
        << firmware.lastEvent();
    Firmware restarted(FirmwareConfig{}, sim->board, sim->world.rig());
    restarted.start();
    EXPECT_EQ(restarted.models().size(), 0u) << "the deletion reached flash after the save";
}

// Issue 25: DTrackSDK and VRPN keep their markers until a `3d` line replaces them, so every frame
// carries one; the latency goes where DTrackSDK reads it.
TEST(FirmwareOnSimBoard, AfterACalibrationADtrackClientShowsNoMarkersAndReadsTheLatency) {
    auto sim = makeBoard("two_cubes", 3);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    runFrames(firmware, 20);
    DtrackSdkView client;
    std::size_t datagrams = 0;
    std::size_t withLatency = 0;
    std::size_t previewFrames = 0;
    std::size_t markersAfterTheSession = 0;
    bool sessionBegun = false;
    bool sessionOver = false;
    auto stepAndReceive = [&] {
        firmware.step();
        const bool calibrating = firmware.state() == FirmwareState::Calibrating;
        sessionOver = sessionOver || (sessionBegun && !calibrating);
        sessionBegun = sessionBegun || calibrating;
        for (const ParsedDtrack& frame : takeDtrack(*sim)) {
            client.receive(frame);
            ++datagrams;
            if (client.latency_us && *client.latency_us > 0u &&
                *client.latency_us < kPlausibleLatency_us)
                ++withLatency;
            if (!sessionOver)
                previewFrames += client.markers.empty() ? 0u : 1u;
            else
                markersAfterTheSession += client.markers.size();
        }
    };
    sim->button.press(sim->clock.now(), 100 * kMs);
    while (firmware.state() != FirmwareState::Calibrating)
        stepAndReceive();
    for (int f = 0; f < 600; ++f)
        stepAndReceive();
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating);
    EXPECT_GT(previewFrames, 300u) << "the preview shows the growing models in most frames";
    sim->button.press(sim->clock.now(), 100 * kMs);
    const auto begin = std::chrono::steady_clock::now();
    while (firmware.state() != FirmwareState::Tracking) {
        stepAndReceive();
        leaveTheProcessorToTheWorker();
        ASSERT_LT(std::chrono::steady_clock::now() - begin, kFinishingTimeout);
    }
    for (int f = 0; f < 200; ++f)
        stepAndReceive();
    EXPECT_TRUE(sessionOver);
    EXPECT_EQ(markersAfterTheSession, 0u) << "markers shown after the calibration ended";
    EXPECT_EQ(withLatency, datagrams) << "a frame without its latency";
    EXPECT_GT(datagrams, 800u);
}

// Issue 25: frame N of `run --board sim` is frame N of `edgetrack sim` with the same scene and

TEST(FirmwareOnSimBoard, ALongPressDeletesAllModelsWithAConfirmationPattern) {
    auto sim = makeBoard("two_cubes", 3);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    runFrames(firmware, 20);
    const hal::Nanoseconds pressed = sim->clock.now();
    sim->button.press(pressed, 3500 * kMs);
    // The deletion happens once the press has lasted 3 s, while the button is still held.
    while (sim->clock.now() < pressed + 3100 * kMs)
        firmware.step();
    EXPECT_EQ(firmware.models().size(), 0u);
    EXPECT_EQ(firmware.counters().modelDeletions, 1u);
    const std::uint64_t changes = sim->statusLed.changes();
    while (sim->clock.now() < pressed + 4500 * kMs)
        firmware.step();
    EXPECT_GE(sim->statusLed.changes() - changes, 10u) << "three double flashes";
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking) << "no short press on release";
    // After a restart the flash holds no models either.
    Firmware restarted(FirmwareConfig{}, sim->board, sim->world.rig());
    restarted.start();
    EXPECT_EQ(restarted.models().size(), 0u);
    EXPECT_NE(restarted.flashReport().find("loaded 0 models"), std::string::npos)
        << restarted.flashReport();
}

// A recalibration with the objects' models on the board: three identical cubes, each known. Only
// continuity tells them apart, and a host has fixed things to their frames: each body must stay
// on its own cube, in its own frame, before the session, while it finishes, and after.
TEST(FirmwareOnSimBoard, ARecalibrationKeepsEachKnownCubeOnItsCubeInItsFrameThroughout) {
    auto sim = makeBoard("three_cubes", 5);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    ASSERT_EQ(firmware.models().size(), 3u);

    // The truth models' frames are the cubes' own: a body's pose is its cube's true pose.
    std::map<std::uint32_t, std::size_t> cubeOf;
    struct Worst {
        double mm = 0.0;
        double deg = 0.0;
        std::size_t found = 0;
    };
    std::map<std::string, Worst> worst;
    sim::Observation truth;
    auto record = [&](const std::string& phase) {
        sim->world.observe(firmware.lastFrame(), truth);
        for (const TrackedBody& body : firmware.bodies()) {
            if (!body.found())
                continue;
            if (!cubeOf.contains(body.modelId)) {
                std::size_t nearest = 0;
                for (std::size_t o = 1; o < truth.objectPoses.size(); ++o)
                    if ((truth.objectPoses[o].translation_mm - body.T_rig_from_model.translation_mm)
                            .norm() < (truth.objectPoses[nearest].translation_mm -
                                       body.T_rig_from_model.translation_mm)
                                          .norm())
                        nearest = o;
                cubeOf[body.modelId] = nearest;
            }
            const RigidTransform& own = truth.objectPoses[cubeOf[body.modelId]];
            Worst& w = worst[phase];
            w.mm =
                std::max(w.mm, (own.translation_mm - body.T_rig_from_model.translation_mm).norm());
            w.deg = std::max(
                w.deg, rotationAngleBetween_rad(own.rotation, body.T_rig_from_model.rotation) *
                           180.0 / 3.14159265358979);
            ++w.found;
        }
    };
    for (int i = 0; i < 300; ++i) {
        firmware.step();
        record("before");
    }
    ASSERT_EQ(cubeOf.size(), 3u) << "each known cube found before the session";
    std::set<std::size_t> cubes;
    for (const auto& [id, cube] : cubeOf)
        cubes.insert(cube);
    ASSERT_EQ(cubes.size(), 3u) << "three bodies on three cubes";

    sim->button.press(sim->clock.now(), 150 * kMs);
    runFrames(firmware, 60);
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating) << firmware.lastEvent();
    while (firmware.state() == FirmwareState::Calibrating)
        firmware.step();
    const auto finishStart = std::chrono::steady_clock::now();
    while (firmware.state() == FirmwareState::Finishing) {
        stepBesideTheWorker(firmware);
        record("finishing");
        ASSERT_LT(std::chrono::steady_clock::now() - finishStart, kFinishingTimeout);
    }
    std::cout << "[          ] " << firmware.lastEvent() << "\n";
    EXPECT_NE(firmware.lastEvent().find(" 0 new, "), std::string::npos) << firmware.lastEvent();
    ASSERT_EQ(firmware.models().size(), 3u) << firmware.lastEvent();
    for (std::uint32_t id = 0; id < 3; ++id)
        EXPECT_EQ(firmware.models()[id].model.id, id);
    for (int i = 0; i < 500; ++i) {
        firmware.step();
        record("after");
    }
    for (const char* phase : {"before", "finishing", "after"}) {
        const Worst& w = worst[phase];
        std::cout << "[          ] " << phase << ": " << w.found << " poses, worst " << w.mm
                  << " mm, " << w.deg << " deg from their own cube\n";
        // A swap of two cubes is tens of millimetres, a frame of its own tens of degrees; a
        // pose from a few markers is good to a few tenths.
        EXPECT_LT(w.mm, 2.0) << phase;
        EXPECT_LT(w.deg, 2.0) << phase;
    }
    EXPECT_GT(worst["finishing"].found, 0u);
    EXPECT_GT(worst["after"].found, 1000u) << "three cubes for 500 frames";
}

// Stopping the board in the middle of a session ends it as abandoned, as a state change does.
TEST(FirmwareOnSimBoard, AStopDuringACalibrationCountsItAsAbandoned) {
    auto sim = makeBoard("two_cubes", 3);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    sim->button.press(sim->clock.now(), 150 * kMs);
    runFrames(firmware, 80);
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating) << firmware.lastEvent();
    firmware.stop();
    EXPECT_EQ(firmware.counters().calibrationsAbandoned, 1u);
    EXPECT_NE(firmware.statusReport().find("calibrations abandoned"), std::string::npos);
}

} // namespace
} // namespace edgetrack::app
