// What the status LED shows in each state of the board, as a function of time.
#include "firmware_app/firmware/status_pattern.hpp"

namespace edgetrack::app {

namespace {
constexpr hal::Nanoseconds kMs = hal::kNanosecondsPerMillisecond;

/// On for the first \a on of every \a period.
bool square(hal::Nanoseconds since, hal::Nanoseconds period, hal::Nanoseconds on) {
    return since % period < on;
}
} // namespace

bool ledLevel(LedPattern pattern, hal::Nanoseconds since) {
    if (since < 0)
        since = 0;
    switch (pattern) {
    case LedPattern::On:
        return true;
    case LedPattern::Heartbeat:
        return square(since, 2000 * kMs, 100 * kMs);
    case LedPattern::Blink:
        return square(since, 500 * kMs, 250 * kMs);
    case LedPattern::Finishing:
        return !square(since, 1000 * kMs, 250 * kMs);
    case LedPattern::FastBlink:
        return square(since, 125 * kMs, 62 * kMs);
    case LedPattern::Confirm: {
        // Two 80 ms flashes 160 ms apart, every 500 ms, three times.
        if (since >= patternDuration(LedPattern::Confirm))
            return false;
        const hal::Nanoseconds phase = since % (500 * kMs);
        return phase < 80 * kMs || (phase >= 160 * kMs && phase < 240 * kMs);
    }
    case LedPattern::Wand: {
        const hal::Nanoseconds phase = since % (1000 * kMs);
        return phase < 100 * kMs || (phase >= 200 * kMs && phase < 300 * kMs);
    }
    case LedPattern::RigGood:
        return since < patternDuration(LedPattern::RigGood);
    case LedPattern::RigPoor:
        return since < patternDuration(LedPattern::RigPoor) && square(since, 500 * kMs, 300 * kMs);
    }
    return false;
}

hal::Nanoseconds patternDuration(LedPattern pattern) {
    switch (pattern) {
    case LedPattern::Confirm:
    case LedPattern::RigGood:
    case LedPattern::RigPoor:
        return 1500 * kMs;
    default:
        return 0;
    }
}

void StatusLedDriver::showOnce(LedPattern pattern, hal::Nanoseconds now) {
    oneShot_ = pattern;
    oneShotUntil_ = now + patternDuration(pattern);
    shown_ = pattern;
    shownSince_ = now;
}

void StatusLedDriver::update(LedPattern statePattern, hal::Nanoseconds now, hal::StatusLed& led) {
    const LedPattern pattern = now < oneShotUntil_ ? oneShot_ : statePattern;
    if (pattern != shown_) {
        shown_ = pattern;
        shownSince_ = now;
    }
    led.set(ledLevel(pattern, now - shownSince_));
}

} // namespace edgetrack::app
