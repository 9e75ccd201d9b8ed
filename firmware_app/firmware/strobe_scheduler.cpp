// Schedules the IR LED ring's pulses so that they light every coming exposure of both cameras.
#include "firmware_app/firmware/strobe_scheduler.hpp"

#include <algorithm>

namespace edgetrack::app {

namespace {

/// Pulses are scheduled this many exposures ahead of the last delivered one: a frame whose
/// processing stalls the loop for up to this many periods still leaves every exposure lit.
constexpr int kStrobeAhead = 4;
/// The ring stays lit continuously for the first frames, until pulses cover the exposures.
constexpr std::uint64_t kContinuousFrames = 2;

} // namespace

void StrobeScheduler::restart(hal::LedRing& ring) {
    pulsing_ = false;
    framesSinceRestart_ = 0;
    ring.setContinuous(true);
}

std::uint64_t StrobeScheduler::schedule(const hal::StereoFrame& frame, hal::Nanoseconds period,
                                        hal::LedRing& ring) {
    const hal::Nanoseconds start =
        std::min(frame.camera[0].exposureStart, frame.camera[1].exposureStart);
    const hal::Nanoseconds end = std::max(frame.camera[0].exposureEnd, frame.camera[1].exposureEnd);
    std::uint64_t refused = 0;
    for (int k = 1; k <= kStrobeAhead; ++k) {
        const hal::Nanoseconds next = start + k * period;
        if (pulsing_ && next <= lastPulsedExposure_ + period / 2)
            continue;
        if (!ring.schedulePulse(next - lead_ns_, next + (end - start) + tail_ns_))
            ++refused;
        lastPulsedExposure_ = next;
        pulsing_ = true;
    }
    // Lit continuously until the pulses already cover the exposure being taken now.
    if (++framesSinceRestart_ == kContinuousFrames)
        ring.setContinuous(false);
    return refused;
}

} // namespace edgetrack::app
