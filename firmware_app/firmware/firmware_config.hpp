// The firmware's configuration (deploy/edgetrack.toml): every stage's settings, capacities and I/O.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/calibration_completion.hpp"
#include "core/marker_pipeline.hpp"
#include "core/model_tracker.hpp"
#include "core/object_calibrator.hpp"
#include "core/pose_filter.hpp"
#include "core/result.hpp"
#include "core/stereo_rig.hpp"
#include "firmware_app/firmware/can_pose.hpp"
#include "hal/udp.hpp"

namespace edgetrack::app {

/// \brief The two cameras and how their frames are paired and queued.
struct CameraSettings {
    /// libcamera ids of camera 0 (left, defines the rig frame) and camera 1.
    std::string ids[2] = {"/base/axi/pcie@120000/rp1/i2c@88000/ov9281@60",
                          "/base/axi/pcie@120000/rp1/i2c@80000/ov9281@60"};
    int width_px = 1280;
    int height_px = 800;
    double frameRate_hz = 100.0;
    double exposure_us = 1000.0;
    /// Two frames whose mid-exposures differ by more than this are not a pair.
    double pairTolerance_us = 500.0;
    /// Buffer pairs the camera backend allocates once.
    int buffers = 4;
    /// Frames waiting between capture and processing; when full the oldest is dropped.
    std::size_t queueDepth = 2;
    /// No frame for this long puts the board in the degraded state.
    double timeout_s = 0.5;
    /// In the degraded state, the cameras are restarted this often.
    double retry_s = 1.0;
    /// The stereo calibration (INTERFACES §2); empty on the simulated board (the scene's rig).
    std::filesystem::path rigFile;
    /// Simulated board only: the board starts with the scene's rig knocked, camera 1 moved by
    /// [0] mm and turned by [1] degrees, while the cameras render with the true one; a rig
    /// calibration (double press, scene wand) mends it.
    std::array<double, 2> simRigKnock{0.0, 0.0};

    bool operator==(const CameraSettings&) const = default;
};

/// \brief GPIO lines (libgpiod names) and the LED strobe timing.
struct GpioSettings {
    std::string chip = "gpiochip0";
    std::string ledLine = "IR_LED";
    std::string buttonLine = "BUTTON";
    std::string statusLine = "STATUS_LED";
    /// The button pulls its line low when pressed (with the line's pull-up); false: it drives
    /// the line high (with a pull-down).
    bool buttonActiveLow = true;
    /// The ring lights this long before the first sensor starts integrating...
    double strobeLead_us = 100.0;
    /// ...and stays lit this long after the last one stops.
    double strobeTail_us = 100.0;
    /// A level must hold this long to count (contact bounce).
    double debounce_ms = 30.0;
    /// A press held this long is a long press (delete all models).
    double longPress_s = 3.0;
    /// A second short press starting within this time of the first's release makes a double
    /// press (rig calibration); a single short press is known only once it has passed.
    double doublePress_s = 0.4;

    bool operator==(const GpioSettings&) const = default;
};

/// \brief When a field calibration ends on its own.
struct CalibrationSessionSettings {
    /// Never ends on its own before this.
    double minDuration_s = 10.0;
    /// Ends when the learnt models (objects and markers) have not changed for this long.
    double settle_s = 5.0;
    /// Ends at the latest after this.
    double maxDuration_s = 120.0;
    /// The growing models are sent to the host (DTrack `3d` lines) this often.
    double previewRate_hz = 10.0;
    /// The session keeps every frame for the completion stage: max_duration_s of frames at the
    /// camera rate, with room for this many points a frame on average (24 bytes each; 120 s at
    /// 100 Hz and 32 points are 9.2 MB). A session whose buffer fills ends there.
    std::size_t bufferPointsPerFrame = 32;

    bool operator==(const CalibrationSessionSettings&) const = default;
};

/// \brief DTrack UDP output.
struct UdpSettings {
    bool enabled = true;
    std::vector<hal::UdpEndpoint> destinations{hal::UdpEndpoint{{127, 0, 0, 1}, 5000}};
    /// Each frame carries DTrack's `ts2 SECONDS MICROSECONDS LATENCY_US` line: the mid-exposure
    /// as UTC and the latency from mid-exposure to sending, where DTrackSDK reads it.
    bool latencyLine = true;

    bool operator==(const UdpSettings&) const = default;
};

/// \brief CAN output.
struct CanSettings {
    bool enabled = false;
    std::string interface = "can0";
    /// One CAN FD frame per body; classic CAN otherwise (three frames per body).
    bool fd = false;
    std::uint32_t bitrate = 500000;
    std::uint32_t dataBitrate = 2000000;
    CanPoseLayout layout{};

