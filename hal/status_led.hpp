// HAL interface: the status LED that shows the board's state.
#pragma once

namespace edgetrack::hal {

/// \brief One LED; blink patterns are made by the firmware.
class StatusLed {
public:
    virtual ~StatusLed() = default;
    virtual void set(bool on) = 0;
};

} // namespace edgetrack::hal
