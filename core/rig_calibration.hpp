// Rig calibration by wand: camera 1's pose (and optionally both cameras' intrinsics) from wand
// sightings.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "core/stereo_rig.hpp"
#include "core/wand_finder.hpp"

namespace edgetrack {

/// \brief The wand as both cameras saw it in one frame pair.
struct WandFramePair {
    std::int64_t frame = 0;
    std::array<WandSighting, 2> sightings{};
};

struct RigCalibrationConfig {
    /// Refine fx, fy, cx, cy of both cameras too (distortion stays as given).
    bool refineIntrinsics = false;
    /// Scale of the robust (Huber) loss on reprojection errors (px): errors beyond it count
    /// linearly, so a few wrongly found wands cannot pull the rig.
    double robustLoss_px = 1.0;
    /// At most this many frame pairs go into the adjustment, spread evenly over the session:
    /// neighbouring frames of a slow wand add little, and this bounds the time.
    std::size_t maxFrames = 2500;
    /// Fewer usable frame pairs than this is an error, not a rig.
    std::size_t minFrames = 50;
    /// RANSAC for the essential matrix: iterations, inlier threshold (px) and random seed.
    int ransacIterations = 600;
    double ransacThreshold_px = 2.0;
    std::uint64_t seed = 1;
    /// A frame pair is refused after the first adjustment when a marker's reprojection error
    /// exceeds this many times the median frame's RMS, and at least outlierFloor_px.
    double outlierFactor = 6.0;
    double outlierFloor_px = 1.0;
    /// The report warns below this share of image cells covered by the wand (8 x 8 grid) ...
    double poorCoverage = 0.35;
    /// ... above this reprojection RMS (px) ...
    double poorReprojection_px = 0.5;
    /// ... and above this RMS of the wand's length error (mm).
    double poorLength_mm = 1.0;
};

/// \brief What a rig calibration used and how well the rig it found fits.
struct RigCalibrationReport {
    std::size_t framePairs = 0;    ///< pairs with the wand in both images
    std::size_t framesUsed = 0;    ///< in the final adjustment
    std::size_t framesRefused = 0; ///< refused as outliers, or unresolved ends
    std::size_t framesSkipped = 0; ///< left out to stay within maxFrames
    std::array<double, 2> reprojectionRms_px{};
    /// End-to-end wand length of every used pair, triangulated with the new rig (no wand
    /// constraint), against the true length (mm).
    double lengthErrorRms_mm = 0.0;
    double lengthError95_mm = 0.0;
    double lengthErrorMax_mm = 0.0;
    /// Share of each image's 8 x 8 cells the wand's markers were seen in.
    std::array<double, 2> coverage{};
    /// Camera 1's pose change from the starting rig: rotation (degrees) and position (mm).
    double rotationChange_deg = 0.0;
    double positionChange_mm = 0.0;
    /// Solver iterations over both adjustments (an assessment, whose wand poses are solved one
    /// by one, counts its slowest pose's).
    int solverIterations = 0;
    /// Human-readable warnings: poor coverage, poor agreement.
    std::vector<std::string> warnings;
    /// True when nothing warned.
    bool good() const { return warnings.empty(); }
};

struct RigCalibrationResult {
    StereoRig rig;
    RigCalibrationReport report;
};

/**
 * \brief Measure camera 1's pose relative to camera 0 from a wand waved in front of both.
 *
 * Steps: (1) the essential matrix of the markers' undistorted rays, by RANSAC over eight-point
 * solutions, gives camera 1's rotation and the direction of its position, whatever the start;
 * the wand's length gives the scale; (2) a bundle adjustment (Ceres, Huber loss) refines camera
 * 1's pose, every wand pose (a point and a direction, the markers at their known offsets) and,
 * when asked, both cameras' focal lengths and principal points, against the raw blob centres
 * through the full lens model; (3) frame pairs that fit badly are refused and the adjustment
 * repeated. Camera 0 stays the rig frame. \a start supplies intrinsics and distortion; its
 * camera 1 pose only decides the order of markers where both images leave a wand's ends open.
 *
 * Runs once, after a session, off the frame loop: it allocates (Ceres does) and takes seconds.
 * \return the new rig and its report, or a one-line error when the wand data cannot give one.
 */
Result<RigCalibrationResult> calibrateRig(const StereoRig& start, const WandSpec& wand,
                                          std::span<const WandFramePair> pairs,
                                          const RigCalibrationConfig& config);

/**
 * \brief How well \a rig fits wand sightings: the wand poses are adjusted as calibrateRig()
 * adjusts them, the rig stays as it is, and the report says how it fits (its rig fields are
 * those of \a rig). The board compares this with a new rig's report to keep the better one.
 */
Result<RigCalibrationReport> assessRig(const StereoRig& rig, const WandSpec& wand,
                                       std::span<const WandFramePair> pairs,
                                       const RigCalibrationConfig& config);

} // namespace edgetrack
