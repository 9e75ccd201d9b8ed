// Hardware test of the SocketCAN backend on the kernel's vcan driver (run inside the test VM).
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <poll.h>
#include <string>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <thread>
#include <unistd.h>

#include <gtest/gtest.h>

#include "firmware_app/firmware/can_pose.hpp"
#include "hal/linux/posix_clock.hpp"
#include "hal/linux/socketcan_bus.hpp"
#include "tests/support/dbc.hpp"

namespace edgetrack {
namespace {

using linux_hal::SocketCanBus;
using linux_hal::SocketCanConfig;

constexpr const char* kInterface = "vcan0";

void shell(const std::string& command) {
    ASSERT_EQ(std::system(command.c_str()), 0) << command;
}

/// The other node on the bus: a plain raw socket, as candump or a vehicle controller opens it.
class PeerSocket {
public:
    PeerSocket() {
        fd_ = ::socket(PF_CAN, SOCK_RAW, CAN_RAW);
        const int on = 1;
        ::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on);
        ifreq request{};
        std::strcpy(request.ifr_name, kInterface);
        ::ioctl(fd_, SIOCGIFINDEX, &request);
        sockaddr_can address{};
        address.can_family = AF_CAN;
        address.can_ifindex = request.ifr_ifindex;
        bound_ = ::bind(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) == 0;
    }
    ~PeerSocket() { ::close(fd_); }
    PeerSocket(const PeerSocket&) = delete;
    PeerSocket& operator=(const PeerSocket&) = delete;

    bool isValid() const { return fd_ >= 0 && bound_; }

    /// \brief The next frame within \a timeout_ms. \return false on timeout.
    bool read(hal::CanFrame& frame, int timeout_ms = 1000) {
        pollfd waitFor{fd_, POLLIN, 0};
        if (::poll(&waitFor, 1, timeout_ms) != 1)
            return false;
        canfd_frame raw{};
        const ssize_t got = ::read(fd_, &raw, sizeof raw);
        if (got != CAN_MTU && got != CANFD_MTU)
            return false;
        frame.extended = (raw.can_id & CAN_EFF_FLAG) != 0;
        frame.id = raw.can_id & CAN_EFF_MASK;
        frame.fd = got == CANFD_MTU;
        frame.bitRateSwitch = (raw.flags & CANFD_BRS) != 0;
        frame.length = raw.len;
        std::memcpy(frame.data.data(), raw.data, raw.len);
        return true;
    }

