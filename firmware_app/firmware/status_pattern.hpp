// What the status LED shows in each state of the board, as a function of time.
#pragma once

#include "hal/status_led.hpp"
#include "hal/types.hpp"

namespace edgetrack::app {

/// \brief Blink patterns, each readable at a glance and distinct from the others.
enum class LedPattern {
    /// Tracking, at least one body found: steadily on.
    On,
    /// Tracking, nothing found (or no models yet): a 100 ms flash every 2 s, a heartbeat.
    Heartbeat,
    /// Calibrating: 2 Hz, half on.
    Blink,
    /// Finishing a calibration (its models are being completed and saved): on, dark for 250 ms
    /// every second.
    Finishing,
    /// Degraded (a camera or the flash failed): 8 Hz.
    FastBlink,
    /// Acknowledges a long press (models deleted): three double flashes in 1.5 s, then the
    /// state's own pattern.
    Confirm,
    /// Rig calibration, collecting the wand: two 100 ms flashes every second.
    Wand,
    /// A new rig in use that fits well: on for 1.5 s, then the state's own pattern.
    RigGood,
    /// A rig calibration that gave no better rig, or a poor one: three 300 ms flashes in 1.5 s.
    RigPoor,
};

/// \return whether the LED is lit \a since after the pattern started.
bool ledLevel(LedPattern pattern, hal::Nanoseconds since);

/// \brief How long a one-shot pattern lasts (0 for the continuing ones).
hal::Nanoseconds patternDuration(LedPattern pattern);

/// \brief Drives the status LED: the board state's pattern, or for a while a one-shot pattern.
class StatusLedDriver {
public:
    /// \brief Show \a pattern once from \a now (e.g. Confirm), over the state's own.
    void showOnce(LedPattern pattern, hal::Nanoseconds now);
    /// \brief Set \a led as it should be at \a now, showing \a statePattern unless a one-shot
    /// pattern is running. The level is passed at every update, not only when it changes: a
    /// backend writes only changes, and one whose line was taken back after being busy must
    /// learn the level even while the pattern holds it steady.
    void update(LedPattern statePattern, hal::Nanoseconds now, hal::StatusLed& led);

private:
    LedPattern shown_ = LedPattern::Heartbeat;
    hal::Nanoseconds shownSince_ = 0;
    LedPattern oneShot_ = LedPattern::Confirm;
    hal::Nanoseconds oneShotUntil_ = 0;
};

} // namespace edgetrack::app
