// `edgetrack calibrate`: the frame loop of object calibration over a recording, then model files.
#include "firmware_app/tools/calibrate_command.hpp"

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "core/calibration_session.hpp"
#include "firmware_app/firmware/model_merge.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;

namespace {

/// How closely the session fixed a learnt layout, for the summary.
std::string precisionText(const LayoutPrecision& p) {
    char text[160];
    if (p.looseModes > 0)
        std::snprintf(text, sizeof text,
                      "layout not fixed by the frames (%u loose): show the sides that share only "
                      "two markers together",
                      p.looseModes);
    else
        std::snprintf(text, sizeof text,
                      "layout fixed to %.3f mm RMS (worst marker %.3f mm, point noise %.3f mm)",
                      p.markerRms_mm, p.worstMarker_mm, p.pointSigma_mm);
    return text;
}

void printProgress(std::ostream& progress, std::size_t frame, double time_s,
                   const ObjectCalibrator& calibrator, std::vector<CalibrationObjectView>& views) {
    const std::size_t count = calibrator.objectViews(views);
    char line[160];
    std::snprintf(line, sizeof line, "\rcalibrate: frame %zu (%.1f s), %zu objects:", frame, time_s,
                  count);
    progress << line;
    for (std::size_t i = 0; i < count && i < 8; ++i)
        progress << ' ' << views[i].established << '/' << views[i].markers;
    progress << (count > 8 ? " ..." : "") << " markers      " << std::flush;
}

} // namespace

