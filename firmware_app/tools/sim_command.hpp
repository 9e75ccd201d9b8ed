// `edgetrack sim`: writes a recording of a simulated scene (INTERFACES §1, §3).
#pragma once

#include <cstdint>
#include <filesystem>
#include <ostream>
#include <string>

#include "core/result.hpp"
#include "firmware_app/formats/recording.hpp"

namespace edgetrack::app {

struct SimRecordingOptions {
    std::string scene;
    std::int64_t frames = 0;
    std::filesystem::path out;
    std::uint64_t seed = 1;
    recording::Level level = recording::Level::Images;
};

/// \brief Print the scene catalogue, one "name  description" line each.
void listScenes(std::ostream& out);

/**
 * \brief Write a recording: rig.toml, frames.csv, the chosen level, truth.csv and truth/.
 *
 * Refuses to write into a directory that exists and is not empty, so no earlier recording is
 * overwritten by accident.
 */
Status writeSimRecording(const SimRecordingOptions& options);

} // namespace edgetrack::app
