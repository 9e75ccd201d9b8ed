// Pose CSV files (INTERFACES §5): one row per body found in a frame, written by `track`.
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/rigid_transform.hpp"

namespace edgetrack::app {

/// \brief One body's pose in one frame.
struct PoseRow {
    std::int64_t frame = 0;
    double time_s = 0.0;
    std::uint32_t body = 0;
    /// Maps model coordinates (mm) to rig coordinates (mm), as truth.csv does.
    RigidTransform T_rig_from_model;
    std::uint32_t markers = 0;
    double rms_mm = 0.0;
};

/// \brief The header line of a pose CSV, with its newline.
inline constexpr const char* kPoseCsvHeader =
    "frame,time_s,body,x,y,z,qw,qx,qy,qz,markers,rms_mm\n";

/// \brief Append one row: positions to 1e-4 mm, quaternion components to 1e-9, scalar first and
/// w >= 0.
void appendPoseRow(std::string& out, const PoseRow& row);

/// \brief Read a pose CSV: exact header, frames in order, unit quaternions, non-negative counts.
Result<std::vector<PoseRow>> readPoses(const std::filesystem::path& path);

} // namespace edgetrack::app
