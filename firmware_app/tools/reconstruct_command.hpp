// `edgetrack reconstruct`: blob detection, stereo correspondence and triangulation of a recording.
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>

#include "core/result.hpp"
#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

struct ReconstructOptions {
    std::filesystem::path input;
    std::filesystem::path out;
    /// images or blobs; nothing: the lowest level present.
    std::optional<recording::Level> from;
    /// [blobs] and [stereo] are used, as on the board.
    CommandSettings settings{};
};

/**
 * \brief Reconstruct the 3D markers of every frame of a recording.
 *
 * Writes REC2 with rig.toml, frames.csv, blobs.csv (detected, or those read) and points.csv, and
 * copies truth.csv and truth/ when the input has them, so that later stages can be checked
 * against the same truth. Prints one summary line to \a summary.
 */
Status runReconstruct(const ReconstructOptions& options, std::ostream& summary);

} // namespace edgetrack::app
