// Tests of the simulated devices: NOR flash with power cuts, CAN faults, button, LEDs, UDP.
#include <gtest/gtest.h>

#include "hal/sim/devices.hpp"

using namespace edgetrack;
using namespace edgetrack::sim;

namespace {
std::vector<std::uint8_t> bytes(std::initializer_list<int> values) {
    std::vector<std::uint8_t> out;
    for (int v : values)
        out.push_back(static_cast<std::uint8_t>(v));
    return out;
}
std::vector<std::uint8_t> readBack(SimFlash& flash, std::size_t offset, std::size_t length) {
    std::vector<std::uint8_t> out(length);
    EXPECT_TRUE(flash.read(offset, out));
    return out;
}
} // namespace

TEST(SimFlash, ErasedIsAllOnesAndWritesOnlyClearBits) {
    SimFlash flash(8192, 4096);
    EXPECT_EQ(readBack(flash, 0, 2), bytes({0xFF, 0xFF}));
    ASSERT_TRUE(flash.write(0, bytes({0xF0, 0x0F})));
    ASSERT_TRUE(flash.write(0, bytes({0x3C, 0xFF})));
    EXPECT_EQ(readBack(flash, 0, 2), bytes({0x30, 0x0F}));
    ASSERT_TRUE(flash.erase(0, 4096));
    EXPECT_EQ(readBack(flash, 0, 2), bytes({0xFF, 0xFF}));
}

TEST(SimFlash, EraseMustBeBlockAligned) {
    SimFlash flash(8192, 4096);
    const Status s = flash.erase(100, 4096);
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().message,
              "flash erase: 100+4096 is not aligned to the 4096-byte erase block");
    EXPECT_FALSE(flash.write(8190, bytes({1, 2, 3})));
    std::vector<std::uint8_t> out(4);
    EXPECT_FALSE(flash.read(8190, out));
}

TEST(SimFlash, PowerCutTearsTheNextOperationAndStopsTheRest) {
    SimFlash flash(8192, 4096);
    flash.cutPowerAfter(1, 0.5);
    ASSERT_TRUE(flash.write(0, bytes({0, 0, 0, 0}))); // operation 1 completes
    const Status torn = flash.write(4, bytes({0, 0, 0, 0}));
    ASSERT_FALSE(torn);
    EXPECT_EQ(torn.error().message, "flash write: power lost");
    EXPECT_FALSE(flash.powered());
    EXPECT_FALSE(flash.write(8, bytes({0})));
    std::vector<std::uint8_t> out(1);
    EXPECT_FALSE(flash.read(0, out));

    flash.restorePower();
    // Half of the torn write landed, the rest did not, and nothing after it happened.
    EXPECT_EQ(readBack(flash, 0, 9), bytes({0, 0, 0, 0, 0, 0, 0xFF, 0xFF, 0xFF}));
}

TEST(SimFlash, TornEraseLeavesAMixture) {
    SimFlash flash(8192, 4096);
    ASSERT_TRUE(flash.write(0, std::vector<std::uint8_t>(4096, 0)));
    flash.cutPowerAfter(0, 0.25);
    EXPECT_FALSE(flash.erase(0, 4096));
    flash.restorePower();
    EXPECT_EQ(readBack(flash, 0, 1)[0], 0xFF);
    EXPECT_EQ(readBack(flash, 1024, 1)[0], 0x00);
    EXPECT_EQ(flash.operations(), 2u);
}

TEST(SimCan, LoopbackDeliversClassicAndFdFrames) {
    SimClock clock;
    SimCanBus bus(clock);
    hal::CanFrame classic;
    classic.id = 0x123;
    classic.length = 8;
    classic.data[7] = 0xAB;
    hal::CanFrame fd;
    fd.id = 0x18FF0001;
    fd.extended = true;
    fd.fd = true;
    fd.bitRateSwitch = true;
    fd.length = 64;
    fd.data[63] = 0xCD;
    EXPECT_EQ(bus.send(classic), hal::CanSendResult::Queued);
    EXPECT_EQ(bus.send(fd), hal::CanSendResult::Queued);
    hal::CanFrame got;
    ASSERT_TRUE(bus.peerReceive(got));
    EXPECT_EQ(got.id, 0x123u);
    EXPECT_EQ(got.data[7], 0xAB);
    ASSERT_TRUE(bus.peerReceive(got));
    EXPECT_TRUE(got.fd);
    EXPECT_EQ(got.data[63], 0xCD);
    EXPECT_FALSE(bus.peerReceive(got));
    EXPECT_EQ(bus.counters().sent, 2u);

    bus.peerSend(classic);
    ASSERT_TRUE(bus.receive(got));
    EXPECT_EQ(got.id, 0x123u);
}

TEST(SimCan, RefusesInvalidFrames) {
    SimClock clock;
    SimCanBus bus(clock);
    hal::CanFrame f;
    f.length = 12; // needs FD
    EXPECT_EQ(bus.send(f), hal::CanSendResult::Invalid);
    f.fd = true;
    f.length = 13; // not an FD length
    EXPECT_EQ(bus.send(f), hal::CanSendResult::Invalid);
    f.length = 8;
    f.id = 0x800; // too big for 11 bits
    EXPECT_EQ(bus.send(f), hal::CanSendResult::Invalid);
    EXPECT_EQ(bus.counters().refused, 3u);
}

