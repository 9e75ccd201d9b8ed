// HAL interface: the board's monotonic clock.
#pragma once

#include "hal/types.hpp"

namespace edgetrack::hal {

/// \brief Monotonic time source; on the simulated board it is virtual time.
class Clock {
public:
    virtual ~Clock() = default;

    /// \return the current time (ns).
    virtual Nanoseconds now() const = 0;

    /// \brief Block until now() >= \a deadline (returns at once if it already is).
    virtual void sleepUntil(Nanoseconds deadline) = 0;

    /// \return UTC (ns since 1970) minus now(): added to a monotonic time it gives wall time,
    /// e.g. for DTrack's `ts` (CLOCK_REALTIME - CLOCK_MONOTONIC on Linux).
    virtual Nanoseconds utcOffset() const = 0;
};

} // namespace edgetrack::hal
