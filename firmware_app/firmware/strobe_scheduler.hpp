// Schedules the IR LED ring's pulses so that they light every coming exposure of both cameras.
#pragma once

#include <cstdint>

#include "hal/camera_pair.hpp"
#include "hal/led_ring.hpp"

namespace edgetrack::app {

/**
 * \brief Lights the ring only while the sensors integrate (a strobe), a few exposures ahead.
 *
 * After the cameras start, the ring is lit continuously: the first exposures come before any
 * pulse could be scheduled. Each delivered frame tells when its exposure began; the next
 * exposures follow at the frame period, and pulses are scheduled for the ones not yet covered,
 * from `lead` before the first sensor starts to `tail` after the last one stops.
 */
class StrobeScheduler {
public:
    /// \param lead_ns, tail_ns margins of each pulse around the exposure (ns).
    StrobeScheduler(hal::Nanoseconds lead_ns, hal::Nanoseconds tail_ns)
        : lead_ns_(lead_ns)
        , tail_ns_(tail_ns) {}

    /// \brief The cameras (re)started: light the ring continuously until pulses take over.
    void restart(hal::LedRing& ring);

    /**
     * \brief Schedule pulses for the exposures after \a frame's, taken every \a period.
     * \return how many pulses \a ring refused (its queue full).
     */
    std::uint64_t schedule(const hal::StereoFrame& frame, hal::Nanoseconds period,
                           hal::LedRing& ring);

private:
    hal::Nanoseconds lead_ns_;
    hal::Nanoseconds tail_ns_;
    /// Start of the last exposure a pulse was scheduled for.
    hal::Nanoseconds lastPulsedExposure_ = 0;
    bool pulsing_ = false;
    std::uint64_t framesSinceRestart_ = 0;
};

} // namespace edgetrack::app
