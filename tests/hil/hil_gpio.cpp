// Hardware test of the libgpiod backends on the kernel's gpio-sim driver (run inside the test VM).
#include <chrono>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "firmware_app/firmware/button_input.hpp"
#include "hal/linux/gpiod_devices.hpp"
#include "hal/linux/posix_clock.hpp"

namespace edgetrack {
namespace {

using linux_hal::GpiodButton;
using linux_hal::GpiodLedRing;
using linux_hal::GpiodStatusLed;
using linux_hal::GpioLineAddress;

constexpr hal::Nanoseconds kMs = hal::kNanosecondsPerMillisecond;

/// The simulated chip that guest-gpio.sh made: lines IR_LED, BUTTON and STATUS_LED at 0, 1, 2.
class GpioSim : public ::testing::Test {
protected:
    void SetUp() override {
        const char* chip = std::getenv("EDGETRACK_GPIO_CHIP");
        const char* sysfs = std::getenv("EDGETRACK_GPIO_SYSFS");
        if (chip == nullptr || sysfs == nullptr)
            GTEST_SKIP() << "no simulated GPIO chip: run inside the test VM (guest-gpio.sh)";
        chip_ = chip;
        sysfs_ = sysfs;
    }

    GpioLineAddress line(const char* name) const { return GpioLineAddress{chip_, name}; }

    /// The level the simulated line shows (what an LED on it would do).
    int value(int offset) const {
        std::ifstream in(sysfs_ + "/sim_gpio" + std::to_string(offset) + "/value");
        int level = -1;
        in >> level;
        return level;
    }
    /// Drive an input line from outside, as a button wired to it would.
    void pull(int offset, const char* direction) const {
        std::ofstream out(sysfs_ + "/sim_gpio" + std::to_string(offset) + "/pull");
        out << direction;
        out.flush();
        ASSERT_TRUE(out.good()) << "cannot write the pull of line " << offset;
    }