    /// \brief Put an error frame on the bus, as a controller driver reports its state.
    void sendError(canid_t errorClass, std::uint8_t controllerState = 0) {
        can_frame raw{};
        raw.can_id = CAN_ERR_FLAG | errorClass;
        raw.len = CAN_ERR_DLC;
        raw.data[1] = controllerState;
        ASSERT_EQ(::write(fd_, &raw, sizeof raw), static_cast<ssize_t>(sizeof raw));
    }

private:
    int fd_ = -1;
    bool bound_ = false;
};

app::CanPose examplePose() {
    app::CanPose pose;
    pose.body = 1;
    pose.found = true;
    pose.frame = 1234;
    pose.T_rig_from_model.translation_mm = Vec3(12.5, -40.25, 512.0);
    pose.T_rig_from_model.rotation = Quat(Eigen::AngleAxisd(0.3, Vec3(0, 0, 1)));
    pose.markers = 5;
    pose.rms_mm = 0.12;
    pose.latency_s = 0.0042;
    return pose;
}

std::map<std::string, double> decodeByDbc(const hal::CanFrame& frame) {
    static const std::map<std::uint32_t, test::DbcMessage> dbc =
        test::readDbc(test::readText(test::deployedDbc()));
    const auto message = dbc.find(frame.id);
    if (message == dbc.end()) {
        ADD_FAILURE() << "frame 0x" << std::hex << frame.id << " is not in the DBC";
        return {};
    }
    EXPECT_EQ(message->second.fd, frame.fd);
    EXPECT_EQ(message->second.length, frame.length);
    return test::decode(message->second, frame);
}

/// Sends while the state stays \a expected, up to a second: error frames arrive asynchronously.
hal::CanSendResult sendUntilState(SocketCanBus& bus, const hal::CanFrame& frame,
                                  hal::CanState expected) {
    hal::CanSendResult result = bus.send(frame);
    for (int i = 0; i < 100 && bus.state() != expected; ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        result = bus.send(frame);
    }
    return result;
}

/// A frame sent once the interface is back is accepted, ends the Down state and reaches the bus.
void expectSendingResumed(SocketCanBus& bus, const hal::CanFrame& frame) {
    PeerSocket peer;
    EXPECT_EQ(bus.send(frame), hal::CanSendResult::Queued);
    EXPECT_EQ(bus.state(), hal::CanState::ErrorActive);
    hal::CanFrame got;
    ASSERT_TRUE(peer.read(got));
    EXPECT_EQ(got.id, frame.id);
}

class SocketCan : public ::testing::Test {
protected:
    void SetUp() override {
        if (::if_nametoindex(kInterface) == 0)
            GTEST_SKIP() << kInterface << " does not exist: run inside the test VM (guest-can.sh)";
    }
    linux_hal::PosixClock clock_;
};

TEST_F(SocketCan, ClassicPoseFramesDecodeByTheDbcOnAnotherSocket) {
    SocketCanBus bus(SocketCanConfig{kInterface, false}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    PeerSocket peer;
    ASSERT_TRUE(peer.isValid());
    const app::CanPose pose = examplePose();
    for (const hal::CanFrame& frame : app::encodeClassicPose(pose, app::CanPoseLayout{}))
        EXPECT_EQ(bus.send(frame), hal::CanSendResult::Queued);

    std::map<std::string, double> signals;
    hal::CanFrame frame;
    for (int i = 0; i < 3; ++i) {
        ASSERT_TRUE(peer.read(frame)) << "frame " << i << " did not arrive";
        EXPECT_FALSE(frame.fd);
        EXPECT_EQ(frame.id, 0x300u + 3 * pose.body + static_cast<std::uint32_t>(i));
        for (const auto& [name, value] : decodeByDbc(frame))
            signals[name] = value;
    }
    EXPECT_NEAR(signals["PositionX"], 12.5, 0.01);
    EXPECT_NEAR(signals["PositionY"], -40.25, 0.01);
    EXPECT_NEAR(signals["PositionZ"], 512.0, 0.01);
    EXPECT_NEAR(signals["QuatZ"], std::sin(0.15), 1e-4);
    EXPECT_EQ(signals["Found"], 1.0);
    EXPECT_EQ(signals["Counter"], 1234 % 16);
    EXPECT_EQ(bus.counters().sent, 3u);
    EXPECT_EQ(bus.state(), hal::CanState::ErrorActive);
}

TEST_F(SocketCan, FdPoseFrameWithBitRateSwitchDecodesByTheDbc) {
    SocketCanBus bus(SocketCanConfig{kInterface, true}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    PeerSocket peer;
    const app::CanPose pose = examplePose();
    hal::CanFrame sent = app::encodeFdPose(pose, app::CanPoseLayout{});
    ASSERT_TRUE(sent.fd);
    EXPECT_EQ(bus.send(sent), hal::CanSendResult::Queued);

    hal::CanFrame frame;
    ASSERT_TRUE(peer.read(frame));
    EXPECT_TRUE(frame.fd);
    EXPECT_EQ(frame.bitRateSwitch, sent.bitRateSwitch);
    EXPECT_EQ(frame.id, 0x380u + pose.body);
    std::map<std::string, double> signals = decodeByDbc(frame);
    EXPECT_NEAR(signals["PositionX"], 12.5, 0.001);
    EXPECT_NEAR(signals["PositionZ"], 512.0, 0.001);
    EXPECT_EQ(signals["FrameNumber"], 1234.0);
    EXPECT_EQ(signals["Markers"], 5.0);
}

TEST_F(SocketCan, FramesFromTheBusAreReceived) {
    SocketCanBus bus(SocketCanConfig{kInterface, true}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    shell(std::string("cansend ") + kInterface + " 123#DEADBEEF");
    shell(std::string("cansend ") + kInterface + " 1F334455##1112233445566778899aabbcc");
    hal::CanFrame frame;
    std::vector<hal::CanFrame> got;
    for (int i = 0; i < 100 && got.size() < 2; ++i) {
        while (bus.receive(frame))
            got.push_back(frame);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    ASSERT_EQ(got.size(), 2u);
    EXPECT_EQ(got[0].id, 0x123u);
    EXPECT_FALSE(got[0].extended);
    EXPECT_EQ(got[0].length, 4);
    EXPECT_EQ(got[0].data[0], 0xDE);
    EXPECT_EQ(got[1].id, 0x1F334455u);
    EXPECT_TRUE(got[1].extended);
    EXPECT_TRUE(got[1].fd);
    EXPECT_TRUE(got[1].bitRateSwitch);
    EXPECT_EQ(got[1].length, 12);
}

TEST_F(SocketCan, ClassicSocketRefusesFdFramesWithoutSendingThem) {
    SocketCanBus bus(SocketCanConfig{kInterface, false}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    const hal::CanFrame fd = app::encodeFdPose(examplePose(), app::CanPoseLayout{});
    EXPECT_EQ(bus.send(fd), hal::CanSendResult::Invalid);
    EXPECT_EQ(bus.counters().refused, 1u);
}

TEST_F(SocketCan, InterfaceDownIsReportedAndSendingResumesWhenItIsUp) {
    SocketCanBus bus(SocketCanConfig{kInterface, true}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    const hal::CanFrame frame = app::encodeClassicPose(examplePose(), app::CanPoseLayout{})[0];
    ASSERT_EQ(bus.send(frame), hal::CanSendResult::Queued);

    shell(std::string("ip link set ") + kInterface + " down");
    EXPECT_EQ(bus.send(frame), hal::CanSendResult::Down);
    EXPECT_EQ(bus.state(), hal::CanState::Down);
    hal::CanErrorEvent event;
    ASSERT_TRUE(bus.nextError(event));
    EXPECT_EQ(event.state, hal::CanState::Down);
    EXPECT_EQ(bus.send(frame), hal::CanSendResult::Down);

    shell(std::string("ip link set ") + kInterface + " up");
    expectSendingResumed(bus, frame);
    ASSERT_TRUE(bus.nextError(event));
    EXPECT_EQ(event.state, hal::CanState::ErrorActive);
}

TEST_F(SocketCan, RemovedInterfaceIsReboundWhenItComesBack) {
    SocketCanBus bus(SocketCanConfig{kInterface, false}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    const hal::CanFrame frame = app::encodeClassicPose(examplePose(), app::CanPoseLayout{})[2];
    shell(std::string("ip link del ") + kInterface);
    EXPECT_EQ(bus.send(frame), hal::CanSendResult::Down);
    EXPECT_EQ(bus.send(frame), hal::CanSendResult::Down);
    EXPECT_EQ(bus.state(), hal::CanState::Down);

    shell(std::string("ip link add dev ") + kInterface + " type vcan && ip link set " + kInterface +
          " mtu 72 && ip link set " + kInterface + " up");
    expectSendingResumed(bus, frame);
}

TEST_F(SocketCan, ErrorFramesDriveTheStateAndBusOffRefusesSendsUntilRestart) {
    SocketCanBus bus(SocketCanConfig{kInterface, false}, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    PeerSocket peer;
    const hal::CanFrame frame = app::encodeClassicPose(examplePose(), app::CanPoseLayout{})[2];

    peer.sendError(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_WARNING);
    EXPECT_EQ(sendUntilState(bus, frame, hal::CanState::ErrorWarning), hal::CanSendResult::Queued);
    EXPECT_EQ(bus.state(), hal::CanState::ErrorWarning);
    peer.sendError(CAN_ERR_CRTL, CAN_ERR_CRTL_TX_PASSIVE);
    EXPECT_EQ(sendUntilState(bus, frame, hal::CanState::ErrorPassive), hal::CanSendResult::Queued);

    peer.sendError(CAN_ERR_BUSOFF);
    EXPECT_EQ(sendUntilState(bus, frame, hal::CanState::BusOff), hal::CanSendResult::BusOff);
    EXPECT_EQ(bus.send(frame), hal::CanSendResult::BusOff);

    peer.sendError(CAN_ERR_RESTARTED);
    EXPECT_EQ(sendUntilState(bus, frame, hal::CanState::ErrorActive), hal::CanSendResult::Queued);

    std::vector<hal::CanState> states;
    hal::CanErrorEvent event;
    while (bus.nextError(event))
        states.push_back(event.state);
    EXPECT_EQ(states,
              (std::vector<hal::CanState>{hal::CanState::ErrorWarning, hal::CanState::ErrorPassive,
                                          hal::CanState::BusOff, hal::CanState::ErrorActive}));
}

TEST_F(SocketCan, FullKernelQueueKeepsTheNewestFramesInOrder) {
    // A token bucket of 8 frames a second holds frames in the kernel like a busy controller, so
    // writes fail with ENOBUFS or EAGAIN and the backend queues them.
    shell(std::string("tc qdisc replace dev ") + kInterface +
          " root tbf rate 1kbit burst 16 limit 64");
    SocketCanConfig config{kInterface, false};
    config.transmitQueueDepth = 4;
    SocketCanBus bus(config, clock_);
    ASSERT_TRUE(bus.isValid()) << bus.errorText();
    hal::CanFrame frame;
    frame.length = 1;
    int dropped = 0;
    for (std::uint32_t id = 0x100; id < 0x140; ++id) {
        frame.id = id;
        if (bus.send(frame) == hal::CanSendResult::DroppedOldest)
            ++dropped;
    }
    EXPECT_GT(dropped, 0);
    EXPECT_EQ(bus.queued(), 4u);
    EXPECT_EQ(bus.counters().droppedQueueFull, static_cast<std::uint64_t>(dropped));

    shell(std::string("tc qdisc del dev ") + kInterface + " root");
    PeerSocket peer;
    hal::CanFrame got;
    for (int i = 0; i < 100 && bus.queued() > 0; ++i) {
        bus.receive(got);
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    EXPECT_EQ(bus.queued(), 0u);
    // The queue kept the last four frames and sends them in order.
    for (std::uint32_t id = 0x13C; id < 0x140; ++id) {
        ASSERT_TRUE(peer.read(got));
        EXPECT_EQ(got.id, id);
    }
}

TEST_F(SocketCan, MissingInterfaceIsAnErrorAtConstruction) {
    SocketCanBus bus(SocketCanConfig{"nocan7", false}, clock_);
    EXPECT_FALSE(bus.isValid());
    EXPECT_NE(bus.errorText().find("nocan7"), std::string::npos) << bus.errorText();
    EXPECT_EQ(bus.state(), hal::CanState::Down);
}

} // namespace
} // namespace edgetrack
