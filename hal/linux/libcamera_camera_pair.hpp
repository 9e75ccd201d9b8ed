// Linux backend: the two IR cameras through libcamera, their frames paired by sensor timestamp.
#pragma once

#include <array>
#include <condition_variable>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include "core/ring_buffer.hpp"
#include "hal/camera_pair.hpp"
#include "hal/linux/posix_clock.hpp"

namespace libcamera {
class Camera;
class CameraConfiguration;
class CameraManager;
class ControlList;
class FrameBufferAllocator;
class Request;
class Stream;
} // namespace libcamera

namespace edgetrack::linux_hal {

/// \brief Settings of the camera pair (the [cameras] section of the configuration).
struct LibcameraPairConfig {
    /// libcamera ids (`cam --list`) of camera 0 (left, the rig frame) and camera 1.
    std::array<std::string, 2> ids;
    int width_px = 1280;
    int height_px = 800;
    double frameRate_hz = 100.0;
    double exposure_us = 1000.0;
    /// Frames whose mid-exposures differ by more than this are not a pair (us).
    double pairTolerance_us = 500.0;
    /// Buffers (requests) per camera, allocated once at start().
    int buffers = 4;
};

/// \brief How one camera's pixels reach the pipeline's 8-bit frame.
enum class PixelPath : std::uint8_t {
    /// 8-bit grey (R8) or the luma plane of a YUV format: the frame points into the camera's
    /// buffer, no copy.
    Direct,
    /// Packed 24- or 32-bit RGB (virtual cameras such as vimc): converted to grey, one pass.
    ConvertRgb,
};

/// \brief Counters beyond hal::CameraPairCounters, for the status view.
struct LibcameraPairCounters {
    /// Frames converted from RGB (0 on the board, whose sensors are monochrome).
    std::uint64_t converted = 0;
    /// Requests that completed with an error or were cancelled while streaming.
    std::uint64_t failedRequests = 0;
};

/**
 * \brief CameraPair on two libcamera cameras, opened by id.
 *
 * start() acquires both cameras, configures one stream each at the configured size (refusing a
 * camera that adjusts the size: the stereo calibration is for that size), prefers formats whose
 * 8-bit luma can be used in place (R8, YUV420, NV12, NV21) over packed RGB, asks for the frame
 * duration and a fixed exposure where the camera has those controls, allocates and maps the
 * buffers and queues one request per buffer. Completed requests are re-queued with
 * Request::reuse(ReuseBuffers) when the consumer hands their frame back: after start() nothing
 * is allocated by this class.
 *
 * Each frame's exposure start is the sensor timestamp (controls::SensorTimestamp, else the
 * buffer's CLOCK_MONOTONIC stamp) and its end adds the reported exposure time (else the
 * configured one). acquire() pairs the oldest frames of the two cameras when their mid-exposures
 * lie within the tolerance and otherwise drops the older one (droppedUnpaired); gaps in a
 * camera's sequence numbers are exposures that found no queued buffer (droppedNoBuffer).
 *
 * A camera that is unplugged, whose driver goes away or whose requests fail makes acquire()
 * return AcquireStatus::Failed; the owner stops the pair and calls start() again later, which
 * succeeds once the camera is back (the camera manager follows hot-plug through udev).
 */
class LibcameraCameraPair : public hal::CameraPair {
public:
    explicit LibcameraCameraPair(LibcameraPairConfig config);
    ~LibcameraCameraPair() override;
    LibcameraCameraPair(const LibcameraCameraPair&) = delete;
    LibcameraCameraPair& operator=(const LibcameraCameraPair&) = delete;

    /// \return false when libcamera's camera manager did not start; errorText() says why.
    bool isValid() const { return managerStarted_; }
    /// \return why the construction or the last start() failed.
    const std::string& errorText() const { return errorText_; }

    Status start() override;
    void stop() override;
    hal::AcquireStatus acquire(hal::StereoFrame& frame, hal::Nanoseconds timeout) override;
    void release(const hal::StereoFrame& frame) override;
    hal::CameraPairCounters counters() const override;
    hal::Nanoseconds framePeriod() const override { return framePeriod_; }