Status runCalibrate(const CalibrateOptions& options, std::ostream& summary,
                    std::ostream& progress) {
    if (Status s = prepareOutputDirectory(options.out); !s)
        return s;

    // Every frame is kept for the completion stage; offline, its room is the recording's size,
    // so the recording is read first.
    std::vector<double> times_s;
    std::vector<std::size_t> frameEnd;
    std::vector<Vec3> points_rig_mm;
    Result<FrameSourceSummary> read = forEachMarkerFrame(
        options.input, options.from, options.settings.config.markers,
        [&](const MarkerFrame& frame) -> Status {
            times_s.push_back(frame.time_s);
            points_rig_mm.insert(points_rig_mm.end(), frame.points_rig_mm.begin(),
                                 frame.points_rig_mm.end());
            frameEnd.push_back(points_rig_mm.size());
            if (options.showProgress && times_s.size() % 25 == 0)
                progress << "\rcalibrate: read frame " << frame.frame << std::flush;
            return Ok{};
        });
    if (!read)
        return read.error();

    const FirmwareConfig& config = options.settings.config;
    const StereoRig* rig = read->rig ? &*read->rig : nullptr;
    CalibrationSession session(config.calibration, completionFor(config, rig),
                               std::max<std::size_t>(times_s.size(), 1),
                               std::max<std::size_t>(points_rig_mm.size(), 1));
    if (!session.isValid())
        return Error{"calibration configuration: markers per object and per model must be 4 to " +
                     std::to_string(MarkerSet::kCapacity)};
    std::vector<CalibrationObjectView> views(config.calibration.maxObjects);
    for (std::size_t f = 0; f < times_s.size(); ++f) {
        const std::size_t begin = f == 0 ? 0 : frameEnd[f - 1];
        session.update(times_s[f],
                       std::span<const Vec3>(points_rig_mm).subspan(begin, frameEnd[f] - begin));
        if (options.showProgress && (f + 1) % 25 == 0)
            printProgress(progress, f, times_s[f], session.online(), views);
    }
    if (options.showProgress)
        progress << "\n";
    // As on the board when it has no models yet: the same fragments dropped, ids and S_min.
    const MergedModels merged =
        mergeLearntModels({}, session.complete(), {}, config.maxModels, config.calibration.smin,
                          config.tracking.distanceTolerance_mm);
    const std::size_t count = merged.models.size();
    for (const NamedModel& named : merged.models)
        if (Status s =
                writeModelJson(modelPath(options.out, named.model.id), named.model, named.name);
            !s)
            return s;

    const CalibrationCounters& c = session.online().counters();
    summary << "edgetrack calibrate: " << read->frames << " frames from " << read->level << ", "
            << read->points << " markers; " << count << (count == 1 ? " model" : " models")
            << " written to " << options.out.string() << "\n";
    summary << "  settings: " << options.settings.source << "\n";
    const std::span<const LayoutPrecision> precision = session.completionPrecision();
    const std::span<const std::size_t> mostSeen = session.completionMostSeenTogether();
    for (std::size_t i = 0; i < merged.models.size(); ++i) {
        const MarkerModel& model = merged.models[i].model;
        summary << "  body_" << model.id << ".json: " << model.markers_model_mm.size()
                << " markers, " << model.edges.size() << " edges, s_min " << model.sMin;
        const int learnt = merged.learntIndex[i];
        if (learnt >= 0 && static_cast<std::size_t>(learnt) < precision.size())
            summary << "; " << precisionText(precision[static_cast<std::size_t>(learnt)]);
        if (model.sameShapeAs >= 0)
            summary << " (same layout as body_" << model.sameShapeAs
                    << ": told apart only by tracking them continuously)";
        summary << "\n";
        if (learnt >= 0 && static_cast<std::size_t>(learnt) < mostSeen.size())
            if (const std::optional<std::string> why =
                    seldomFindable(model, mostSeen[static_cast<std::size_t>(learnt)]))
                summary << "  WARNING body_" << model.id << ".json " << *why << "\n";
    }
    // Pieces of one object that the session could not tie: only the user can mend that.
    auto fileOfLearnt = [&](std::size_t learnt) -> const MarkerModel* {
        for (std::size_t i = 0; i < merged.models.size(); ++i)
            if (merged.learntIndex[i] == static_cast<int>(learnt))
                return &merged.models[i].model;
        return nullptr;
    };
    for (const UntiedPieces& pieces : session.completionUntiedPieces()) {
        const MarkerModel* first = fileOfLearnt(pieces.first);
        const MarkerModel* second = fileOfLearnt(pieces.second);
        if (first == nullptr || second == nullptr)
            continue;
        summary << "  body_" << first->id << ".json and body_" << second->id << ".json hold "
                << pieces.sharedMarkers
                << " of the same markers, but no frame showed enough of both to join them: "
                   "pieces of one object; record it again, turning it so that the markers "
                   "between the two are in view together\n";
    }
    if (merged.fragments + merged.refused > 0)
        summary << "  dropped: " << merged.fragments << " fragments of a larger body, "
                << merged.refused << " beyond max_models\n";
    summary << "  markers born " << c.markersBorn << ", reappeared " << c.markersReappeared
            << ", invalid " << c.invalidRemoved << "; objects split " << c.splits << ", collapsed "
            << c.collapsed << ", found again " << c.refound << "; refused: markers "
            << c.markerOverflow << ", objects " << c.objectOverflow << ", markers in an object "
            << c.memberOverflow << ", clustering deferred " << c.clusteringDeferred
            << "; objects evicted " << c.objectsEvicted << "\n";
    const CompletionCounters& k = session.completionCounters();
    summary << "  completion: " << session.seedsUsed() << " online models in, " << k.discovered
            << " bodies found in the points, " << k.rounds << " rounds; "
            << k.joinedByMotion + k.joinedByTracks + k.joinedByLayout << " pieces joined, "
            << k.framesFollowed << " frames followed, " << k.framesFromTriangles
            << " posed from three markers, " << k.dropped << " dropped, " << k.droppedSeenBriefly
            << " seen too briefly; markers added " << k.markersAdded << ", removed "
            << k.markersRemoved << "; not rigid with their body: " << k.markersNotRigid
            << " markers, " << k.droppedNotRigid
            << " whole bodies; not fixed by any frame: " << k.markersNotFixed
            << " markers; refused: places " << k.siteOverflow << ", models " << k.modelOverflow
            << ", markers " << k.markerOverflow << "\n";
    return Ok{};
}

} // namespace edgetrack::app
