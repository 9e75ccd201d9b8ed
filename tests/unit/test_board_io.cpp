// Tests of the button's debouncing and press classification, and of the status LED patterns.
#include <gtest/gtest.h>

#include "firmware_app/firmware/button_input.hpp"
#include "firmware_app/firmware/status_pattern.hpp"

namespace edgetrack::app {
namespace {

constexpr hal::Nanoseconds kMs = hal::kNanosecondsPerMillisecond;

ButtonInput makeButton() {
    return ButtonInput(30 * kMs, 3000 * kMs);
}

TEST(ButtonInput, ABouncyShortPressIsOneShortPress) {
    ButtonInput button = makeButton();
    // Press at 100 ms with four bounces, release at 300 ms with two.
    for (hal::Nanoseconds t : {100, 101, 102, 103, 104})
        button.edge({t * kMs, t % 2 == 0});
    EXPECT_EQ(button.poll(120 * kMs), ButtonEvent::None) << "still bouncing";
    EXPECT_EQ(button.poll(140 * kMs), ButtonEvent::None);
    EXPECT_TRUE(button.held());
    for (hal::Nanoseconds t : {300, 301, 302})
        button.edge({t * kMs, t % 2 == 1});
    EXPECT_EQ(button.poll(400 * kMs), ButtonEvent::ShortPress);
    EXPECT_EQ(button.poll(1000 * kMs), ButtonEvent::None);
    EXPECT_FALSE(button.held());
}

TEST(ButtonInput, AGlitchShorterThanTheDebounceIsNoPress) {
    ButtonInput button = makeButton();
    button.edge({100 * kMs, true});
    button.edge({110 * kMs, false});
    EXPECT_EQ(button.poll(500 * kMs), ButtonEvent::None);
}

TEST(ButtonInput, ALongPressIsReportedWhileHeldAndTheReleaseAddsNothing) {
    ButtonInput button = makeButton();
    button.edge({0, true});
    EXPECT_EQ(button.poll(2900 * kMs), ButtonEvent::None);
    EXPECT_EQ(button.poll(3000 * kMs), ButtonEvent::LongPress);
    button.edge({5000 * kMs, false});
    EXPECT_EQ(button.poll(6000 * kMs), ButtonEvent::None);
}

TEST(ButtonInput, PressAndReleaseReadTogetherAreClassifiedByTheirOwnTimes) {
    ButtonInput button = makeButton();
    button.edge({0, true});
    button.edge({4000 * kMs, false});
    button.edge({5000 * kMs, true});
    button.edge({5200 * kMs, false});
    EXPECT_EQ(button.poll(6000 * kMs), ButtonEvent::LongPress);
    EXPECT_EQ(button.poll(6000 * kMs), ButtonEvent::ShortPress);
    EXPECT_EQ(button.poll(6000 * kMs), ButtonEvent::None);
}

ButtonInput makeButtonWithDoublePress() {
    return ButtonInput(30 * kMs, 3000 * kMs, 400 * kMs);
}

TEST(ButtonInput, TwoQuickShortPressesAreOneDoublePress) {
    ButtonInput button = makeButtonWithDoublePress();
    button.edge({0, true});
    button.edge({150 * kMs, false});
    // Released, but a second press may follow: nothing yet.
    EXPECT_EQ(button.poll(300 * kMs), ButtonEvent::None);
    button.edge({400 * kMs, true});
    button.edge({550 * kMs, false});
    EXPECT_EQ(button.poll(600 * kMs), ButtonEvent::DoublePress);
    EXPECT_EQ(button.poll(2000 * kMs), ButtonEvent::None);
}

TEST(ButtonInput, AShortPressIsKnownOnceTheDoublePressTimeHasPassed) {
    ButtonInput button = makeButtonWithDoublePress();
    button.edge({0, true});
    button.edge({150 * kMs, false});
    EXPECT_EQ(button.poll(500 * kMs), ButtonEvent::None);
    EXPECT_EQ(button.poll(560 * kMs), ButtonEvent::ShortPress);
    // Two presses further apart than the window are two short presses.
    button.edge({1000 * kMs, true});
    button.edge({1100 * kMs, false});
    button.edge({1700 * kMs, true});
    button.edge({1800 * kMs, false});
    EXPECT_EQ(button.poll(3000 * kMs), ButtonEvent::ShortPress);
    EXPECT_EQ(button.poll(3000 * kMs), ButtonEvent::ShortPress);
    EXPECT_EQ(button.poll(3000 * kMs), ButtonEvent::None);
}

TEST(ButtonInput, AShortPressThenALongOneAreBothReported) {
    ButtonInput button = makeButtonWithDoublePress();
    button.edge({0, true});
    button.edge({150 * kMs, false});
    button.edge({300 * kMs, true});
    EXPECT_EQ(button.poll(3400 * kMs), ButtonEvent::ShortPress);
    EXPECT_EQ(button.poll(3400 * kMs), ButtonEvent::LongPress);
    button.edge({4000 * kMs, false});
    EXPECT_EQ(button.poll(5000 * kMs), ButtonEvent::None);
}

/// Lit share of one pattern over \a span, sampled every millisecond.
double dutyCycle(LedPattern pattern, hal::Nanoseconds span) {
    int on = 0;
    for (hal::Nanoseconds t = 0; t < span; t += kMs)
        on += ledLevel(pattern, t) ? 1 : 0;
    return static_cast<double>(on) / static_cast<double>(span / kMs);
}

int risingEdges(LedPattern pattern, hal::Nanoseconds span) {
    int edges = 0;
    bool last = false;
    for (hal::Nanoseconds t = 0; t < span; t += kMs) {
        const bool level = ledLevel(pattern, t);
        edges += level && !last ? 1 : 0;
        last = level;
    }
    return edges;
}

TEST(StatusPattern, EachStateLooksDifferent) {
    const hal::Nanoseconds fourSeconds = 4000 * kMs;
    EXPECT_DOUBLE_EQ(dutyCycle(LedPattern::On, fourSeconds), 1.0);
    EXPECT_EQ(risingEdges(LedPattern::Heartbeat, fourSeconds), 2);
    EXPECT_NEAR(dutyCycle(LedPattern::Heartbeat, fourSeconds), 0.05, 0.001);
    EXPECT_EQ(risingEdges(LedPattern::Blink, fourSeconds), 8);
    EXPECT_NEAR(dutyCycle(LedPattern::Blink, fourSeconds), 0.5, 0.01);
    EXPECT_EQ(risingEdges(LedPattern::FastBlink, fourSeconds), 32);
    EXPECT_EQ(risingEdges(LedPattern::Finishing, fourSeconds), 4);
    EXPECT_NEAR(dutyCycle(LedPattern::Finishing, fourSeconds), 0.75, 0.01) << "mostly on";
    EXPECT_EQ(risingEdges(LedPattern::Confirm, fourSeconds), 6) << "three double flashes";
    EXPECT_FALSE(ledLevel(LedPattern::Confirm, patternDuration(LedPattern::Confirm)));
    EXPECT_EQ(patternDuration(LedPattern::Blink), 0);
}

} // namespace
} // namespace edgetrack::app
