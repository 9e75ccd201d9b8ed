// Reads a recording (any level) or a .c3d file frame by frame, running blob detection and stereo
// where the level needs them, for the offline sub-commands.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <string>

#include "core/geometry.hpp"
#include "core/marker_pipeline.hpp"
#include "core/result.hpp"
#include "core/stereo_rig.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "firmware_app/formats/recording.hpp"

namespace edgetrack::app {

/// \brief One frame as the pipeline sees it.
struct MarkerFrame {
    std::int64_t frame = 0;
    double time_s = 0.0;
    /// Blobs of cameras 0 and 1 (raw pixels); empty when the input is at points level.
    std::span<const Blob> blobs[2];
    /// The frame's 3D markers, rig frame (mm): reconstructed, or as read.
    std::span<const Vec3> points_rig_mm;
};

/// \brief What reading the input took and refused.
struct FrameSourceSummary {
    /// "images", "blobs", "points" or "c3d".
    const char* level = "";
    std::size_t frames = 0;
    std::uint64_t blobs = 0;
    std::uint64_t points = 0;
    std::uint64_t rejectedNotRound = 0;
    std::uint64_t splitBlobs = 0;
    /// Blobs split again on the other camera's epipolar lines (MarkerPipelineCounters).
    std::uint64_t splitOnLines = 0;
    std::uint64_t blobOverflow = 0;
    std::uint64_t markerOverflow = 0;
    /// The recording's rig.toml, when it has one (a .c3d file has none).
    std::optional<StereoRig> rig;
};

/**
 * \brief The settings an offline command runs with: those of an edgetrack.toml, so that a
 * recording is processed as the board with that file would process it.
 */
struct CommandSettings {
    FirmwareConfig config{};
    /// Where they came from, for the command's summary.
    std::string source = "built-in defaults (as deploy/edgetrack.toml)";
};

/// \brief The settings of \a path (INTERFACES' `--config FILE`); none: the built-in defaults.
Result<CommandSettings> loadCommandSettings(const std::filesystem::path& path);

/**
 * \brief Call \a visit for every frame of \a input, in order.
 *
 * \a input is a recording directory (INTERFACES §1; the level is \a from or the lowest present)
 * or a .c3d file (points level: its valid samples, labels ignored). Images and blobs go through
 * a MarkerPipeline built from \a config, as on the board. Stops at the first error, from reading
 * or from \a visit.
 */
Result<FrameSourceSummary>
forEachMarkerFrame(const std::filesystem::path& input, std::optional<recording::Level> from,
                   const MarkerPipelineConfig& config,
                   const std::function<Status(const MarkerFrame&)>& visit);

/// \return whether \a input names a C3D file (by its extension).
bool isC3dFile(const std::filesystem::path& input);

/// \brief A recording at images or blobs level: the level to read, and its rig.toml.
struct PixelRecording {
    recording::Level level = recording::Level::Blobs;
    StereoRig rig;
};

/**
 * \brief Open \a input for a command that needs pixels (\a what, e.g. "reconstruct"): the level
 * (\a from or the lowest present) and the rig; a one-line error for a C3D file, a recording of
 * points only, or a bad rig.toml.
 */
Result<PixelRecording> openPixelRecording(const std::filesystem::path& input,
                                          std::optional<recording::Level> from,
                                          const std::string& what);

/**
 * \brief Make \a out ready to be written: created if missing; refused when it already holds
 * anything, so that no run mixes its files with an older one's.
 */
Status prepareOutputDirectory(const std::filesystem::path& out);

} // namespace edgetrack::app
