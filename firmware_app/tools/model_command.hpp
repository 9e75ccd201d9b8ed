// `edgetrack model list|show|export|import`: the models on the board's flash or in a directory.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <ostream>
#include <string>

#include "core/result.hpp"

namespace edgetrack::app {

struct ModelCommandOptions {
    /// "list", "show", "export" or "import".
    std::string action;
    /// Configuration whose [flash] names the partition (device, size, erase block).
    std::filesystem::path config;
    /// The flash partition file; defaults to the configuration's [flash] device.
    std::filesystem::path flash;
    /// A model directory (INTERFACES §4): the source of list/show/import.
    std::filesystem::path models;
    /// export: the directory to write.
    std::filesystem::path out;
    /// show: the model's id.
    std::optional<std::uint32_t> id;
};

/**
 * \brief Run one model sub-command.
 *
 * list and show read the flash partition (or --models DIR); export writes the flash's models as
 * body_<id>.json files into a new directory; import saves a directory's models to flash as the
 * newest set (the A/B store keeps the previous set until the new one is whole). A running
 * firmware reads the flash at start-up, so it sees imported models after a restart.
 */
Status runModelCommand(const ModelCommandOptions& options, std::ostream& out);

} // namespace edgetrack::app
