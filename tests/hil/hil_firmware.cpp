// Hardware test of `edgetrack run --board linux` on vimc, gpio-sim and vcan0 (run inside the VM).
#include <chrono>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <fcntl.h>
#include <fstream>
#include <linux/can.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <netinet/in.h>
#include <optional>
#include <poll.h>
#include <regex>
#include <sstream>
#include <string>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <sys/un.h>
#include <sys/wait.h>
#include <thread>
#include <unistd.h>
#include <vector>

#include <gtest/gtest.h>

#include "hal/linux/posix_udp_sender.hpp"

namespace edgetrack {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;
using std::chrono::seconds;

const char* const kDir = "/tmp/edgetrack-hil";
const char* const kNotifySocket = "/tmp/edgetrack-hil/notify.sock";
const char* const kConfigFile = "/tmp/edgetrack-hil/edgetrack.toml";
const char* const kRigFile = "/tmp/edgetrack-hil/rig.toml";
const char* const kModelDir = "/tmp/edgetrack-hil/models";
const char* const kOutLog = "/tmp/edgetrack-hil/out.log";
const char* const kErrLog = "/tmp/edgetrack-hil/err.log";

void shell(const std::string& command) {
    const int rc = std::system(command.c_str());
    ASSERT_EQ(rc, 0) << command;
}

std::string readFile(const std::string& path) {
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
}

/// systemd's side of sd_notify: a datagram socket the firmware finds in NOTIFY_SOCKET.
class NotifySocket {
public:
    NotifySocket() {
        ::unlink(kNotifySocket);
        fd_ = ::socket(AF_UNIX, SOCK_DGRAM | SOCK_CLOEXEC, 0);
        sockaddr_un address{};
        address.sun_family = AF_UNIX;
        std::strncpy(address.sun_path, kNotifySocket, sizeof address.sun_path - 1);
        if (::bind(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0) {
            ::close(fd_);
            fd_ = -1;
        }
    }
    ~NotifySocket() {
        if (fd_ >= 0)
            ::close(fd_);
    }
    bool isValid() const { return fd_ >= 0; }

    /// \return whether a message containing \a text arrived within \a timeout; keeps the others.
    bool waitFor(const std::string& text, milliseconds timeout) {
        const auto until = Clock::now() + timeout;
        for (;;) {
            for (const std::string& message : messages_)
                if (message.find(text) != std::string::npos)
                    return true;
            const auto left =
                std::chrono::duration_cast<milliseconds>(until - Clock::now()).count();
            if (left <= 0)
                return false;
            pollfd p{fd_, POLLIN, 0};
            if (::poll(&p, 1, static_cast<int>(left)) <= 0)
                continue;
            char buffer[4096];
            const ssize_t n = ::recv(fd_, buffer, sizeof buffer, 0);
            if (n > 0)
                messages_.emplace_back(buffer, static_cast<std::size_t>(n));
        }
    }
    bool received(const std::string& text) { return waitFor(text, milliseconds(0)); }
    void clear() { messages_.clear(); }

private:
    int fd_ = -1;
    std::vector<std::string> messages_;
};

/// A node on vcan0 that counts the pose frames of one identifier.
class CanListener {
public:
    CanListener() {
        fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
        ifreq request{};
        std::strncpy(request.ifr_name, "vcan0", IFNAMSIZ - 1);
        ::ioctl(fd_, SIOCGIFINDEX, &request);
        sockaddr_can address{};
        address.can_family = AF_CAN;
        address.can_ifindex = request.ifr_ifindex;
        ::bind(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address);
    }
    ~CanListener() { ::close(fd_); }