    std::string chip_, sysfs_;
    linux_hal::PosixClock clock_;
};

TEST_F(GpioSim, StrobePulsesLightTheLineOnlyDuringTheirExposure) {
    GpiodLedRing ring(line("IR_LED"), clock_);
    ASSERT_TRUE(ring.available()) << ring.errorText();
    std::printf("strobe thread: %s\n", ring.schedulingNote().c_str());
    // Long pulses: the guest runs under TCG, where a wake-up can be a few ms late.
    const hal::Nanoseconds start = clock_.now() + 200 * kMs;
    struct Window {
        hal::Nanoseconds on, off;
    };
    std::vector<Window> windows;
    for (int i = 0; i < 4; ++i) {
        const hal::Nanoseconds on = start + i * 400 * kMs;
        windows.push_back({on, on + 150 * kMs});
        ASSERT_TRUE(ring.schedulePulse(on, on + 150 * kMs));
    }
    const hal::Nanoseconds margin = 40 * kMs;
    int litInside = 0, darkOutside = 0, wrong = 0;
    while (clock_.now() < start + 1700 * kMs) {
        const hal::Nanoseconds before = clock_.now();
        const int level = value(0);
        const hal::Nanoseconds at = (before + clock_.now()) / 2;
        bool inside = false, nearEdge = false;
        for (const Window& w : windows) {
            inside = inside || (at > w.on + margin && at < w.off - margin);
            nearEdge = nearEdge || (at > w.on - margin && at < w.on + margin) ||
                       (at > w.off - margin && at < w.off + margin);
        }
        if (!nearEdge) {
            if (level == (inside ? 1 : 0))
                ++(inside ? litInside : darkOutside);
            else
                ++wrong;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(3));
    }
    EXPECT_EQ(wrong, 0);
    EXPECT_GT(litInside, 20);
    EXPECT_GT(darkOutside, 20);
    const linux_hal::StrobeCounters counters = ring.strobeCounters();
    EXPECT_EQ(counters.pulses, 4u);
    EXPECT_EQ(counters.missed, 0u);
    EXPECT_EQ(counters.late, 0u);
    EXPECT_EQ(ring.droppedPulses(), 0u);
}

TEST_F(GpioSim, ContinuousLightAndAFullPulseQueue) {
    GpiodLedRing ring(line("IR_LED"), clock_, 2);
    ASSERT_TRUE(ring.available()) << ring.errorText();
    ring.setContinuous(true);
    EXPECT_EQ(value(0), 1);
    ring.setContinuous(false);
    EXPECT_EQ(value(0), 0);
    // Pulses a minute ahead stay queued: the third does not fit and is counted.
    const hal::Nanoseconds later = clock_.now() + 60 * hal::kNanosecondsPerSecond;
    EXPECT_TRUE(ring.schedulePulse(later, later + kMs));
    EXPECT_TRUE(ring.schedulePulse(later + 10 * kMs, later + 11 * kMs));
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    int accepted = 0;
    for (int i = 0; i < 3; ++i)
        accepted += ring.schedulePulse(later + 20 * kMs, later + 21 * kMs) ? 1 : 0;
    EXPECT_LE(accepted, 1); // the thread holds one pulse while it sleeps towards it
    EXPECT_GE(ring.droppedPulses(), 2u);
}

TEST_F(GpioSim, StatusLedFollowsTheFirmware) {
    GpiodStatusLed led(line("STATUS_LED"), clock_);
    ASSERT_TRUE(led.available()) << led.errorText();
    led.set(true);
    EXPECT_EQ(value(2), 1);
    led.set(false);
    EXPECT_EQ(value(2), 0);
}

TEST_F(GpioSim, ButtonPressesShortAndLongThroughTheDebouncer) {
    GpiodButton button(line("BUTTON"), clock_);
    ASSERT_TRUE(button.available()) << button.errorText();
    app::ButtonInput input(30 * kMs, 3 * hal::kNanosecondsPerSecond);
    std::vector<app::ButtonEvent> events;
    std::vector<hal::ButtonEdge> edges;
    auto pump = [&](int milliseconds) {
        const hal::Nanoseconds until = clock_.now() + milliseconds * kMs;
        while (clock_.now() < until) {
            hal::ButtonEdge edge;
            while (button.nextEdge(edge)) {
                edges.push_back(edge);
                input.edge(edge);
            }
            for (app::ButtonEvent e = input.poll(clock_.now()); e != app::ButtonEvent::None;
                 e = input.poll(clock_.now()))
                events.push_back(e);
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
    };
    pump(100);
    EXPECT_TRUE(edges.empty()) << "the line is pulled up: not pressed";

    const hal::Nanoseconds pressedAt = clock_.now();
    pull(1, "pull-down");
    pump(300);
    pull(1, "pull-up");
    pump(200);
    ASSERT_EQ(edges.size(), 2u);
    EXPECT_TRUE(edges[0].pressed);
    EXPECT_FALSE(edges[1].pressed);
    // The kernel's stamps are on the board clock: within a few ms of when the pull changed.
    EXPECT_NEAR(static_cast<double>(edges[0].time - pressedAt) / kMs, 0.0, 50.0);
    EXPECT_NEAR(static_cast<double>(edges[1].time - edges[0].time) / kMs, 300.0, 60.0);
    ASSERT_EQ(events, std::vector<app::ButtonEvent>{app::ButtonEvent::ShortPress});

    events.clear();
    pull(1, "pull-down");
    pump(3300);
    EXPECT_EQ(events, std::vector<app::ButtonEvent>{app::ButtonEvent::LongPress})
        << "a long press is reported while the button is still held";
    pull(1, "pull-up");
    pump(200);
    EXPECT_EQ(events, std::vector<app::ButtonEvent>{app::ButtonEvent::LongPress});
    EXPECT_EQ(edges.size(), 4u);
}

TEST_F(GpioSim, AnActiveHighButtonIsPressedWhenItDrivesTheLineHigh) {
    GpiodButton button(line("BUTTON"), clock_, /*activeLow=*/false);
    ASSERT_TRUE(button.available()) << button.errorText();
    const auto edgesWithin = [&](int milliseconds) {
        std::vector<hal::ButtonEdge> edges;
        const hal::Nanoseconds until = clock_.now() + milliseconds * kMs;
        while (clock_.now() < until) {
            hal::ButtonEdge edge;
            while (button.nextEdge(edge))
                edges.push_back(edge);
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
        return edges;
    };
    EXPECT_TRUE(edgesWithin(100).empty()) << "the requested pull-down holds it released";
    pull(1, "pull-up");
    std::vector<hal::ButtonEdge> edges = edgesWithin(200);
    ASSERT_EQ(edges.size(), 1u);
    EXPECT_TRUE(edges[0].pressed);
    pull(1, "pull-down");
    edges = edgesWithin(200);
    ASSERT_EQ(edges.size(), 1u);
    EXPECT_FALSE(edges[0].pressed);
}

TEST_F(GpioSim, BusyLineIsReportedAndTakenOverWhenItsHolderLetsGo) {
    // Another program holds the LED line (gpioset keeps it until it is signalled).
    ASSERT_EQ(std::system(
                  ("gpioset --mode=signal " + chip_ + " 0=0 & echo $! > /tmp/gpioset.pid").c_str()),
              0);
    std::this_thread::sleep_for(std::chrono::milliseconds(500));
    GpiodLedRing ring(line("IR_LED"), clock_);
    EXPECT_FALSE(ring.available());
    EXPECT_NE(ring.errorText().find("busy"), std::string::npos) << ring.errorText();
    EXPECT_NE(ring.errorText().find("gpioset"), std::string::npos) << ring.errorText();
    hal::Nanoseconds now = clock_.now();
    ASSERT_TRUE(ring.schedulePulse(now + 10 * kMs, now + 20 * kMs));
    std::this_thread::sleep_for(std::chrono::milliseconds(100));
    EXPECT_EQ(ring.strobeCounters().lineUnavailable, 1u);

    ASSERT_EQ(std::system("kill $(cat /tmp/gpioset.pid)"), 0);
    // The ring asks for the line again once a second.
    std::this_thread::sleep_for(std::chrono::milliseconds(1200));
    now = clock_.now();
    ASSERT_TRUE(ring.schedulePulse(now + 100 * kMs, now + 400 * kMs));
    std::this_thread::sleep_for(std::chrono::milliseconds(250));
    EXPECT_TRUE(ring.available()) << ring.errorText();
    EXPECT_EQ(value(0), 1) << "the pulse lights the line taken over";
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    EXPECT_EQ(value(0), 0);
}

TEST_F(GpioSim, MissingLineIsAnError) {
    GpiodButton button(line("NO_SUCH_LINE"), clock_);
    EXPECT_FALSE(button.available());
    EXPECT_NE(button.errorText().find("NO_SUCH_LINE"), std::string::npos) << button.errorText();
    hal::ButtonEdge edge;
    EXPECT_FALSE(button.nextEdge(edge));
}

} // namespace
} // namespace edgetrack
