// HAL interface: the synchronised pair of IR cameras, delivering buffers allocated once.
#pragma once

#include <array>
#include <cstdint>

#include "core/result.hpp"
#include "hal/types.hpp"

namespace edgetrack::hal {

/// \brief One 8-bit greyscale image in a buffer owned by the camera backend.
struct CameraFrame {
    const std::uint8_t* pixels = nullptr;
    int width_px = 0;
    int height_px = 0;
    /// Bytes from one row to the next (>= width_px).
    int stride_bytes = 0;
    Nanoseconds exposureStart = 0;
    Nanoseconds exposureEnd = 0;
    /// The sensor's own frame counter.
    std::uint64_t sequence = 0;

    Nanoseconds midExposure() const { return exposureStart + (exposureEnd - exposureStart) / 2; }
};

/**
 * \brief Both cameras' images of one exposure.
 *
 * Valid from CameraPair::acquire() until it is handed back with CameraPair::release(); the
 * buffers are then re-queued for a later exposure (libcamera's Request::reuse(ReuseBuffers)).
 */
struct StereoFrame {
    std::array<CameraFrame, 2> camera{};
    /// The exposure's number: one more for each exposure, so a gap means exposures were dropped
    /// or left unpaired. The simulated board numbers them as `edgetrack sim` numbers a
    /// recording's frames (frame k shows the scene at k / rate); libcamera's pair counts camera
    /// 0's sensor sequence from its first pair, continuing across restarts.
    std::uint64_t number = 0;
    /// Backend's buffer slot, for release().
    int slot = -1;

    Nanoseconds midExposure() const {
        return (camera[0].midExposure() + camera[1].midExposure()) / 2;
    }
};

enum class AcquireStatus {
    Frame,   ///< a paired frame was delivered
    Timeout, ///< nothing arrived within the timeout
    Stopped, ///< the pair is not started
    Failed,  ///< a camera failed; the owner should stop, report degraded and retry start()
};

/// \brief Run-time counters of a camera pair, for the status view.
struct CameraPairCounters {
    std::uint64_t delivered = 0;
    /// A frame of one camera without its partner within the pairing tolerance.
    std::uint64_t droppedUnpaired = 0;
    /// An exposure that found no free buffer because the consumer held them all.
    std::uint64_t droppedNoBuffer = 0;
    std::uint64_t failures = 0;
};

/// \brief Two cameras that expose together and deliver paired 8-bit frames.
class CameraPair {
public:
    virtual ~CameraPair() = default;

    /// \brief Allocate the buffers and start streaming.
    virtual Status start() = 0;
    virtual void stop() = 0;

    /**
     * \brief Wait up to \a timeout for the next paired frame.
     * \param frame filled on AcquireStatus::Frame; hand it back with release().
     */
    virtual AcquireStatus acquire(StereoFrame& frame, Nanoseconds timeout) = 0;

    /// \brief Return a frame's buffers to the backend for re-use.
    virtual void release(const StereoFrame& frame) = 0;

    virtual CameraPairCounters counters() const = 0;

    /// \return the nominal frame period (ns).
    virtual Nanoseconds framePeriod() const = 0;
};

} // namespace edgetrack::hal
