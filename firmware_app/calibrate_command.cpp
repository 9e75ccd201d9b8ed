// `edgetrack calibrate`: the frame loop of object calibration over a recording, then model files.
#include "firmware_app/calibrate_command.hpp"

#include <cstdio>
#include <vector>

#include "firmware_app/frame_source.hpp"
#include "firmware_app/model_file.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;

namespace {

void printProgress(std::ostream& progress, const MarkerFrame& frame,
                   const ObjectCalibrator& calibrator, std::vector<CalibrationObjectView>& views) {
    const std::size_t count = calibrator.objectViews(views);
    char line[160];
    std::snprintf(line, sizeof line, "\rcalibrate: frame %lld (%.1f s), %zu objects:",
                  static_cast<long long>(frame.frame), frame.time_s, count);
    progress << line;
    for (std::size_t i = 0; i < count && i < 8; ++i)
        progress << ' ' << views[i].established << '/' << views[i].markers;
    progress << (count > 8 ? " ..." : "") << " markers      " << std::flush;
}

} // namespace

Status runCalibrate(const CalibrateOptions& options, std::ostream& summary,
                    std::ostream& progress) {
    ObjectCalibrator calibrator(options.config);
    if (!calibrator.isValid())
        return Error{"calibration configuration: markers per object must be 4 to " +
                     std::to_string(MarkerSet::kCapacity)};
    if (Status s = prepareOutputDirectory(options.out); !s)
        return s;

    std::vector<CalibrationObjectView> views(options.config.maxObjects);
    std::size_t frames = 0;
    Result<FrameSourceSummary> read =
        forEachMarkerFrame(options.input, options.from, [&](const MarkerFrame& frame) -> Status {
            calibrator.update(frame.time_s, frame.points_rig_mm);
            if (options.showProgress && ++frames % 25 == 0)
                printProgress(progress, frame, calibrator, views);
            return Ok{};
        });
    if (options.showProgress)
        progress << "\n";
    if (!read)
        return read.error();

    std::vector<MarkerModel> models;
    for (std::size_t i = 0; i < options.config.maxObjects; ++i)
        models.emplace_back(options.config.maxMarkersPerObject);
    const std::size_t count = calibrator.exportModels(models);
    for (std::size_t i = 0; i < count; ++i)
        if (Status s = writeModelJson(modelPath(options.out, models[i].id), models[i],
                                      "body " + std::to_string(models[i].id));
            !s)
            return s;

    const CalibrationCounters& c = calibrator.counters();
    summary << "edgetrack calibrate: " << read->frames << " frames from " << read->level << ", "
            << read->points << " markers; " << count << (count == 1 ? " model" : " models")
            << " written to " << options.out.string() << "\n";
    for (std::size_t i = 0; i < count; ++i) {
        summary << "  body_" << models[i].id << ".json: " << models[i].markers_model_mm.size()
                << " markers, " << models[i].edges.size() << " edges, s_min " << models[i].sMin;
        if (models[i].sameShapeAs >= 0)
            summary << " (same layout as body_" << models[i].sameShapeAs
                    << ": told apart only by tracking them continuously)";
        summary << "\n";
    }
    summary << "  markers born " << c.markersBorn << ", reappeared " << c.markersReappeared
            << ", invalid " << c.invalidRemoved << "; objects split " << c.splits << ", collapsed "
            << c.collapsed << ", found again " << c.refound << "; refused: markers "
            << c.markerOverflow << ", objects " << c.objectOverflow << ", markers in an object "
            << c.memberOverflow << ", clustering deferred " << c.clusteringDeferred << "\n";
    return Ok{};
}

} // namespace edgetrack::app
