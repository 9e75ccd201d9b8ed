// `edgetrack track`: the frame loop of model-based tracking over a recording, then the pose CSV.
#include "firmware_app/tools/track_command.hpp"

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "core/model_tracker.hpp"
#include "firmware_app/formats/csv.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "firmware_app/formats/pose_file.hpp"
#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

namespace {

/// What the summary says about one body.
struct BodyTally {
    std::size_t predicted = 0;
    std::size_t searched = 0;
    std::uint64_t markers = 0;
    std::vector<double> rms_mm;
};

double percentile(std::vector<double>& values, double share) {
    if (values.empty())
        return 0.0;
    const auto rank = static_cast<std::size_t>(share * static_cast<double>(values.size() - 1));
    std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(rank),
                     values.end());
    return values[rank];
}

} // namespace

Status runTrack(const TrackOptions& options, std::ostream& summary, std::ostream& progress) {
    Result<std::vector<NamedModel>> read = readModelDirectory(options.models, MarkerSet::kCapacity);
    if (!read)
        return read.error();
    std::vector<MarkerModel> models;
    for (NamedModel& named : *read)
        models.push_back(std::move(named.model));
    ModelTracker tracker(models, options.settings.config.tracking);
    if (!tracker.isValid())
        return Error{"tracking configuration is unusable"};

    std::string csv = kPoseCsvHeader;
    std::vector<BodyTally> tally(models.size());
    std::size_t frames = 0;
    Result<FrameSourceSummary> source = forEachMarkerFrame(
        options.input, options.from, options.settings.config.markers,
        [&](const MarkerFrame& frame) -> Status {
            tracker.update(frame.time_s, frame.points_rig_mm);
            std::size_t found = 0;
            for (std::size_t b = 0; b < models.size(); ++b) {
                const TrackedBody& body = tracker.bodies()[b];
                if (!body.found())
                    continue;
                ++found;
                appendPoseRow(csv, PoseRow{frame.frame, frame.time_s, body.modelId,
                                           body.T_rig_from_model, body.markers, body.rms_mm});
                BodyTally& t = tally[b];
                ++(body.source == PoseSource::Predicted ? t.predicted : t.searched);
                t.markers += body.markers;
                t.rms_mm.push_back(body.rms_mm);
            }
            if (options.showProgress && ++frames % 25 == 0) {
                char line[128];
                std::snprintf(
                    line, sizeof line, "\rtrack: frame %lld (%.1f s), %zu of %zu bodies   ",
                    static_cast<long long>(frame.frame), frame.time_s, found, models.size());
                progress << line << std::flush;
            }
            return Ok{};
        });
    if (options.showProgress)
        progress << "\n";
    if (!source)
        return source.error();
    std::error_code ec;
    if (options.out.has_parent_path())
        std::filesystem::create_directories(options.out.parent_path(), ec);
    if (ec)
        return Error{options.out.parent_path().string() + ": cannot create: " + ec.message()};
    if (Status s = recording::writeTextFileAtomically(options.out, csv); !s)
        return s;

    summary << "edgetrack track: " << source->frames << " frames from " << source->level << ", "
            << models.size() << (models.size() == 1 ? " model" : " models") << "; poses written to "
            << options.out.string() << "\n";
    summary << "  settings: " << options.settings.source << "\n";
    for (std::size_t b = 0; b < models.size(); ++b) {
        BodyTally& t = tally[b];
        const std::size_t found = t.predicted + t.searched;
        char line[256];
        std::snprintf(
            line, sizeof line,
            "  body %u: found in %zu of %zu frames (%.1f%%; %zu predicted, %zu searched), "
            "%.1f markers, rms median %.3f mm, 95%% %.3f mm\n",
            models[b].id, found, source->frames,
            source->frames
                ? 100.0 * static_cast<double>(found) / static_cast<double>(source->frames)
                : 0.0,
            t.predicted, t.searched,
            found ? static_cast<double>(t.markers) / static_cast<double>(found) : 0.0,
            percentile(t.rms_mm, 0.5), percentile(t.rms_mm, 0.95));
        summary << line;
    }
    const ModelTrackingCounters& c = tracker.counters();
    summary << "  searches " << c.searches << " (found " << c.searchHits << "), predictions failed "
            << c.predictionFailures << ", hypotheses " << c.hypotheses << " (" << c.repeatedRefusals
            << " refused as a repeat); refused: points " << c.pointOverflow << ", candidates "
            << c.candidateOverflow << ", frames out of search budget " << c.budgetExhausted
            << " (searches skipped " << c.searchesSkipped << "), poses from markers on one line "
            << c.degeneratePoses << "\n";
    return Ok{};
}

} // namespace edgetrack::app