TEST(SimCan, FullTransmitQueueDropsTheOldest) {
    SimClock clock;
    SimCanBus bus(clock, 4);
    bus.setTransmitBlocked(true);
    hal::CanFrame f;
    f.length = 1;
    for (int i = 0; i < 6; ++i) {
        f.data[0] = static_cast<std::uint8_t>(i);
        const auto result = bus.send(f);
        EXPECT_EQ(result, i < 4 ? hal::CanSendResult::Queued : hal::CanSendResult::DroppedOldest);
    }
    EXPECT_EQ(bus.counters().droppedQueueFull, 2u);
    bus.setTransmitBlocked(false);
    hal::CanFrame got;
    ASSERT_TRUE(bus.peerReceive(got));
    EXPECT_EQ(got.data[0], 2); // frames 0 and 1 were dropped
}

TEST(SimCan, BusOffAndRestartAreReported) {
    SimClock clock;
    SimCanBus bus(clock);
    hal::CanFrame f;
    f.length = 2;
    clock.advanceTo(5000);
    bus.injectBusOff();
    EXPECT_EQ(bus.state(), hal::CanState::BusOff);
    EXPECT_EQ(bus.send(f), hal::CanSendResult::BusOff);
    hal::CanErrorEvent event;
    ASSERT_TRUE(bus.nextError(event));
    EXPECT_EQ(event.state, hal::CanState::BusOff);
    EXPECT_EQ(event.time, 5000);
    bus.restart();
    ASSERT_TRUE(bus.nextError(event));
    EXPECT_EQ(event.state, hal::CanState::ErrorActive);
    EXPECT_EQ(bus.send(f), hal::CanSendResult::Queued);

    bus.injectErrorFrame(hal::CanState::ErrorPassive, 0x04);
    ASSERT_TRUE(bus.nextError(event));
    EXPECT_EQ(event.errorClass, 0x04u);
    EXPECT_EQ(bus.state(), hal::CanState::ErrorPassive);

    bus.setDown(true);
    EXPECT_EQ(bus.send(f), hal::CanSendResult::Down);
    bus.setDown(false);
    EXPECT_EQ(bus.send(f), hal::CanSendResult::Queued);
}

TEST(SimButton, EdgesArriveWhenTheirTimeHasCome) {
    SimClock clock;
    SimButton button(clock);
    button.press(1'000'000, 200'000'000, 2);
    hal::ButtonEdge edge;
    EXPECT_FALSE(button.nextEdge(edge));
    clock.advanceTo(1'000'000);
    ASSERT_TRUE(button.nextEdge(edge));
    EXPECT_TRUE(edge.pressed);
    EXPECT_EQ(edge.time, 1'000'000);
    clock.advanceTo(500'000'000);
    int edges = 1;
    bool last = true;
    while (button.nextEdge(edge)) {
        ++edges;
        last = edge.pressed;
    }
    EXPECT_EQ(edges, 2 + 4 * 2); // press and release, each with two bounces
    EXPECT_FALSE(last);
}

TEST(SimLeds, StatusLedAndLedRing) {
    SimClock clock;
    SimStatusLed status(clock);
    clock.advanceTo(42);
    status.set(true);
    status.set(true);
    EXPECT_TRUE(status.isOn());
    EXPECT_EQ(status.changes(), 1u);
    EXPECT_EQ(status.lastChange(), 42);

    SimLedRing ring;
    EXPECT_DOUBLE_EQ(ring.litFraction(0, 1000), 0.0);
    ASSERT_TRUE(ring.schedulePulse(250, 750));
    EXPECT_DOUBLE_EQ(ring.litFraction(0, 1000), 0.5);
    ring.setContinuous(true);
    EXPECT_DOUBLE_EQ(ring.litFraction(0, 1000), 1.0);
    ring.setContinuous(false);
    for (std::size_t i = 0; i < SimLedRing::kPulseQueue; ++i)
        ring.schedulePulse(2000, 3000);
    EXPECT_EQ(ring.droppedPulses(), 1u);
    ring.forgetBefore(1000);
    EXPECT_DOUBLE_EQ(ring.litFraction(0, 1000), 0.0);
}

TEST(SimUdp, KeepsDatagramsAndCountsUnreachable) {
    SimUdpSender udp(2);
    const hal::UdpEndpoint host{{127, 0, 0, 1}, 5000};
    const hal::UdpEndpoint gone{{10, 9, 9, 9}, 5000};
    const std::string text = "fr 1\r\n";
    const std::span<const std::uint8_t> payload(reinterpret_cast<const std::uint8_t*>(text.data()),
                                                text.size());
    EXPECT_EQ(udp.send(host, payload), hal::UdpSendResult::Sent);
    udp.setUnreachable(gone, true);
    EXPECT_EQ(udp.send(gone, payload), hal::UdpSendResult::Unreachable);
    EXPECT_EQ(udp.counters().failed, 1u);
    SimUdpSender::Datagram d;
    ASSERT_TRUE(udp.takeSent(d));
    EXPECT_EQ(d.text(), "fr 1\r\n");
    EXPECT_EQ(d.to, host);
    EXPECT_FALSE(udp.takeSent(d));
    EXPECT_TRUE((hal::UdpEndpoint{{239, 1, 2, 3}, 5000}.isMulticast()));
}
