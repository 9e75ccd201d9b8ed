// Linux backend: the board's clock on CLOCK_MONOTONIC, wall time from CLOCK_REALTIME.
#pragma once

#include "hal/clock.hpp"

namespace edgetrack::linux_hal {

/// \brief hal::Clock on CLOCK_MONOTONIC, the clock of libcamera's sensor timestamps and of
/// libgpiod's line events, so that exposure, strobe and button times compare directly.
class PosixClock : public hal::Clock {
public:
    hal::Nanoseconds now() const override;
    void sleepUntil(hal::Nanoseconds deadline) override;
    hal::Nanoseconds utcOffset() const override;
};

} // namespace edgetrack::linux_hal