    /// \return frames with \a canId received during \a window (not those from before it).
    int count(canid_t canId, milliseconds window) {
        can_frame frame{};
        while (::read(fd_, &frame, sizeof frame) == static_cast<ssize_t>(sizeof frame)) {
        }
        int frames = 0;
        const auto until = Clock::now() + window;
        while (Clock::now() < until) {
            pollfd p{fd_, POLLIN, 50};
            if (::poll(&p, 1, 50) <= 0)
                continue;
            while (::read(fd_, &frame, sizeof frame) == static_cast<ssize_t>(sizeof frame))
                if ((frame.can_id & CAN_SFF_MASK) == canId)
                    ++frames;
        }
        return frames;
    }

private:
    int fd_ = -1;
};

/// The firmware as systemd would run it, output to files under kDir.
class Edgetrack {
public:
    explicit Edgetrack(const std::string& binary) {
        pid_ = ::fork();
        if (pid_ == 0) {
            ::setenv("NOTIFY_SOCKET", kNotifySocket, 1);
            const int out = ::open(kOutLog, O_WRONLY | O_CREAT | O_TRUNC, 0644);
            const int err = ::open(kErrLog, O_WRONLY | O_CREAT | O_TRUNC, 0644);
            ::dup2(out, STDOUT_FILENO);
            ::dup2(err, STDERR_FILENO);
            const int null = ::open("/dev/null", O_RDONLY);
            ::dup2(null, STDIN_FILENO);
            ::execl(binary.c_str(), binary.c_str(), "run", "--board", "linux", "--config",
                    kConfigFile, "--models", kModelDir, static_cast<char*>(nullptr));
            ::_exit(127);
        }
    }
    ~Edgetrack() {
        if (pid_ > 0 && !exited_) {
            ::kill(pid_, SIGKILL);
            ::waitpid(pid_, nullptr, 0);
        }
    }

    /// \return the exit code, or nullopt when it still runs after \a timeout.
    std::optional<int> waitExit(milliseconds timeout) {
        const auto until = Clock::now() + timeout;
        while (Clock::now() < until) {
            int status = 0;
            if (::waitpid(pid_, &status, WNOHANG) == pid_) {
                exited_ = true;
                return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
            }
            std::this_thread::sleep_for(milliseconds(50));
        }
        return std::nullopt;
    }
    std::optional<int> terminate(milliseconds timeout) {
        ::kill(pid_, SIGTERM);
        return waitExit(timeout);
    }
    static std::string out() { return readFile(kOutLog); }
    static std::string err() { return readFile(kErrLog); }

private:
    pid_t pid_ = -1;
    bool exited_ = false;
};

class LinuxBoardFirmware : public ::testing::Test {
protected:
    void SetUp() override {
        const char* binary = std::getenv("EDGETRACK_BINARY");
        const char* chip = std::getenv("EDGETRACK_GPIO_CHIP");
        const char* camera0 = std::getenv("EDGETRACK_CAMERA0");
        const char* camera1 = std::getenv("EDGETRACK_CAMERA1");
        if (!binary || !chip || !camera0 || !camera1 || !std::getenv("EDGETRACK_GPIO_SYSFS"))
            GTEST_SKIP() << "no simulated board: run inside the test VM (guest-firmware.sh)";
        binary_ = binary;
        chip_ = chip;
        sysfs_ = std::getenv("EDGETRACK_GPIO_SYSFS");
        shell(std::string("rm -rf ") + kDir + " && mkdir -p " + kModelDir);
        std::ofstream config(kConfigFile);
        // vimc's two instances run free (not triggered together) at 15-30 Hz under TCG.
        config << "[cameras]\ncamera0_id = \"" << camera0 << "\"\ncamera1_id = \"" << camera1
               << "\"\nwidth_px = 480\nheight_px = 360\nframe_rate_hz = 15.0\n"
                  "pair_tolerance_us = 100000.0\ntimeout_s = 3.0\nretry_s = 1.0\n"
                  "rig = \""
               << kRigFile << "\"\n"
               << "[gpio]\nchip = \"" << chip << "\"\ndebounce_ms = 30.0\n"
               << "[flash]\ndevice = \"/tmp/edgetrack-hil/models.flash\"\n"
                  "rig_device = \"/tmp/edgetrack-hil/rig.flash\"\n"
               << "[output.udp]\ndestinations = [\"127.0.0.1:5000\"]\n"
               << "[output.can]\nenabled = true\ninterface = \"vcan0\"\n"
               << "[health]\nstatus_interval_s = 0.25\n";
        std::ofstream rig(kRigFile);
        for (int c = 0; c < 2; ++c)
            rig << "[[camera]]\nwidth = 480\nheight = 360\nfx = 500.0\nfy = 500.0\ncx = 240.0\n"
                   "cy = 180.0\ndistortion = [0.0, 0.0, 0.0, 0.0, 0.0]\n"
                   "rotation = [1, 0, 0, 0, 1, 0, 0, 0, 1]\ntranslation = ["
                << (c == 0 ? "0.0" : "-100.0") << ", 0.0, 0.0]\n";
        // One body (id 1: CAN frames 0x303-0x305) that vimc's test pattern never shows: the
        // firmware sends its status frame, "not found", every frame while tracking.
        std::ofstream model(std::string(kModelDir) + "/body_1.json");
        model << R"({ "id": 1, "name": "tetrahedron",
  "markers": [[0, 0, 0], [60, 0, 0], [0, 45, 0], [0, 0, 30]],
  "edges": [[0, 1, 60], [0, 2, 45], [0, 3, 30], [1, 2, 75], [1, 3, 67.082], [2, 3, 54.083]],
  "s_min": 4 })";
    }

