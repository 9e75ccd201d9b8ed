// `edgetrack rig calibrate`: measures the stereo rig from a recording of a waved wand.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>
#include <string_view>
#include <vector>

#include "core/result.hpp"
#include "core/rig_calibration.hpp"
#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

struct RigCalibrateOptions {
    std::filesystem::path input;
    std::filesystem::path out;
    /// images or blobs; nothing: the lowest level present.
    std::optional<recording::Level> from;
    /// Marker spacings from one end of the wand (mm), as `--wand D1,D2,...`.
    std::vector<double> wandSpacings_mm;
    bool refineIntrinsics = false;
    /// [blobs] is used, as on the board.
    CommandSettings settings{};
};

/// \brief Parse `--wand D1[,D2...]` (mm); a one-line error for anything but positive numbers.
Result<std::vector<double>> parseWandSpacings(std::string_view text);

/**
 * \brief Find the wand in every frame pair of a recording, calibrate the rig, write RIG.toml.
 *
 * Prints the report (frames used and refused, reprojection RMS per camera, wand length error,
 * coverage, warnings) to \a report. Writes nothing when no rig could be found.
 */
Status runRigCalibrate(const RigCalibrateOptions& options, std::ostream& report);

/// \brief The report of a rig calibration as the command prints it.
void printRigReport(const RigCalibrationReport& report, std::ostream& out);

} // namespace edgetrack::app
