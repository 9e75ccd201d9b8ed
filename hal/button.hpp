// HAL interface: the push button as timestamped edge events.
#pragma once

#include "hal/types.hpp"

namespace edgetrack::hal {

/// \brief A change of the button's level, as libgpiod reports a line event.
struct ButtonEdge {
    Nanoseconds time = 0;
    bool pressed = false;
};

/// \brief The board's push button. Raw edges; debouncing and press lengths are the firmware's.
class Button {
public:
    virtual ~Button() = default;

    /// \brief Take the oldest pending edge without blocking. \return false when there is none.
    virtual bool nextEdge(ButtonEdge& edge) = 0;
};

} // namespace edgetrack::hal
