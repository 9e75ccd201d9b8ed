// HAL interface: the status LED that shows the board's state.
#pragma once

namespace edgetrack::hal {

/// \brief One LED; blink patterns are made by the firmware.
class StatusLed {
public:
    virtual ~StatusLed() = default;
    /// \brief Called every frame with the level the LED should show. A backend writes only
    /// changes, and one that could not drive its LED (a GPIO line held by another process)
    /// tries again here and then shows the level it is given.
    virtual void set(bool on) = 0;
};

} // namespace edgetrack::hal
