// Tests of the CAN log: candump -L lines as can-utils writes them, and only frames the bus took.
#include <array>
#include <fstream>
#include <sstream>
#include <string>

#include <gtest/gtest.h>

#include "firmware_app/app/can_log.hpp"
#include "hal/sim/devices.hpp"
#include "tests/support/temp_dir.hpp"

namespace edgetrack::app {
namespace {

std::string line(const hal::CanFrame& frame, std::int64_t utc_ns) {
    std::array<char, 192> buffer{};
    const std::size_t length = formatCandumpLine(frame, utc_ns, "can0", buffer);
    return std::string(buffer.data(), length);
}

TEST(CanLog, WritesClassicExtendedAndFdFramesAsCandumpDoes) {
    hal::CanFrame classic;
    classic.id = 0x301;
    classic.length = 8;
    classic.data = {0x01, 0x23, 0x45, 0x67, 0x89, 0xAB, 0xCD, 0xEF};
    EXPECT_EQ(line(classic, 1'795'564'845'123'456'789LL),
              "(1795564845.123456) can0 301#0123456789ABCDEF\n");

    hal::CanFrame extended;
    extended.id = 0x18DAF110;
    extended.extended = true;
    extended.length = 2;
    extended.data[0] = 0x0A;
    extended.data[1] = 0xFF;
    EXPECT_EQ(line(extended, 5'000'001'000LL), "(5.000001) can0 18DAF110#0AFF\n");

    hal::CanFrame empty;
    empty.id = 0x7;
    EXPECT_EQ(line(empty, 0), "(0.000000) can0 007#\n");

    hal::CanFrame fd;
    fd.id = 0x380;
    fd.fd = true;
    fd.bitRateSwitch = true;
    fd.length = 12;
    for (std::uint8_t i = 0; i < 12; ++i)
        fd.data[i] = static_cast<std::uint8_t>(0x10 + i);
    EXPECT_EQ(line(fd, 1'000'000'000LL), "(1.000000) can0 380##1101112131415161718191A1B\n");
    fd.bitRateSwitch = false;
    EXPECT_EQ(line(fd, 1'000'000'000LL), "(1.000000) can0 380##0101112131415161718191A1B\n");

    std::array<char, 24> shortBuffer{};
    EXPECT_EQ(formatCandumpLine(classic, 0, "can0", shortBuffer), 0u) << "nothing partial";
}

TEST(CanLogBus, FramesWhoseWriteFailedAreCountedLostNotLogged) {
    // On a full disk the log said "1791 CAN frames logged, 2 writes failed" of an empty file:
    // buffered writes succeed, and only the flush fails. /dev/full fails every write.
    if (!std::filesystem::exists("/dev/full"))
        GTEST_SKIP() << "no /dev/full";
    sim::SimClock clock(false);
    sim::SimCanBus bus(clock, 4096);
    CanLogBus logged(bus, clock, "vcan0", "/dev/full");
    ASSERT_TRUE(logged.isValid()) << logged.error();
    hal::CanFrame frame;
    frame.id = 0x300;
    frame.length = 8;
    for (int i = 0; i < 3000; ++i)
        logged.send(frame);
    logged.flush();
    EXPECT_EQ(logged.framesLogged(), 0u);
    EXPECT_EQ(logged.framesLost(), 3000u);
    EXPECT_GE(logged.writeFailures(), 2u) << "the buffer filled more than once";
}

TEST(CanLogBus, LogsTheFramesTheBusTookAndPassesEverythingOn) {
    sim::SimClock clock(false);
    sim::SimCanBus bus(clock, 2);
    test::TempDir dir;
    const std::filesystem::path file = dir.path() / "can.log";
    {
        CanLogBus logged(bus, clock, "vcan0", file);
        ASSERT_TRUE(logged.isValid()) << logged.error();
        hal::CanFrame frame;
        frame.id = 0x300;
        frame.length = 1;
        for (std::uint8_t i = 0; i < 3; ++i) {
            frame.data[0] = i;
            EXPECT_EQ(logged.send(frame), hal::CanSendResult::Queued);
        }
        hal::CanFrame invalid;
        invalid.id = 0x800; // beyond 11 bits
        EXPECT_EQ(logged.send(invalid), hal::CanSendResult::Invalid);
        bus.setDown(true);
        EXPECT_EQ(logged.send(frame), hal::CanSendResult::Down);
        EXPECT_EQ(logged.framesLogged(), 0u) << "buffered: not in the file yet";
        logged.flush();
        EXPECT_EQ(logged.framesLogged(), 3u);
        EXPECT_EQ(logged.framesLost(), 0u);
        EXPECT_EQ(logged.writeFailures(), 0u);
        EXPECT_EQ(logged.counters().sent, bus.counters().sent);
    }
    std::ifstream in(file);
    std::stringstream text;
    text << in.rdbuf();
    const std::string expectedTime =
        "(" + std::to_string(clock.utcOffset() / 1'000'000'000LL) + ".000000) vcan0 300#";
    EXPECT_EQ(text.str(), expectedTime + "00\n" + expectedTime + "01\n" + expectedTime + "02\n");
}

TEST(CanLogBus, AFileThatCannotBeOpenedIsAnError) {
    sim::SimClock clock(false);
    sim::SimCanBus bus(clock);
    CanLogBus logged(bus, clock, "can0", "/nonexistent-dir/can.log");
    EXPECT_FALSE(logged.isValid());
    EXPECT_NE(logged.error().find("/nonexistent-dir/can.log: cannot open for writing"),
              std::string::npos)
        << logged.error();
}

} // namespace
} // namespace edgetrack::app