    LibcameraPairCounters libcameraCounters() const;
    /// \return the cameras' ids, sizes and pixel formats as configured, e.g. for the log.
    std::string describe() const;
    /// \return how camera \a index delivers 8-bit pixels (valid while started).
    PixelPath pixelPath(int index) const { return sides_[static_cast<std::size_t>(index)].path; }
    /// \return the ids of every camera libcamera knows now.
    std::vector<std::string> cameraIds() const;
    /**
     * \brief Whether only a new process can use the cameras again.
     *
     * libcamera 0.0.3 neither notices a camera whose device is removed while it streams (its
     * requests just stop completing) nor survives stopping it (an assertion aborts the process),
     * and it refuses a second camera with the same id when the device comes back. This pair
     * therefore notices the removal itself (a camera silent for 10 frame periods while a video or
     * media node it holds has been deleted), reports AcquireStatus::Failed, leaves that camera
     * unstopped and returns true here: the owner exits and systemd starts it again.
     */
    bool needsProcessRestart() const;

private:
    struct MappedBuffer {
        void* base = nullptr;
        std::size_t length = 0;
        /// Plane 0 (the image, or the luma plane) within the mapping.
        const std::uint8_t* pixels = nullptr;
    };
    /// A completed request: its buffer and the frame's timing (pixels are set by acquire()).
    struct Completed {
        int buffer = -1;
        hal::CameraFrame frame;
    };
    struct Side {
        std::shared_ptr<libcamera::Camera> camera;
        std::unique_ptr<libcamera::CameraConfiguration> configuration;
        libcamera::Stream* stream = nullptr;
        std::unique_ptr<libcamera::FrameBufferAllocator> allocator;
        /// Frame duration and exposure for Camera::start(), where the camera has the controls.
        std::unique_ptr<libcamera::ControlList> startControls;
        std::vector<std::unique_ptr<libcamera::Request>> requests;
        std::vector<MappedBuffer> mapped;
        /// Grey images, one per buffer, when the camera delivers RGB.
        std::vector<std::vector<std::uint8_t>> grey;
        PixelPath path = PixelPath::Direct;
        int bytesPerPixel = 1;
        int stride_bytes = 0;
        bool acquired = false;
        bool started = false;
        /// Completed requests not yet paired, oldest first (a ring of `buffers` entries).
        RingBuffer<Completed> completed{0};
        bool sequenceKnown = false;
        std::uint64_t lastSequence = 0;
        /// When this camera last completed a request (CLOCK_MONOTONIC), or started.
        hal::Nanoseconds lastCompletion = 0;
        /// A request was cancelled under it or libcamera reported it disconnected.
        bool faulted = false;
        /// Its device went away while streaming: it cannot be stopped (see stopSides()).
        bool removed = false;
    };
    struct PairSlot {
        std::array<int, 2> buffer{-1, -1};
        bool inUse = false;
    };

    Status startSide(int index);
    void stopSides();
    void onRequestCompleted(int index, libcamera::Request* request);
    void onDisconnected(int index);
    /// \brief Re-queue a buffer's request; called with mutex_ held.
    void requeue(int index, int buffer);
    Completed popCompleted(int index);
    void convertToGrey(Side& side, int buffer);
    /// \brief Mark a silent or faulted camera removed when a video or media node we hold has
    /// gone; called with mutex_ held.
    void checkForRemovedCamera();
    /// \brief AcquireStatus::Failed, counted, after looking for a removed camera; mutex_ held.
    hal::AcquireStatus fail();

    LibcameraPairConfig config_;
    PosixClock clock_;
    hal::Nanoseconds framePeriod_ = 0;
    hal::Nanoseconds pairTolerance_ = 0;
    std::unique_ptr<libcamera::CameraManager> manager_;
    bool managerStarted_ = false;
    std::string errorText_;
    std::array<Side, 2> sides_;
    std::vector<PairSlot> slots_;
    /// Removed cameras, kept alive and unstopped until the process ends.
    std::vector<Side> abandoned_;

    // Shared with libcamera's thread, which completes requests and reports disconnection.
    mutable std::mutex mutex_;
    std::condition_variable frameArrived_;
    bool streaming_ = false;
    bool failed_ = false;
    /// Frame number minus camera 0's sequence number (unset until the first pair after start()).
    std::optional<std::int64_t> sequenceToNumber_;
    std::uint64_t nextNumber_ = 0;
    hal::CameraPairCounters counters_{};
    LibcameraPairCounters libcameraCounters_{};
};

} // namespace edgetrack::linux_hal
