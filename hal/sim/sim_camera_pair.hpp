// Simulated camera pair: renders the world into buffers allocated once, lit by the sim LED ring.
#pragma once

#include <cstdint>
#include <vector>

#include "hal/camera_pair.hpp"
#include "hal/sim/devices.hpp"
#include "hal/sim/world.hpp"

namespace edgetrack::sim {

/**
 * \brief Two cameras exposing the simulated world at the scene's frame rate.
 *
 * Behaves like the libcamera backend: a fixed pool of buffer pairs; acquire() hands out the next
 * exposure and the caller gives it back with release(). If every buffer is held when an exposure
 * completes, that exposure is dropped and counted. Time is the board's clock: acquire() advances
 * it to the end of the exposure plus readout. Markers show only if the LED ring was lit during
 * the exposure.
 */
class SimCameraPair : public hal::CameraPair {
public:
    SimCameraPair(const World& world, SimClock& clock, SimLedRing& led, int bufferPairs = 4);

    Status start() override;
    void stop() override;
    hal::AcquireStatus acquire(hal::StereoFrame& frame, Nanoseconds timeout) override;
    void release(const hal::StereoFrame& frame) override;
    hal::CameraPairCounters counters() const override { return counters_; }
    Nanoseconds framePeriod() const override { return period_; }

    /// \return start of exposure of the next frame (the firmware strobes the LED for it).
    Nanoseconds nextExposureStart() const;
    Nanoseconds exposureDuration() const { return exposure_; }

    // Faults, for tests of the degraded state.
    /// \brief Cameras stop delivering (a cable pulled): acquire() times out.
    void setStalled(bool stalled) { stalled_ = stalled; }
    /// \brief Cameras fail outright: acquire() reports Failed until start() is called again.
    void injectFailure() { failed_ = true; }
    /// \brief Every n-th exposure loses camera 1's frame (0: never).
    void dropPartnerEvery(std::uint64_t n) { dropPartnerEvery_ = n; }
    /// \brief Each image also shows \a perCamera small round reflections at random places (a
    /// burst of spurious blobs, e.g. sunlight on a shiny surface); 0 ends the burst.
    void setSpuriousBurst(int perCamera) { spuriousBurst_ = perCamera; }

    /// \return the observation rendered into the last delivered frame (ground truth for tests).
    const Observation& lastObservation() const { return observation_; }

    /// \brief Time between the end of exposure and the frame being available (sensor readout).
    static constexpr Nanoseconds kReadout = 2 * hal::kNanosecondsPerMillisecond;
    /// \brief Camera 1 starts this much after camera 0 (hardware sync is never perfect).
    static constexpr Nanoseconds kSyncSkew = 15'000;

private:
    Nanoseconds exposureStart(std::uint64_t index) const;
    void addSpuriousBurst(std::uint64_t index);

    const World& world_;
    SimClock& clock_;
    SimLedRing& led_;
    FrameRenderer renderer_;
    Nanoseconds period_;
    Nanoseconds exposure_;
    int width_;
    int height_;
    std::vector<std::vector<std::uint8_t>> buffers_;
    std::vector<bool> held_;
    Observation observation_;
    hal::CameraPairCounters counters_{};
    std::uint64_t nextIndex_ = 0;
    /// Exposures read out while the host was behind with no buffer free for them: dropped.
    std::uint64_t skipFrom_ = 0;
    std::uint64_t skipTo_ = 0;
    std::uint64_t dropPartnerEvery_ = 0;
    int spuriousBurst_ = 0;
    bool started_ = false;
    bool stalled_ = false;
    bool failed_ = false;
};

} // namespace edgetrack::sim