    void setButtonPressed(bool pressed) {
        // Active low with a pull-up: pressing pulls the line down.
        std::ofstream pull(sysfs_ + "/sim_gpio1/pull");
        pull << (pressed ? "pull-down" : "pull-up");
    }
    void shortPress() {
        setButtonPressed(true);
        std::this_thread::sleep_for(milliseconds(300));
        setButtonPressed(false);
    }

    std::string binary_, chip_, sysfs_;
};

TEST_F(LinuxBoardFirmware, ReadyOnlyOnceCamerasGpioAndCanAreUpThenCalibratesOnTheButton) {
    NotifySocket notify;
    ASSERT_TRUE(notify.isValid());
    // Start with the right camera unplugged, vcan0 down and the status LED line held elsewhere.
    shell("echo vimc.1 > /sys/bus/platform/drivers/vimc/unbind");
    shell("ip link set vcan0 down");
    shell("gpioset --mode=signal " + chip_ + " 2=0 & echo $! > /tmp/edgetrack-hil/gpioset.pid");
    Edgetrack firmware(binary_);

    ASSERT_TRUE(notify.waitFor("STATUS=degraded", seconds(20))) << Edgetrack::err();
    shell("echo vimc.1 > /sys/bus/platform/drivers/vimc/bind");
    ASSERT_TRUE(notify.waitFor("STATUS=tracking", seconds(20))) << "the cameras did not come back\n"
                                                                << Edgetrack::err();
    EXPECT_FALSE(notify.waitFor("READY=1", seconds(2))) << "READY=1 with CAN and GPIO missing";
    shell("ip link set vcan0 up");
    EXPECT_FALSE(notify.waitFor("READY=1", seconds(2))) << "READY=1 with a GPIO line missing";
    shell("kill $(cat /tmp/edgetrack-hil/gpioset.pid)");
    ASSERT_TRUE(notify.waitFor("READY=1", seconds(10))) << Edgetrack::err();
    const std::string waited = Edgetrack::err();
    EXPECT_NE(waited.find("waiting for "), std::string::npos) << waited;
    EXPECT_NE(waited.find("CAN vcan0 is down"), std::string::npos) << waited;
    EXPECT_NE(waited.find("status LED line"), std::string::npos) << waited;

    // Tracking one body that is not in view: its status frame every frame.
    CanListener can;
    EXPECT_GT(can.count(0x305, seconds(2)), 3) << "no pose status frames on vcan0";

    // A short press starts a field calibration; another ends it (nothing learnt).
    notify.clear();
    shortPress();
    ASSERT_TRUE(notify.waitFor("STATUS=calibrating", seconds(10))) << Edgetrack::err();
    EXPECT_EQ(can.count(0x305, seconds(1)), 0) << "pose frames while calibrating";
    notify.clear();
    shortPress();
    ASSERT_TRUE(notify.waitFor("STATUS=tracking", seconds(10))) << Edgetrack::err();
    EXPECT_GT(can.count(0x305, seconds(2)), 3) << "tracking did not resume on CAN";

    const std::optional<int> exit = firmware.terminate(seconds(10));
    ASSERT_TRUE(exit.has_value()) << "edgetrack did not stop on SIGTERM";
    EXPECT_EQ(*exit, 0) << Edgetrack::err();
    const std::string report = Edgetrack::out();
    EXPECT_NE(report.find("ready (cameras, GPIO, CAN up)"), std::string::npos) << report;
    EXPECT_TRUE(std::regex_search(report, std::regex("calibrations started +1\n"))) << report;
    EXPECT_NE(report.find("CAN vcan0: error active"), std::string::npos) << report;
    std::cout << report;
}