    bool operator==(const CanSettings&) const = default;
};

/// \brief The flash partitions that keep the models and the board's own rig.
struct FlashSettings {
    /// MTD device or file on the board.
    std::filesystem::path device = "/var/lib/edgetrack/models.flash";
    std::size_t size_bytes = 1u << 20;
    std::size_t eraseBlock_bytes = 4096;
    /// The rig's partition (rig calibration by wand), same erase block.
    std::filesystem::path rigDevice = "/var/lib/edgetrack/rig.flash";
    std::size_t rigSize_bytes = 64u << 10;

    bool operator==(const FlashSettings&) const = default;
};

/// \brief The board's own rig calibration by wand (a double press of the button).
struct RigCalibrationSettings {
    /// The wand's marker spacings from one end (mm), as `rig calibrate --wand`.
    std::vector<double> wand_mm{55.0, 102.0};
    /// A session ends by itself after this long (a short press ends it sooner).
    double duration_s = 30.0;
    /// Frame pairs with the wand the session keeps (sized at start-up: about 300 bytes each).
    std::size_t maxFrames = 6000;
    /// Refine both cameras' focal lengths and principal points too.
    bool refineIntrinsics = false;
    /// While tracking, the RMS epipolar error of matched markers (rectified px) above which the
    /// status view says the rig has drifted and a rig calibration is due.
    double driftWarning_px = 1.0;

    bool operator==(const RigCalibrationSettings&) const = default;
};

/// \brief Status reporting and the frame-time budget.
struct HealthSettings {
    /// A console status line this often (0: never).
    double statusInterval_s = 1.0;
    /// A frame whose processing takes longer is counted as over budget (0: the frame period).
    double frameBudget_ms = 0.0;

    bool operator==(const HealthSettings&) const = default;
};

/// \brief Everything `edgetrack run` needs, with defaults that suit the simulated rig.
struct FirmwareConfig {
    CameraSettings cameras{};
    GpioSettings gpio{};
    /// [blobs] and [stereo]: the marker front end.
    MarkerPipelineConfig markers{};
    CalibrationConfig calibration{};
    CalibrationSessionSettings session{};
    /// The completion stage at the end of a session; its capacities and S_min follow
    /// [calibration] (max_objects, max_markers_per_object, min_model_markers, smin_*).
    CompletionConfig completion{};
    ModelTrackingConfig tracking{};
    /// Models kept and tracked at once.
    std::size_t maxModels = 16;
    PoseFilterConfig filter{};
    FlashSettings flash{};
    RigCalibrationSettings rig{};
    UdpSettings udp{};
    CanSettings can{};
    HealthSettings health{};

    bool operator==(const FirmwareConfig&) const = default;
};

/**
 * \brief Parse a configuration; every key is optional and defaults as above.
 *
 * Refuses unknown sections and keys (a typo would otherwise be silently ignored), wrong types and
 * values out of range, with an error that names the file, line and key, e.g.
 * `edgetrack.toml:12: [tracking] distance_tolerance_mm: must be > 0 (got -1)`.
 */
Result<FirmwareConfig> parseFirmwareConfig(std::string_view text, std::string_view name);

/// \brief Read and parse \a path.
Result<FirmwareConfig> loadFirmwareConfig(const std::filesystem::path& path);

/// \brief Frames a calibration session can hold: max_duration_s at the camera rate, and a
/// margin for jitter.
std::size_t sessionFrames(const FirmwareConfig& config);

/// \brief What the configuration's capacities allocate at start-up, in bytes, by its largest
/// parts (the rest is a few megabytes).
struct MemoryNeed {
    /// The cameras' frame buffers: two cameras, [cameras] buffers each, 8-bit (RGB as libcamera
    /// may deliver it is three times that: counted so).
    std::uint64_t images = 0;
    /// Blob detection's per-pixel working images, both cameras.
    std::uint64_t detection = 0;
    /// The calibration session buffer: sessionFrames() frames of buffer_points_per_frame points.
    std::uint64_t session = 0;
    /// The model and rig partitions (the simulated board holds them in memory).
    std::uint64_t flash = 0;

    std::uint64_t total() const { return images + detection + session + flash; }
};
MemoryNeed memoryNeed(const FirmwareConfig& config);

/// A configuration that would allocate more than this is refused: the smallest boards of the
/// Raspberry Pi class have 1 GiB, shared with the system.
inline constexpr std::uint64_t kMaxMemoryNeed_bytes = 512ull << 20;

/**
 * \brief The completion stage's settings for a session on \a rig: [completion], with the
 * capacities and S_min of [calibration], seen from between the cameras (none: the rig origin).
 */
CompletionConfig completionFor(const FirmwareConfig& config, const StereoRig* rig);
/// \brief Parse "HOST:PORT" with a dotted IPv4 host (multicast groups included).
Result<hal::UdpEndpoint> parseEndpoint(std::string_view text);

} // namespace edgetrack::app
