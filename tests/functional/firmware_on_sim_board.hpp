// What the firmware's functional tests share: the simulated board, a UDP receiver, pacing.
#pragma once

#include <algorithm>
#include <arpa/inet.h>
#include <chrono>
#include <memory>
#include <netinet/in.h>
#include <optional>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include "firmware_app/firmware/dtrack.hpp"
#include "firmware_app/firmware/firmware.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/sim_board.hpp"
#include "tests/support/sim_models.hpp"

namespace edgetrack::app {

inline constexpr hal::Nanoseconds kMs = hal::kNanosecondsPerMillisecond;

/// The longest wait for a calibration to finish in its worker thread (wall time): qemu and the
/// sanitizers run it many times slower.
#ifdef EDGETRACK_SLOW_TARGET
inline constexpr auto kFinishingTimeout = std::chrono::seconds(900);
#else
inline constexpr auto kFinishingTimeout = std::chrono::seconds(120);
#endif

/// The pause after each frame while a calibration finishes, as on the board: there the loop waits
/// for its cameras and the worker (nice 10) gets the processor; stepping the simulated board's
/// virtual clock in a busy loop would starve the worker on a loaded machine.
inline void leaveTheProcessorToTheWorker() {
    std::this_thread::sleep_for(std::chrono::microseconds(500));
}

/// \brief One step of the frame loop while a calibration finishes, paced as on the board.
inline void stepBesideTheWorker(Firmware& firmware) {
    firmware.step();
    leaveTheProcessorToTheWorker();
}

inline std::unique_ptr<sim::SimBoard> makeBoard(const char* scene, std::uint64_t seed) {
    std::optional<sim::Scene> s = sim::makeScene(scene, seed);
    EXPECT_TRUE(s.has_value());
    return std::make_unique<sim::SimBoard>(std::move(*s), seed);
}

/// The scene's true layouts as a model set, as `--models` would load them.
inline std::vector<NamedModel> truthSet(const sim::SimBoard& board) {
    std::vector<NamedModel> set;
    for (MarkerModel& m : test::truthModels(board.world.scene()))
        set.push_back({std::move(m), "truth"});
    return set;
}

inline std::vector<NamedModel> copySet(const std::vector<NamedModel>& set) {
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

inline void runFrames(Firmware& firmware, std::uint64_t frames) {
    const std::uint64_t until = firmware.counters().framesProcessed + frames;
    while (firmware.counters().framesProcessed < until)
        firmware.step();
}

/// Per body, the pose relative to one object's true pose stays the same frame after frame.
inline double
worstOffsetSpread_mm(const std::vector<std::pair<RigidTransform, RigidTransform>>& pairs) {
    if (pairs.empty())
        return 1e9;
    const RigidTransform first = pairs.front().second.inverse() * pairs.front().first;
    double worst = 0.0;
    for (const auto& [pose, truth] : pairs)
        worst = std::max(worst,
                         ((truth.inverse() * pose).translation_mm - first.translation_mm).norm());
    return worst;
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
inline std::vector<ParsedDtrack> takeDtrack(sim::SimBoard& board) {
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

} // namespace edgetrack::app
