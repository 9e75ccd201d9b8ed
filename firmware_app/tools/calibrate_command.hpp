// `edgetrack calibrate`: learns the rigid objects of a recording and writes their model files.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>

#include "core/result.hpp"
#include "firmware_app/formats/recording.hpp"
#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

struct CalibrateOptions {
    std::filesystem::path input;
    std::filesystem::path out;
    std::optional<recording::Level> from;
    /// [blobs], [stereo], [calibration] and [completion] are used, as on the board.
    CommandSettings settings{};
    /// Rewrite one progress line on \a progress (a terminal) while frames are read.
    bool showProgress = false;
};

/**
 * \brief Run object calibration over every frame of a recording (or .c3d file) and write
 * MODELDIR/body_<id>.json for each object found.
 *
 * The online stage (ObjectCalibrator) runs frame by frame as on the board; its models are then
 * completed over all the recording's frames (CalibrationCompletion) and merged as the board
 * merges a field calibration into an empty model set (fragments of a body dropped), and those are
 * written.
 *
 * MODELDIR must be new or empty. Prints a summary (models, markers, S_min, counters) to
 * \a summary, and progress (frames, objects, markers per object) to \a progress when asked.
 */
Status runCalibrate(const CalibrateOptions& options, std::ostream& summary, std::ostream& progress);

} // namespace edgetrack::app
