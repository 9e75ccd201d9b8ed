// `edgetrack track`: finds the models' poses in every frame of a recording and writes a pose CSV.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>

#include "core/result.hpp"
#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

struct TrackOptions {
    std::filesystem::path models;
    std::filesystem::path input;
    std::filesystem::path out;
    std::optional<recording::Level> from;
    /// [blobs], [stereo] and [tracking] are used, as on the board.
    CommandSettings settings{};
    /// Rewrite one progress line on \a progress (a terminal) while frames are read.
    bool showProgress = false;
};

/**
 * \brief Track every model of MODELDIR through a recording (or .c3d file) and write POSES.csv
 * (INTERFACES §5), replacing it atomically: a failed run leaves no partial file.
 *
 * Prints a summary to \a summary: per body, the frames it was found in (by prediction or by
 * search), its mean matched markers and residual percentiles; and the tracker's counters.
 */
Status runTrack(const TrackOptions& options, std::ostream& summary, std::ostream& progress);

} // namespace edgetrack::app