TEST_F(LinuxBoardFirmware, ACameraRemovedWhileRunningEndsTheProcessForSystemdToRestart) {
    NotifySocket notify;
    ASSERT_TRUE(notify.isValid());
    Edgetrack firmware(binary_);
    ASSERT_TRUE(notify.waitFor("READY=1", seconds(20))) << Edgetrack::err();
    shell("echo vimc.1 > /sys/bus/platform/drivers/vimc/unbind");
    const std::optional<int> exit = firmware.waitExit(seconds(20));
    shell("echo vimc.1 > /sys/bus/platform/drivers/vimc/bind");
    ASSERT_TRUE(exit.has_value()) << "still running with a camera removed\n" << Edgetrack::err();
    EXPECT_EQ(*exit, 75) << Edgetrack::err(); // EX_TEMPFAIL: Restart=on-failure starts it again
    EXPECT_NE(Edgetrack::err().find("exiting so that systemd starts edgetrack again"),
              std::string::npos)
        << Edgetrack::err();
    EXPECT_TRUE(std::regex_search(Edgetrack::out(), std::regex("camera failures +[1-9]")))
        << Edgetrack::out();
}

// The UDP backend (what the firmware sends DTrack frames through) to a destination without a
// route, then with one: failures are counted, never fatal, and sending resumes by itself.
TEST(LinuxUdp, AnUnreachableDestinationIsCountedAndSendingResumesWhenItIsReachable) {
    if (std::getenv("EDGETRACK_BINARY") == nullptr)
        GTEST_SKIP() << "changes the network: run inside the test VM (guest-firmware.sh)";
    const int receiver = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(5055);
    ASSERT_EQ(::bind(receiver, reinterpret_cast<const sockaddr*>(&address), sizeof address), 0);

    linux_hal::PosixUdpSender udp;
    ASSERT_TRUE(udp.isValid());
    const hal::UdpEndpoint host{{10, 99, 0, 1}, 5055};
    const std::uint8_t datagram[] = {'f', 'r', '\n'};
    EXPECT_EQ(udp.send(host, datagram), hal::UdpSendResult::Unreachable) << "no route yet";
    EXPECT_EQ(udp.send(host, datagram), hal::UdpSendResult::Unreachable);
    EXPECT_EQ(udp.counters().failed, 2u);

    // The host's network appears (here: its subnet on the loopback interface).
    shell("ip addr add 10.99.0.2/24 dev lo");
    EXPECT_EQ(udp.send(host, datagram), hal::UdpSendResult::Sent);
    EXPECT_EQ(udp.counters().sent, 1u);
    pollfd p{receiver, POLLIN, 0};
    ASSERT_EQ(::poll(&p, 1, 2000), 1) << "the datagram did not arrive";
    char received[16];
    EXPECT_EQ(::recv(receiver, received, sizeof received, 0), 3);
    shell("ip addr del 10.99.0.2/24 dev lo");
    ::close(receiver);
}

} // namespace
} // namespace edgetrack
