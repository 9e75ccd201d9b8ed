// HAL interface: the IR LED ring, lit continuously or strobed in step with exposure.
#pragma once

#include <cstdint>

#include "hal/types.hpp"

namespace edgetrack::hal {

/**
 * \brief The ring of IR LEDs around the lenses.
 *
 * Strobing lights the markers only while the sensors integrate, which keeps the LEDs cool and
 * ambient IR low. The firmware schedules one pulse per exposure, a frame ahead.
 */
class LedRing {
public:
    virtual ~LedRing() = default;

    /// \brief Light the ring continuously (true) or leave it to scheduled pulses (false).
    virtual void setContinuous(bool on) = 0;

    /**
     * \brief Light the ring from \a onAt to \a offAt (monotonic ns).
     * \return false when the pulse queue is full; the pulse is then dropped and counted.
     */
    virtual bool schedulePulse(Nanoseconds onAt, Nanoseconds offAt) = 0;

    /// \return pulses dropped because the queue was full.
    virtual std::uint64_t droppedPulses() const = 0;
};

} // namespace edgetrack::hal
