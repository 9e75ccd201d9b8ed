// Functional tests of the firmware on the simulated board: button calibration, flash, outputs.
#include <algorithm>
#include <arpa/inet.h>
#include <chrono>
#include <iostream>
#include <map>
#include <memory>
#include <netinet/in.h>
#include <optional>
#include <set>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>

#include <gtest/gtest.h>

#include "firmware_app/firmware/dtrack.hpp"
#include "firmware_app/firmware/firmware.hpp"
#include "hal/linux/posix_udp_sender.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/sim_board.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/support/dbc.hpp"
#include "tests/support/sim_models.hpp"

namespace edgetrack::app {
namespace {

constexpr hal::Nanoseconds kMs = hal::kNanosecondsPerMillisecond;

/// The longest wait for a calibration to finish in its worker thread (wall time): qemu and the
/// sanitizers run it many times slower.
#ifdef EDGETRACK_SLOW_TARGET
constexpr auto kFinishingTimeout = std::chrono::seconds(900);
#else
constexpr auto kFinishingTimeout = std::chrono::seconds(120);
#endif

/// The pause after each frame while a calibration finishes, as on the board: there the loop waits
/// for its cameras and the worker (nice 10) gets the processor; stepping the simulated board's
/// virtual clock in a busy loop would starve the worker on a loaded machine.
void leaveTheProcessorToTheWorker() {
    std::this_thread::sleep_for(std::chrono::microseconds(500));
}

/// \brief One step of the frame loop while a calibration finishes, paced as on the board.
void stepBesideTheWorker(Firmware& firmware) {
    firmware.step();
    leaveTheProcessorToTheWorker();
}

std::unique_ptr<sim::SimBoard> makeBoard(const char* scene, std::uint64_t seed) {
    std::optional<sim::Scene> s = sim::makeScene(scene, seed);
    EXPECT_TRUE(s.has_value());
    return std::make_unique<sim::SimBoard>(std::move(*s), seed);
}

/// The scene's true layouts as a model set, as `--models` would load them.
std::vector<NamedModel> truthSet(const sim::SimBoard& board) {
    std::vector<NamedModel> set;
    for (MarkerModel& m : test::truthModels(board.world.scene()))
        set.push_back({std::move(m), "truth"});
    return set;
}

std::vector<NamedModel> copySet(const std::vector<NamedModel>& set) {
    std::vector<NamedModel> copy;
    for (const NamedModel& m : set) {
        MarkerModel model(m.model.markers_model_mm.size());
        model.assign(m.model);
        copy.push_back({std::move(model), m.name});
    }
    return copy;
}

/// A UDP socket on 127.0.0.1 that collects what the firmware sends.
class LoopbackReceiver {
public:
    LoopbackReceiver() {
        fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK, 0);
        sockaddr_in address{};
        address.sin_family = AF_INET;
        address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
        int size = 8 << 20;
        ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &size, sizeof size);
        EXPECT_EQ(::bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address), 0);
        socklen_t length = sizeof address;
        ::getsockname(fd_, reinterpret_cast<sockaddr*>(&address), &length);
        port_ = ntohs(address.sin_port);
    }
    ~LoopbackReceiver() { ::close(fd_); }

    hal::UdpEndpoint endpoint() const { return {{127, 0, 0, 1}, port_}; }

    /// \brief Every datagram received so far, parsed as a DTrack client would.
    std::vector<ParsedDtrack> drain() {
        std::vector<ParsedDtrack> frames;
        char buffer[65536];
        while (true) {
            const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
            if (n <= 0)
                break;
            Result<ParsedDtrack> parsed =
                parseDtrack(std::string_view(buffer, static_cast<std::size_t>(n)));
            EXPECT_TRUE(parsed) << parsed.error().message;
            if (parsed)
                frames.push_back(std::move(*parsed));
        }
        return frames;
    }

private:
    int fd_ = -1;
    std::uint16_t port_ = 0;
};

void runFrames(Firmware& firmware, std::uint64_t frames) {
    const std::uint64_t until = firmware.counters().framesProcessed + frames;
    while (firmware.counters().framesProcessed < until)
        firmware.step();
}

