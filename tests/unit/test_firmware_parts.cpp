// Tests of the frame loop's parts on fake devices: LED strobe, status LED driver, pose outputs.
#include <vector>

#include <gtest/gtest.h>

#include "firmware_app/firmware/dtrack.hpp"
#include "firmware_app/firmware/pose_outputs.hpp"
#include "firmware_app/firmware/status_pattern.hpp"
#include "firmware_app/firmware/strobe_scheduler.hpp"

namespace edgetrack::app {
namespace {

constexpr hal::Nanoseconds kMs = hal::kNanosecondsPerMillisecond;
constexpr hal::Nanoseconds kUs = 1000;

struct FakeRing : hal::LedRing {
    void setContinuous(bool on) override { continuous = on; }
    bool schedulePulse(hal::Nanoseconds onAt, hal::Nanoseconds offAt) override {
        if (pulses.size() >= room)
            return false;
        pulses.push_back({onAt, offAt});
        return true;
    }
    std::uint64_t droppedPulses() const override { return 0; }

    bool continuous = false;
    std::size_t room = 100;
    std::vector<std::pair<hal::Nanoseconds, hal::Nanoseconds>> pulses;
};

/// Both cameras exposing for 1 ms from \a start (camera 1 15 us later).
hal::StereoFrame exposedAt(hal::Nanoseconds start) {
    hal::StereoFrame frame;
    frame.camera[0].exposureStart = start;
    frame.camera[0].exposureEnd = start + kMs;
    frame.camera[1].exposureStart = start + 15 * kUs;
    frame.camera[1].exposureEnd = start + kMs + 15 * kUs;
    return frame;
}

TEST(StrobeScheduler, LightsEachComingExposureOnceWithItsMargins) {
    FakeRing ring;
    StrobeScheduler strobe(100 * kUs, 50 * kUs);
    strobe.restart(ring);
    EXPECT_TRUE(ring.continuous) << "lit before any pulse can be scheduled";
    const hal::Nanoseconds period = 10 * kMs;
    EXPECT_EQ(strobe.schedule(exposedAt(0), period, ring), 0u);
    ASSERT_EQ(ring.pulses.size(), 4u) << "four exposures ahead";
    for (std::size_t k = 0; k < 4; ++k) {
        const hal::Nanoseconds exposure = static_cast<hal::Nanoseconds>(k + 1) * period;
        EXPECT_EQ(ring.pulses[k].first, exposure - 100 * kUs);
        EXPECT_EQ(ring.pulses[k].second, exposure + kMs + 15 * kUs + 50 * kUs);
    }
    EXPECT_TRUE(ring.continuous);
    // The next frame (its exposure 20 us late) adds only the exposure not yet covered.
    EXPECT_EQ(strobe.schedule(exposedAt(period + 20 * kUs), period, ring), 0u);
    ASSERT_EQ(ring.pulses.size(), 5u);
    EXPECT_EQ(ring.pulses.back().first, 5 * period + 20 * kUs - 100 * kUs);
    EXPECT_FALSE(ring.continuous) << "the pulses cover the exposures from the second frame on";
    // A full pulse queue is reported, not hidden.
    ring.room = ring.pulses.size();
    EXPECT_EQ(strobe.schedule(exposedAt(2 * period), period, ring), 1u);
}

struct FakeStatusLed : hal::StatusLed {
    void set(bool on) override {
        if (available)
            level = on;
    }
    bool available = true;
    bool level = false;
};

TEST(StatusLedDriver, ShowsTheStatePatternAndAOneShotOverIt) {
    FakeStatusLed led;
    StatusLedDriver driver;
    hal::Nanoseconds t = 0;
    driver.update(LedPattern::Blink, t, led);
    EXPECT_TRUE(led.level);
    driver.update(LedPattern::Blink, t + 300 * kMs, led);
    EXPECT_FALSE(led.level) << "2 Hz, half on";

    t = 1000 * kMs;
    driver.showOnce(LedPattern::Confirm, t);
    driver.update(LedPattern::On, t + 100 * kMs, led);
    EXPECT_FALSE(led.level) << "between the confirm pattern's flashes, though the state says on";
    driver.update(LedPattern::On, t + patternDuration(LedPattern::Confirm), led);
    EXPECT_TRUE(led.level) << "the state's pattern again after the one-shot";
}

TEST(StatusLedDriver, AnLedThatComesBackShowsTheLevelThoughThePatternHeldItSteady) {
    // A GPIO line held by another process at start-up: the board takes it back once freed, and
    // must then light it though the steady pattern's level never changed meanwhile.
    FakeStatusLed led;
    led.available = false;
    StatusLedDriver driver;
    driver.update(LedPattern::On, 0, led);
    EXPECT_FALSE(led.level);
    led.available = true;
    driver.update(LedPattern::On, 100 * kMs, led);
    EXPECT_TRUE(led.level);
}

struct FakeUdp : hal::UdpSender {
    hal::UdpSendResult send(const hal::UdpEndpoint&, std::span<const std::uint8_t> bytes) override {
        datagrams.emplace_back(bytes.begin(), bytes.end());
        return hal::UdpSendResult::Sent;
    }
    hal::UdpCounters counters() const override { return {}; }
    std::vector<std::string> datagrams;
};

struct FakeCan : hal::CanBus {
    hal::CanSendResult send(const hal::CanFrame& frame) override {
        frames.push_back(frame);
        return hal::CanSendResult::Queued;
    }
    bool receive(hal::CanFrame&) override { return false; }
    bool nextError(hal::CanErrorEvent&) override { return errors-- > 0; }
    hal::CanState state() const override { return hal::CanState::ErrorActive; }
    hal::CanCounters counters() const override { return {}; }
    std::vector<hal::CanFrame> frames;
    int errors = 0;
};

TrackedBody bodyAt(std::uint32_t id, bool found, const Vec3& position_rig_mm) {
    TrackedBody body;
    body.modelId = id;
    body.source = found ? PoseSource::Searched : PoseSource::None;
    body.T_rig_from_model.translation_mm = position_rig_mm;
    body.markers = found ? 6 : 0;
    return body;
}

TEST(PoseOutputs, SendsFoundBodiesOverUdpAndEveryBodysStatusOnCan) {
    FirmwareConfig config;
    config.can.enabled = true;
    config.can.layout.maxBodies = 2;
    config.filter.enabled = false;
    PoseOutputs outputs(config);
    const TrackedBody bodies[] = {bodyAt(0, true, Vec3(10, 20, 800)),
                                  bodyAt(1, false, Vec3::Zero()), bodyAt(5, true, Vec3(0, 0, 900))};
    outputs.updatePoses(1.0, bodies);
    OutputFrame frame;
    frame.number = 42;
    frame.calibrated = 3;
    frame.bodies = bodies;
    FakeUdp udp;
    FakeCan can;
    outputs.send(frame, udp, can);

    ASSERT_EQ(udp.datagrams.size(), config.udp.destinations.size());
    const Result<ParsedDtrack> parsed = parseDtrack(udp.datagrams[0]);
    ASSERT_TRUE(parsed) << parsed.error().message;
    EXPECT_EQ(parsed->frame, 42u);
    EXPECT_EQ(parsed->calibrated, 3u);
    ASSERT_EQ(parsed->bodies.size(), 2u) << "a body not found has no 6d entry";
    EXPECT_EQ(parsed->bodies[0].id, 0u);
    EXPECT_NEAR(parsed->bodies[0].T_rig_from_model.translation_mm.z(), 800.0, 1e-3);
    EXPECT_EQ(parsed->bodies[1].id, 5u);
    EXPECT_TRUE(parsed->hasMarkerLine && parsed->markers.empty()) << "`3d 0` clears a preview";

    // Classic CAN: three frames for a found body, the status frame alone for one not found;
    // body 5 is beyond the layout's two bodies.
    EXPECT_EQ(can.frames.size(), 4u);
    EXPECT_EQ(outputs.counters().canSent, 4u);
    EXPECT_EQ(outputs.counters().canBodiesBeyondLayout, 1u);
    can.errors = 2;
    outputs.drainCanErrors(can);
    EXPECT_EQ(outputs.counters().canErrors, 2u);
}

TEST(PoseOutputs, PreviewIdsTellTheObjectApart) {
    EXPECT_EQ(PoseOutputs::previewMarkerId(0, 7), 7u);
    EXPECT_EQ(PoseOutputs::previewMarkerId(3, 7), 3007u);
    EXPECT_EQ(PoseOutputs::previewMarkerId(3, 1007), 3007u) << "the marker's id within 0-999";
}

} // namespace
} // namespace edgetrack::app
