// `edgetrack model`: list, show, export and import models on a flash partition file.
#include "firmware_app/tools/model_command.hpp"

#include <cstdio>
#include <vector>

#include "core/marker_set.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "firmware_app/firmware/model_store.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "firmware_app/tools/frame_source.hpp"
#include "hal/linux/file_flash.hpp"

namespace edgetrack::app {

namespace {

/// The flash partition and how many models the board keeps, from --config (or the defaults).
struct BoardSettings {
    FlashSettings flash;
    std::size_t maxModels = FirmwareConfig{}.maxModels;
};

Result<BoardSettings> boardSettings(const ModelCommandOptions& options) {
    BoardSettings board;
    if (!options.config.empty()) {
        Result<FirmwareConfig> config = loadFirmwareConfig(options.config);
        if (!config)
            return config.error();
        board.flash = config->flash;
        board.maxModels = config->maxModels;
    }
    if (!options.flash.empty())
        board.flash.device = options.flash;
    return board;
}

Result<std::vector<NamedModel>> loadFromFlash(const FlashSettings& settings) {
    std::error_code ec;
    if (!std::filesystem::exists(settings.device, ec))
        return Error{settings.device.string() + ": no such flash partition"};
    linux_hal::FileFlash flash(settings.device, settings.size_bytes, settings.eraseBlock_bytes);
    if (!flash.isValid())
        return Error{flash.error()};
    if (!flash.warning().empty())
        std::fprintf(stderr, "edgetrack model: %s\n", flash.warning().c_str());
    ModelStore store(flash, MarkerSet::kCapacity);
    Result<StoredModels> stored = store.load();
    if (!stored)
        return Error{settings.device.string() + ": " + stored.error().message};
    return std::move(stored->models);
}

void printList(const std::vector<NamedModel>& models, std::ostream& out) {
    for (const NamedModel& m : models) {
        char line[200];
        std::snprintf(line, sizeof line, "body %u  %zu markers, %zu edges, s_min %u%s  %s\n",
                      m.model.id, m.model.markers_model_mm.size(), m.model.edges.size(),
                      m.model.sMin, m.model.sameShapeAs >= 0 ? ", has a copy" : "", m.name.c_str());
        out << line;
    }
    out << models.size() << (models.size() == 1 ? " model\n" : " models\n");
}

} // namespace

Status runModelCommand(const ModelCommandOptions& options, std::ostream& out) {
    Result<BoardSettings> board = boardSettings(options);
    if (!board)
        return board.error();
    const FlashSettings& settings = board->flash;
    const bool fromDirectory = !options.models.empty();

    if (options.action == "import") {
        if (!fromDirectory)
            return Error{"import needs --models DIR"};
        Result<std::vector<NamedModel>> models =
            readModelDirectory(options.models, MarkerSet::kCapacity);
        if (!models)
            return models.error();
        // The board would keep only max_models of them and say so in a counter nobody reads.
        if (models->size() > board->maxModels)
            return Error{options.models.string() + ": " + std::to_string(models->size()) +
                         " models; the board keeps at most " + std::to_string(board->maxModels) +
                         " ([tracking] max_models): nothing imported"};
        linux_hal::FileFlash flash(settings.device, settings.size_bytes, settings.eraseBlock_bytes);
        if (!flash.isValid())
            return Error{flash.error()};
        if (!flash.warning().empty())
            return Error{flash.warning()};
        ModelStore store(flash, MarkerSet::kCapacity);
        if (Status s = store.save(*models); !s)
            return Error{settings.device.string() + ": " + s.error().message};
        out << "edgetrack model import: " << models->size()
            << (models->size() == 1 ? " model" : " models") << " saved to "
            << settings.device.string() << "\n";
        return Ok{};
    }

    Result<std::vector<NamedModel>> models =
        fromDirectory ? readModelDirectory(options.models, MarkerSet::kCapacity)
                      : loadFromFlash(settings);
    if (!models)
        return models.error();

    if (options.action == "list") {
        printList(*models, out);
        return Ok{};
    }
    if (options.action == "show") {
        if (!options.id)
            return Error{"show needs --id N"};
        for (const NamedModel& m : *models) {
            if (m.model.id != *options.id)
                continue;
            out << "body " << m.model.id << " (" << m.name
                << "): " << m.model.markers_model_mm.size() << " markers, s_min " << m.model.sMin
                << "; model frame, mm\n";
            char line[128];
            for (std::size_t i = 0; i < m.model.markers_model_mm.size(); ++i) {
                const Vec3& p = m.model.markers_model_mm[i];
                std::snprintf(line, sizeof line, "%4zu %10.3f %10.3f %10.3f\n", i, p.x(), p.y(),
                              p.z());
                out << line;
            }
            out << m.model.edges.size() << " co-visible pairs\n";
            return Ok{};
        }
        return Error{"no model with id " + std::to_string(*options.id)};
    }
    if (options.action == "export") {
        if (options.out.empty())
            return Error{"export needs --out DIR"};
        if (Status s = prepareOutputDirectory(options.out); !s)
            return s;
        for (const NamedModel& m : *models)
            if (Status s = writeModelJson(modelPath(options.out, m.model.id), m.model, m.name); !s)
                return s;
        out << "edgetrack model export: " << models->size()
            << (models->size() == 1 ? " model" : " models") << " written to "
            << options.out.string() << "\n";
        return Ok{};
    }
    return Error{"unknown action '" + options.action + "'"};
}

} // namespace edgetrack::app