/// Per body, the pose relative to one object's true pose stays the same frame after frame.
double worstOffsetSpread_mm(const std::vector<std::pair<RigidTransform, RigidTransform>>& pairs) {
    if (pairs.empty())
        return 1e9;
    const RigidTransform first = pairs.front().second.inverse() * pairs.front().first;
    double worst = 0.0;
    for (const auto& [pose, truth] : pairs)
        worst = std::max(worst,
                         ((truth.inverse() * pose).translation_mm - first.translation_mm).norm());
    return worst;
}

TEST(FirmwareOnSimBoard, ButtonCalibratesTheTwoCubesSavesThemAndTracksOverUdp) {
    auto sim = makeBoard("two_cubes", 7);
    LoopbackReceiver receiver;
    linux_hal::PosixUdpSender udp;
    ASSERT_TRUE(udp.isValid());
    hal::Board board{sim->clock,     sim->cameras, sim->ledRing, sim->button,
                     sim->statusLed, sim->flash,   sim->can,     udp};
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
    sim->button.press(sim->clock.now(), 150 * kMs, 3);
    runFrames(firmware, 30);
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
    EXPECT_NE(firmware.lastEvent().find(", saved to flash"), std::string::npos)
        << firmware.lastEvent();
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
    for (int f = 0; f < 400; ++f) {
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
    ASSERT_GE(frames.size(), 390u) << "loopback UDP loses nothing";
    std::size_t withBoth = 0;
    std::size_t framesBothInView = 0;
    std::map<std::uint32_t, std::array<std::vector<std::pair<RigidTransform, RigidTransform>>, 2>>
        byBodyAndObject;
    for (const ParsedDtrack& frame : frames) {
        EXPECT_EQ(frame.calibrated, 2u);
        ASSERT_TRUE(frame.ts2.has_value());
        EXPECT_GT(frame.ts2->latency_us, 0u);
        EXPECT_LT(frame.ts2->latency_us, 50'000u);
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
    EXPECT_EQ(sim->statusLed.isOn(), true) << "steady on while bodies are tracked";
}

TEST(FirmwareOnSimBoard, ASecondPressEndsTheCalibrationAndAnEmptyOneKeepsTheModels) {
    auto sim = makeBoard("two_cubes", 3);
    hal::Board& board = sim->board;
    Firmware firmware(FirmwareConfig{}, board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    sim->button.press(sim->clock.now(), 100 * kMs);
    runFrames(firmware, 20);
    ASSERT_EQ(firmware.state(), FirmwareState::Calibrating);
    // Ended after 0.3 s, before any object is established: nothing learnt, old models stay.
    sim->button.press(sim->clock.now(), 100 * kMs);
    runFrames(firmware, 20);
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
    runFrames(firmware, 30);
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

/// What a DTrack client built on DTrackSDK shows after each datagram: bodies are replaced by every
/// `6d` line, markers only when a `3d` line arrives, and the latency is that frame's `ts2`.
struct DtrackSdkView {
    std::vector<DtrackMarker> markers;
    std::optional<std::uint32_t> latency_us;

    void receive(const ParsedDtrack& frame) {
        if (frame.hasMarkerLine)
            markers = frame.markers;
        latency_us.reset();
        if (frame.ts2)
            latency_us = frame.ts2->latency_us;
    }
};

/// Every datagram the simulated board's UDP sent since the last call, parsed.
std::vector<ParsedDtrack> takeDtrack(sim::SimBoard& board) {
    std::vector<ParsedDtrack> frames;
    sim::SimUdpSender::Datagram datagram;
    while (board.udp.takeSent(datagram)) {
        Result<ParsedDtrack> parsed = parseDtrack(datagram.text());
        EXPECT_TRUE(parsed) << parsed.error().message;
        if (parsed)
            frames.push_back(std::move(*parsed));
    }
    return frames;
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
            if (client.latency_us && *client.latency_us > 0u && *client.latency_us < 50'000u)
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
// seed, which draws frame N as World::observe(N); its `ts` is that frame's mid-exposure.
TEST(FirmwareOnSimBoard, FrameNumbersAreTheFramesOfASimRecording) {
    constexpr std::uint64_t kSeed = 5;
    auto sim = makeBoard("two_cubes", kSeed);
    const sim::World recording(*sim::makeScene("two_cubes", kSeed), kSeed);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    runFrames(firmware, 300);
    sim::Observation truth;
    auto error_mm = [&](std::uint64_t frame, const DtrackBody& body) {
        recording.observe(frame, truth);
        return (truth.objectPoses[body.id].translation_mm - body.T_rig_from_model.translation_mm)
            .norm();
    };
    std::size_t compared = 0;
    std::size_t closestToItsOwnFrame = 0;
    double worstTimeError_s = 0.0;
    for (const ParsedDtrack& frame : takeDtrack(*sim)) {
        ASSERT_TRUE(frame.ts2.has_value());
        const double utc_s = static_cast<double>(frame.ts2->seconds) +
                             1e-6 * static_cast<double>(frame.ts2->microseconds);
        const double boardTime_s = utc_s - hal::toSeconds(sim->clock.utcOffset());
        worstTimeError_s =
            std::max(worstTimeError_s, std::abs(boardTime_s - recording.frameTime_s(frame.frame)));
        if (frame.frame == 0)
            continue;
        for (const DtrackBody& body : frame.bodies) {
            const double own = error_mm(frame.frame, body);
            ++compared;
            closestToItsOwnFrame +=
                own < error_mm(frame.frame - 1, body) && own < error_mm(frame.frame + 1, body) ? 1u
                                                                                               : 0u;
        }
    }
    EXPECT_GT(compared, 300u);
    EXPECT_GE(closestToItsOwnFrame, compared * 95 / 100)
        << "poses nearer another frame's truth than their own";
    // Camera 1 exposes 50 us after camera 0; the frame's time is between them.
    EXPECT_LT(worstTimeError_s, 100e-6);
}

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

TEST(FirmwareOnSimBoard, APowerCutAtEveryWriteOfAModelSaveLeavesTheOldOrTheNewModels) {
    auto sim = makeBoard("two_cubes", 3);
    const std::vector<NamedModel> full = truthSet(*sim);
    ASSERT_EQ(full.size(), 2u);
    {
        std::vector<NamedModel> oldSet = copySet(full);
        oldSet.pop_back();
        Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
        firmware.start();
        ASSERT_TRUE(firmware.replaceModels(std::move(oldSet)));
    }
    // How many flash operations one save takes.
    const std::vector<std::uint8_t> before = sim->flash.contents();
    const std::uint64_t start = sim->flash.operations();
    {
        Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
        firmware.start();
        ASSERT_TRUE(firmware.replaceModels(copySet(full)));
    }
    const std::uint64_t operations = sim->flash.operations() - start;
    ASSERT_GE(operations, 3u);
    // Half of the cut operation lands (test_model_store also cuts with none and all landed).
    for (std::uint64_t cut = 0; cut < operations; ++cut) {
        for (double torn : {0.5}) {
            sim->flash.contents() = before;
            sim->flash.cutPowerAfter(cut, torn);
            {
                Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
                firmware.start();
                EXPECT_FALSE(firmware.replaceModels(copySet(full))) << "cut at " << cut;
            }
            sim->flash.restorePower();
            Firmware restarted(FirmwareConfig{}, sim->board, sim->world.rig());
            restarted.start();
            const std::size_t count = restarted.models().size();
            EXPECT_TRUE(count == 1 || count == 2)
                << "cut at operation " << cut << " (" << torn << " landed): " << count
                << " models; " << restarted.flashReport();
        }
    }
}

TEST(FirmwareOnSimBoard, BothSlotsCorruptStartsWithNoModelsAndSaysWhy) {
    auto sim = makeBoard("two_cubes", 3);
    {
        Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
        firmware.start();
        ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
        ASSERT_TRUE(firmware.replaceModels(truthSet(*sim))); // both slots hold a set
    }
    const std::size_t half = sim->flash.size() / 2;
    sim->flash.contents()[40] ^= 0x5A;        // slot A's payload
    sim->flash.contents()[half + 10] ^= 0x01; // slot B's header
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    EXPECT_EQ(firmware.models().size(), 0u);
    EXPECT_NE(firmware.flashReport().find("slot A corrupt"), std::string::npos)
        << firmware.flashReport();
    EXPECT_NE(firmware.flashReport().find("slot B corrupt"), std::string::npos)
        << firmware.flashReport();
    runFrames(firmware, 10);
    EXPECT_EQ(firmware.state(), FirmwareState::Tracking);
    EXPECT_TRUE(firmware.ready());
    sim::SimUdpSender::Datagram datagram;
    ASSERT_TRUE(sim->udp.takeSent(datagram));
    Result<ParsedDtrack> parsed = parseDtrack(datagram.text());
    ASSERT_TRUE(parsed) << parsed.error().message;
    EXPECT_EQ(parsed->calibrated, 0u);
    EXPECT_TRUE(parsed->bodies.empty());
}

// The issue asks for 10,000 frames under the allocation guard; the sanitizer and qemu builds run
// a tenth of them, and fewer frames of the CAN and burst cases, as the simulated cameras'
// rendering dominates there.
#ifdef EDGETRACK_SLOW_TARGET
constexpr int kGuardedFrames = 1000;
constexpr int kCanFrames = 100;
constexpr int kBurstFrames = 40;
#else
constexpr int kGuardedFrames = 10000;
constexpr int kCanFrames = 200;
constexpr int kBurstFrames = 100;
#endif

/// Decoded CAN poses of one frame number, by body.
struct CanBody {
    bool found = false;
    Vec3 position_mm = Vec3::Zero();
    Quat rotation = Quat::Identity();
};

void expectCanMatchesUdp(bool fd) {
    auto sim = makeBoard("two_cubes", 4);
    FirmwareConfig config;
    config.can.enabled = true;
    config.can.fd = fd;
    Firmware firmware(config, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    const std::map<std::uint32_t, test::DbcMessage> dbc =
        test::readDbc(test::readText(test::deployedDbc()));
    std::size_t compared = 0;
    for (int f = 0; f < kCanFrames; ++f) {
        firmware.step();
        const std::vector<ParsedDtrack> sent = takeDtrack(*sim);
        ASSERT_FALSE(sent.empty());
        const ParsedDtrack& udpFrame = sent.back();
        std::map<std::uint32_t, std::map<std::string, double>> signals;
        hal::CanFrame frame;
        while (sim->can.peerReceive(frame)) {
            const auto message = dbc.find(frame.id);
            ASSERT_NE(message, dbc.end()) << "frame 0x" << std::hex << frame.id << " not in DBC";
            EXPECT_EQ(message->second.fd, frame.fd);
            const std::uint32_t body =
                fd ? frame.id - 0x380 : (frame.id - 0x300) / 3; // default layout
            for (const auto& [name, value] : test::decode(message->second, frame))
                signals[body][name] = value;
        }
        for (const DtrackBody& body : udpFrame.bodies) {
            ASSERT_TRUE(signals.contains(body.id)) << "body " << body.id << " not on CAN";
            std::map<std::string, double>& s = signals[body.id];
            EXPECT_EQ(s["Found"], 1.0);
            if (fd)
                EXPECT_EQ(static_cast<std::uint64_t>(s["FrameNumber"]), udpFrame.frame);
            else
                EXPECT_EQ(static_cast<std::uint64_t>(s["Counter"]), udpFrame.frame % 16);
            const Vec3 canPosition(s["PositionX"], s["PositionY"], s["PositionZ"]);
            EXPECT_LT((canPosition - body.T_rig_from_model.translation_mm).norm(),
                      fd ? 0.002 : 0.02);
            const Quat q(s["QuatW"], s["QuatX"], s["QuatY"], s["QuatZ"]);
            EXPECT_LT(rotationAngleBetween_rad(q.normalized(), body.T_rig_from_model.rotation),
                      fd ? 1e-4 : 3e-4);
            ++compared;
        }
        for (std::uint32_t id = 0; id < 2; ++id) {
            const bool onUdp = std::any_of(udpFrame.bodies.begin(), udpFrame.bodies.end(),
                                           [&](const DtrackBody& b) { return b.id == id; });
            ASSERT_TRUE(signals.contains(id)) << "a lost body still sends its status";
            EXPECT_EQ(signals[id]["Found"], onUdp ? 1.0 : 0.0);
        }
    }
    EXPECT_GE(compared, static_cast<std::size_t>(kCanFrames) * 3 / 2);
}

TEST(FirmwareOnSimBoard, ClassicCanFramesDecodeToTheUdpPoses) {
    expectCanMatchesUdp(false);
}

TEST(FirmwareOnSimBoard, CanFdFramesDecodeToTheUdpPoses) {
    expectCanMatchesUdp(true);
}

TEST(FirmwareOnSimBoard, NoHeapAllocationPerFrame) {
    auto sim = makeBoard("two_cubes", 5);
    FirmwareConfig config;
    config.can.enabled = true;
    Firmware firmware(config, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    runFrames(firmware, 300); // warm-up: every vector reaches its working size
    hal::CanFrame frame;
    sim::SimUdpSender::Datagram datagram;
    test::AllocationGuard guard;
    for (int f = 0; f < kGuardedFrames; ++f) {
        firmware.step();
        while (sim->can.peerReceive(frame)) {
        }
        while (sim->udp.takeSent(datagram)) {
        }
    }
    EXPECT_EQ(guard.allocations(), 0u);
    EXPECT_EQ(firmware.counters().framesProcessed, 300u + kGuardedFrames);
    EXPECT_GE(firmware.outputCounters().udpSent, 300u + kGuardedFrames);
    EXPECT_GE(firmware.outputCounters().canSent, 2u * kGuardedFrames);
}

TEST(FirmwareOnSimBoard, ABurstOfSpuriousBlobsIsCountedAndTrackingHolds) {
    auto sim = makeBoard("two_cubes", 6);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    runFrames(firmware, 100);
    sim->cameras.setSpuriousBurst(500);
    runFrames(firmware, kBurstFrames);
    sim->cameras.setSpuriousBurst(0);
    // 500 reflections per image against 256 blobs kept: the rest are counted, not stored. (The
    // detector keeps blobs from the top of the image down, so markers low in the image are lost
    // during such a burst; bench_firmware measures what the burst costs.)
    EXPECT_GE(firmware.counters().blobOverflow, kBurstFrames * 2u * 200u);
    EXPECT_EQ(firmware.counters().framesProcessed, 100u + kBurstFrames)
        << "no frame lost to the burst";
    EXPECT_EQ(firmware.counters().framesDroppedQueue, 0u);
    // Once the burst is over the cubes are found again within a few frames.
    runFrames(firmware, 20);
    EXPECT_TRUE(firmware.bodies()[0].found() && firmware.bodies()[1].found());
}

TEST(FirmwareOnSimBoard, CamerasThatStopPutTheBoardInTheDegradedStateUntilTheyReturn) {
    auto sim = makeBoard("two_cubes", 3);
    FirmwareConfig config;
    Firmware firmware(config, sim->board, sim->world.rig());
    firmware.start();
    runFrames(firmware, 20);
    sim->cameras.setStalled(true);
    const hal::Nanoseconds stalled = sim->clock.now();
    while (firmware.state() != FirmwareState::Degraded &&
           sim->clock.now() < stalled + 2 * hal::kNanosecondsPerSecond)
        firmware.step();
    ASSERT_EQ(firmware.state(), FirmwareState::Degraded);
    EXPECT_FALSE(firmware.ready());
    EXPECT_NE(firmware.lastEvent().find("no frames from the cameras"), std::string::npos)
        << firmware.lastEvent();
    // Still stalled: the retries fail and the board stays degraded, blinking fast.
    const std::uint64_t changes = sim->statusLed.changes();
    while (sim->clock.now() < stalled + 3 * hal::kNanosecondsPerSecond)
        firmware.step();
    EXPECT_GE(sim->statusLed.changes() - changes, 8u);
    EXPECT_GE(firmware.counters().cameraRestarts, 1u);
    sim->cameras.setStalled(false);
    while (firmware.state() != FirmwareState::Tracking &&
           sim->clock.now() < stalled + 6 * hal::kNanosecondsPerSecond)
        firmware.step();
    ASSERT_EQ(firmware.state(), FirmwareState::Tracking) << firmware.lastEvent();
    const std::uint64_t processed = firmware.counters().framesProcessed;
    runFrames(firmware, 10);
    EXPECT_EQ(firmware.counters().framesProcessed, processed + 10);
    EXPECT_TRUE(firmware.ready());
}

TEST(FirmwareOnSimBoard, WhenProcessingLagsTheOldestQueuedFrameIsDroppedNotCapture) {
    auto sim = makeBoard("two_cubes", 3);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    ASSERT_TRUE(firmware.replaceModels(truthSet(*sim)));
    runFrames(firmware, 20);
    // Every frame now takes 35 ms to process (3.5 frame periods): several exposures complete
    // during each, and capture takes them all while the queue keeps only the newest two.
    std::uint64_t lastProcessed = firmware.lastFrame();
    for (int f = 0; f < 50; ++f) {
        firmware.step();
        EXPECT_GE(firmware.lastFrame(), lastProcessed + 1);
        lastProcessed = firmware.lastFrame();
        sim->clock.advanceTo(sim->clock.now() + 35 * kMs);
    }
    const hal::CameraPairCounters camera = sim->cameras.counters();
    EXPECT_EQ(camera.droppedNoBuffer, 0u) << "capture always had a free buffer";
    EXPECT_GE(firmware.counters().framesDroppedQueue, 100u);
    // Every delivered frame was processed, dropped from the queue, or is still queued (at most 2).
    const std::uint64_t handled =
        firmware.counters().framesProcessed + firmware.counters().framesDroppedQueue;
    EXPECT_LE(handled, camera.delivered);
    EXPECT_LE(camera.delivered - handled, 2u);
    // The frames that are processed are recent: at most two frames (the queue) behind capture.
    EXPECT_GE(firmware.lastFrame() + 3, camera.delivered - 1);
    EXPECT_TRUE(firmware.bodies()[0].found() || firmware.bodies()[1].found());
}

TEST(FirmwareOnSimBoard, AFrameWithoutItsPartnerIsDroppedAndCounted) {
    auto sim = makeBoard("two_cubes", 3);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    sim->cameras.dropPartnerEvery(10);
    runFrames(firmware, 90);
    EXPECT_EQ(sim->cameras.counters().droppedUnpaired, 10u);
    EXPECT_EQ(firmware.counters().framesProcessed, 90u);
    const std::string report = firmware.statusReport();
    EXPECT_NE(report.find("frames dropped: unpaired           10"), std::string::npos) << report;
}

TEST(FirmwareOnSimBoard, TheStrobeLightsEveryExposureAndOnlyThen) {
    auto sim = makeBoard("two_cubes", 3);
    Firmware firmware(FirmwareConfig{}, sim->board, sim->world.rig());
    firmware.start();
    runFrames(firmware, 5);
    EXPECT_FALSE(sim->ledRing.continuous()) << "pulses once the exposure timing is known";
    for (int f = 0; f < 50; ++f) {
        firmware.step();
        const hal::Nanoseconds next = sim->cameras.nextExposureStart();
        const hal::Nanoseconds exposure = sim->cameras.exposureDuration();
        EXPECT_DOUBLE_EQ(sim->ledRing.litFraction(next, next + exposure), 1.0);
        EXPECT_DOUBLE_EQ(sim->ledRing.litFraction(next - 4 * kMs, next - 1 * kMs), 0.0)
            << "dark between exposures";
    }
    EXPECT_EQ(firmware.counters().strobePulsesRefused, 0u);
}

} // namespace
} // namespace edgetrack::app
