// Reads a recording (any level) or a .c3d file frame by frame, running blob detection and stereo
// where the level needs them, for the offline sub-commands.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>

#include "core/blob_detector.hpp"
#include "core/geometry.hpp"
#include "core/result.hpp"
#include "firmware_app/recording/recording.hpp"

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
    std::uint64_t blobOverflow = 0;
    std::uint64_t markerOverflow = 0;
};

/**
 * \brief Call \a visit for every frame of \a input, in order.
 *
 * \a input is a recording directory (INTERFACES §1; the level is \a from or the lowest present)
 * or a .c3d file (points level: its valid samples, labels ignored). Stops at the first error,
 * from reading or from \a visit.
 */
Result<FrameSourceSummary>
forEachMarkerFrame(const std::filesystem::path& input, std::optional<recording::Level> from,
                   const std::function<Status(const MarkerFrame&)>& visit);

/// \return whether \a input names a C3D file (by its extension).
bool isC3dFile(const std::filesystem::path& input);

/**
 * \brief Make \a out ready to be written: created if missing; refused when it already holds
 * anything, so that no run mixes its files with an older one's.
 */
Status prepareOutputDirectory(const std::filesystem::path& out);

} // namespace edgetrack::app
