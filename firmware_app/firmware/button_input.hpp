// The push button's raw edges turned into debounced short and long presses.
#pragma once

#include <array>
#include <cstddef>

#include "hal/button.hpp"

namespace edgetrack::app {

enum class ButtonEvent {
    None,
    /// Pressed and released before the long-press time, and no second press followed within
    /// the double-press time: start or end a calibration.
    ShortPress,
    /// Two short presses, the second starting within the double-press time of the first's
    /// release: start (or end) a rig calibration.
    DoublePress,
    /// Held for the long-press time: reported while still held, so the LED confirms at once.
    LongPress,
};

/**
 * \brief Debounces the button and classifies presses.
 *
 * A level counts once it has held for the debounce time without another edge; a press starts
 * at its first edge. Edges are fed in time order (as libgpiod reports them) and poll() settles
 * everything up to a time, so a press and release read in one go are classified by their own
 * times, not by when they were read.
 */
class ButtonInput {
public:
    /// \param doublePress 0: every short press is reported at its release (no double presses).
    ButtonInput(hal::Nanoseconds debounce, hal::Nanoseconds longPress,
                hal::Nanoseconds doublePress = 0)
        : debounce_(debounce)
        , longPress_(longPress)
        , doublePress_(doublePress) {}

    /// \brief A raw edge from hal::Button::nextEdge().
    void edge(const hal::ButtonEdge& edge);

    /// \brief Settle up to \a now. \return the next press event, or None when there is none.
    ButtonEvent poll(hal::Nanoseconds now);

    /// \return the debounced level: the button is held down.
    bool held() const { return stable_; }

private:
    void settle(hal::Nanoseconds until);
    void releaseShort(hal::Nanoseconds releasedAt);
    void emit(ButtonEvent event);

    hal::Nanoseconds debounce_;
    hal::Nanoseconds longPress_;
    hal::Nanoseconds doublePress_;
    /// A short press released at shortReleasedAt_ waits for a second one.
    bool shortPending_ = false;
    hal::Nanoseconds shortReleasedAt_ = 0;
    bool raw_ = false;
    hal::Nanoseconds rawSince_ = 0;
    bool stable_ = false;
    hal::Nanoseconds pressedAt_ = 0;
    bool longReported_ = false;
    std::array<ButtonEvent, 4> pending_{};
    std::size_t pendingCount_ = 0;
};

} // namespace edgetrack::app
