// Turns MoCapRasp's blob logs (../shared/realdata/MoCapRasp) into blobs-level recordings.
#pragma once

#include <cstddef>
#include <filesystem>

#include "core/result.hpp"

namespace edgetrack::test {

/// \brief What a conversion wrote.
struct MoCapRaspSummary {
    std::size_t frames = 0; ///< rows of frames.csv: frames either camera saw
    std::size_t framesBothCameras = 0;
    std::size_t blobsPerCamera = 0; ///< blobs in each row of the log
};

/**
 * \brief Write recording \a out (INTERFACES §1, blobs level) from MoCapRasp log \a csv.
 *
 * The log (e.g. 7Jun_camCalib.csv) holds one row per camera image: N blob centres as u, v pairs
 * (already undistorted by MoCapRasp with its camera matrices), the time in microseconds, the
 * image number and the camera (0 or 1). Images of the two cameras taken in one trigger period
 * (by their times, not their numbers: see the .cpp) form a frame. The
 * intrinsics of rig.toml are read from MoCapRasp's \a constants file (cameraMatrix_cam1 and
 * cameraMatrix_cam2, at 960 x 720, the mode those matrices are for); distortion is zero since the
 * centres are undistorted. Camera 1's pose is unknown: rig.toml says "a metre to the right,
 * looking the same way", a start that rig calibration must not need.
 */
Result<MoCapRaspSummary> convertMoCapRasp(const std::filesystem::path& csv,
                                          const std::filesystem::path& constants,
                                          const std::filesystem::path& out);

} // namespace edgetrack::test
