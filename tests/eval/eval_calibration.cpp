// Measures object calibration on simulated scenes against the true marker layouts.
//
//   eval_calibration --scene cube_sphere --frames 4000 [--seed 1] [--level images|points]
//                    [--require-objects N] [--require-rms 0.3] [--require-complete]
//                    [--allow-missing N]
//
// Runs the core pipeline (images level: render, blob detection, stereo; points level: the
// simulator's points) into the ObjectCalibrator, exports its models, aligns each to the true
// layout it matches best and reports per object: markers found, duplicates, false markers and the
// RMS position error. Every second it also exports the models so far and reports when they first
// held every marker that was in view for at least --min-seen-s seconds. Exits 1 on a missed target.
#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/calibration_completion.hpp"
#include "core/calibration_session.hpp"
#include "core/completion_geometry.hpp"
#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"
#include "core/session_buffer.hpp"
#include "core/stereo_matcher.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"
#include "tests/eval/sim_image_pipeline.hpp"
#include "tests/support/model_alignment.hpp"

using namespace edgetrack;

namespace {

// Tolerances of the comparison with truth (mm).
constexpr double kMatch_mm = 1.5;

struct ObjectReport {
    std::size_t expected = 0; // markers in view long enough
    std::size_t found = 0;    // of those, in the model
    std::size_t duplicates = 0;
    int models = 0; // models aligned to this object
    double rms_mm = 0.0;
};

struct Report {
    std::vector<ObjectReport> objects;
    std::size_t models = 0;
    std::size_t falseMarkers = 0; // model markers on no true marker
    std::size_t strayModels = 0;  // models that match no object
    /// Per model: the object its layout matches best, and how far each of its false markers
    /// lies from that object's nearest marker after the alignment (mm).
    std::vector<std::size_t> objectOfModel;
    std::vector<std::vector<double>> falseMarkerDistances_mm;
    /// Per model: the markers of its object's layout that its markers lie on.
    std::vector<std::vector<int>> layoutMarkersOfModel;
};

// The true marker (object, marker) seen at a rig position (mm), if any is within 1 mm.
std::optional<std::pair<int, int>> trueMarkerAt(const sim::Observation& observation,
                                                const Vec3& p_rig_mm) {
    std::optional<std::pair<int, int>> label;
    for (const sim::MarkerView& m : observation.markers)
        if ((m.position_rig_mm - p_rig_mm).norm() < 1.0)
            label = std::pair{m.object, m.marker};
    return label;
}

Report evaluate(std::span<const MarkerModel> models, const std::vector<std::vector<Vec3>>& layouts,
                const std::vector<std::vector<bool>>& expected) {
    Report r;
    r.models = models.size();
    r.objects.resize(layouts.size());
    std::vector<std::vector<int>> hits(layouts.size());
    for (std::size_t k = 0; k < layouts.size(); ++k) {
        hits[k].assign(layouts[k].size(), 0);
        r.objects[k].expected =
            static_cast<std::size_t>(std::count(expected[k].begin(), expected[k].end(), true));
    }
    std::vector<double> squared(layouts.size(), 0.0);
    std::vector<std::size_t> squaredCount(layouts.size(), 0);
    for (const MarkerModel& model : models) {
        test::ModelAlignment best;
        std::size_t bestObject = 0;
        for (std::size_t k = 0; k < layouts.size(); ++k) {
            test::ModelAlignment a = test::alignModel(model, layouts[k], kMatch_mm);
            // Copies of one layout (identical cubes) share the models out between them.
            const bool better =
                a.matched > best.matched || (a.matched == best.matched && a.matched > 0 &&
                                             r.objects[k].models < r.objects[bestObject].models);
            if (better) {
                best = a;
                bestObject = k;
            }
        }
        const std::size_t k = bestObject;
        r.objectOfModel.push_back(k);
        std::vector<int>& onLayout = r.layoutMarkersOfModel.emplace_back();
        if (best.matched >= 4)
            for (const int m : best.layoutMarkerOf)
                if (m >= 0)
                    onLayout.push_back(m);
        std::sort(onLayout.begin(), onLayout.end());
        std::vector<double>& falseAt = r.falseMarkerDistances_mm.emplace_back();
        for (std::size_t i = 0; i < best.layoutMarkerOf.size(); ++i) {
            if (best.layoutMarkerOf[i] >= 0 && best.matched >= 4)
                continue;
            const Vec3 p = best.T_layout_from_model.apply(model.markers_model_mm[i]);
            double nearest = std::numeric_limits<double>::infinity();
            for (const Vec3& q : layouts[k])
                nearest = std::min(nearest, (p - q).norm());
            falseAt.push_back(nearest);
        }
        if (best.matched < 4) {
            ++r.strayModels;
            r.falseMarkers += model.markers_model_mm.size();
            continue;
        }
        ++r.objects[k].models;
        for (std::size_t i = 0; i < best.layoutMarkerOf.size(); ++i) {
            if (best.layoutMarkerOf[i] < 0) {
                ++r.falseMarkers;
                continue;
            }
            ++hits[k][static_cast<std::size_t>(best.layoutMarkerOf[i])];
            const double d = (best.T_layout_from_model.apply(model.markers_model_mm[i]) -
                              layouts[k][static_cast<std::size_t>(best.layoutMarkerOf[i])])
                                 .squaredNorm();
            squared[k] += d;
            ++squaredCount[k];
        }
    }
    for (std::size_t k = 0; k < layouts.size(); ++k) {
        for (std::size_t m = 0; m < layouts[k].size(); ++m) {
            if (hits[k][m] > 1)
                r.objects[k].duplicates += static_cast<std::size_t>(hits[k][m] - 1);
            if (expected[k][m] && hits[k][m] > 0)
                ++r.objects[k].found;
        }
        r.objects[k].rms_mm =
            squaredCount[k] ? std::sqrt(squared[k] / static_cast<double>(squaredCount[k])) : 0.0;
    }
    return r;
}

// An object can be learnt when at least a pose's worth of its markers (4) were each in view with
// three others long enough; one that never showed that much is no test of calibration.
bool learnable(const ObjectReport& o) {
    return o.expected >= 4;
}

// Right models: every learnable object in exactly one model holding every marker in view long
// enough (but \a allowedMissing of them over all objects), no stray model, and no model marker
// where its object has none.
bool complete(const Report& r, std::size_t allowedMissing = 0) {
    std::size_t missing = 0;
    for (const ObjectReport& o : r.objects) {
        if (!learnable(o))
            continue;
        if (o.models != 1 || o.duplicates > 0)
            return false;
        missing += o.expected - std::min(o.found, o.expected);
    }
    return missing <= allowedMissing && r.strayModels == 0 && r.falseMarkers == 0;
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"Object calibration quality on a simulated scene"};
    std::string sceneName = "cube_sphere";
    std::int64_t frames = 3000;
    std::uint64_t seed = 1;
    std::string level = "images";
    double minSeen_s = 1.0;
    bool onlineOnly = false;
    int requireObjects = -1;
    double requireRms = -1.0;
    bool requireComplete = false;
    std::size_t allowMissing = 0;
    bool verbose = false;
    bool trace = false;
    bool timeline = false;
    bool visibleSets = false;
    std::int64_t traceEvery = 0;
    std::int64_t traceObject = -1, traceFrom = 0, traceTo = 0;
    app.add_option("--scene", sceneName);
    app.add_option("--frames", frames)->check(CLI::PositiveNumber);
    app.add_option("--seed", seed);
    app.add_option("--level", level)->check(CLI::IsMember({"images", "points"}));
    app.add_option("--min-seen-s", minSeen_s,
                   "a marker in view this long, with three others of its object, must be in the "
                   "model");
    app.add_flag("--online-only", onlineOnly,
                 "judge the online stage's models, without the completion stage");
    app.add_option("--require-objects", requireObjects, "models that must come out");
    app.add_option("--require-rms", requireRms, "maximum marker RMS error after alignment (mm)");
    app.add_flag("--require-complete", requireComplete,
                 "every marker in view long enough found exactly once, no stray models, no false "
                 "markers");
    app.add_option("--allow-missing", allowMissing,
                   "with --require-complete, this many markers in all may be missing");
    app.add_flag("--verbose", verbose, "print the objects every second");
    app.add_flag("--visible-sets", visibleSets,
                 "each object's markers in view (of three or more), one line per unchanged run");
    app.add_flag("--timeline", timeline,
                 "with --verbose, the markers of each model in view every 5th frame");
    app.add_flag(
        "--trace", trace,
        "at the end, list members more than 1.5 mm from the true marker they were seen as");
    app.add_option("--trace-every", traceEvery, "with --trace, list them every this many frames");
    app.add_option("--trace-object", traceObject, "print this object's visible members per frame");
    app.add_option("--trace-from", traceFrom, "first frame of --trace-object");
    app.add_option("--trace-to", traceTo, "last frame of --trace-object");
    CalibrationConfig config;
    app.add_option("--edge-break", config.edgeBreak_mm, "edge break threshold (mm)");
    app.add_option("--edge-window", config.edgeWindow_frames, "N of the running distance");
    app.add_option("--max-objects", config.maxObjects, "object graphs alive at once")
        ->check(CLI::Range(1, 1024));
    app.add_option("--max-markers-per-object", config.maxMarkersPerObject,
                   "markers per object graph")
        ->check(CLI::Range(4, 128));
    CLI11_PARSE(app, argc, argv);

    std::optional<sim::Scene> scene = sim::makeScene(sceneName, seed);
    if (!scene) {
        std::fprintf(stderr, "unknown scene %s\n", sceneName.c_str());
        return 2;
    }
    const sim::World world(std::move(*scene), seed);
    test::SimFrames simFrames(world, seed, level == "images");
    CalibrationSession learning(config, CompletionConfig{}, static_cast<std::size_t>(frames),
                                static_cast<std::size_t>(frames) * 256);
    const ObjectCalibrator& calibrator = learning.online();
    std::vector<MarkerModel> models;
    for (std::size_t i = 0; i < config.maxObjects; ++i)
        models.emplace_back(config.maxMarkersPerObject);

    std::vector<std::vector<Vec3>> layouts;
    std::vector<std::vector<int>> framesSeen;
    for (const sim::SceneObject& o : world.scene().objects) {
        layouts.emplace_back();
        for (const sim::SimMarker& m : o.object.markers)
            layouts.back().push_back(m.position_object_mm);
        framesSeen.emplace_back(o.object.markers.size(), 0);
    }
    // Per object, every set of three or more of its markers seen together (a bit per marker; an
    // object of more than 64 markers is not looked at): what the data can tie together rigidly.
    std::vector<std::set<std::uint64_t>> seenTogether(layouts.size());
    // The same per frame, for --verbose's account of why pieces of one object stayed apart.
    std::vector<std::vector<std::uint64_t>> inViewPerFrame(layouts.size());

    struct Seen {
        std::pair<int, int> first{-1, -1};
        std::pair<int, int> last{-1, -1};
        std::int64_t firstFrame = 0;
        std::int64_t lastFrame = 0;
        std::int64_t frames = 0;
        int relabelled = 0;
    };
    std::map<std::uint32_t, Seen> seenAs;
    std::vector<Vec3> points;
    sim::Observation observation;
    auto printOffMembers = [&](std::int64_t frame) {
        // Per object: its members with the true marker each was last seen as; the object's
        // learnt layout is laid onto the true layout by a fit that drops members over the
        // threshold, so a member's error is its place in the model, whatever the pose now.
        struct Traced {
            ObjectCalibrator::MemberView view;
            Seen seen;
        };
        std::map<std::uint32_t, std::vector<Traced>> byObject;
        calibrator.forEachMember([&](const ObjectCalibrator::MemberView& v) {
            const auto it = seenAs.find(v.markerId);
            if (it != seenAs.end())
                byObject[v.objectId].push_back({v, it->second});
        });
        std::printf("members off at frame %lld:\n", static_cast<long long>(frame));
        for (const auto& [id, traced] : byObject) {
            std::map<int, int> votes;
            for (const Traced& t : traced)
                ++votes[t.seen.last.first];
            const int object = std::max_element(votes.begin(), votes.end(), [](auto a, auto b) {
                                   return a.second < b.second;
                               })->first;
            auto truthOf = [&](const Traced& t) {
                return layouts[static_cast<std::size_t>(object)]
                              [static_cast<std::size_t>(t.seen.last.second)];
            };
            std::vector<bool> use(traced.size());
            for (std::size_t i = 0; i < traced.size(); ++i)
                use[i] = traced[i].seen.last.first == object;
            RigidTransform T_layout_from_model{};
            for (int round = 0; round < 3; ++round) {
                std::vector<Vec3> from, to;
                for (std::size_t i = 0; i < traced.size(); ++i)
                    if (use[i]) {
                        from.push_back(traced[i].view.model_mm);
                        to.push_back(truthOf(traced[i]));
                    }
                const std::optional<RigidFit> fit = fitRigid(from, to);
                if (!fit)
                    break;
                T_layout_from_model = fit->transform;
                for (std::size_t i = 0; i < traced.size(); ++i)
                    use[i] =
                        traced[i].seen.last.first == object &&
                        (T_layout_from_model.apply(traced[i].view.model_mm) - truthOf(traced[i]))
                                .norm() < kMatch_mm;
            }
            int off = 0;
            for (const Traced& t : traced) {
                const double error =
                    t.seen.last.first == object
                        ? (T_layout_from_model.apply(t.view.model_mm) - truthOf(t)).norm()
                        : -1.0;
                if (error >= 0.0 && error < kMatch_mm)
                    continue;
                ++off;
                std::printf(
                    "  #%u marker %u: seen as %d:%d (first %d:%d) frames %lld-%lld (%lld, "
                    "relabelled %d), %s%s, %.1f mm off in the model\n",
                    id, t.view.markerId, t.seen.last.first, t.seen.last.second, t.seen.first.first,
                    t.seen.first.second, static_cast<long long>(t.seen.firstFrame),
                    static_cast<long long>(t.seen.lastFrame), static_cast<long long>(t.seen.frames),
                    t.seen.relabelled, t.view.visible ? "visible" : "hidden",
                    t.view.established ? " established" : "", error);
                if (error < 0.0)
                    std::printf("    (a marker of another object)\n");
            }
            std::printf("  #%u: %zu members on object %d, %d off\n", id, traced.size(), object,
                        off);
        }
    };
    std::vector<int> visible;
    const auto perSecond = static_cast<std::int64_t>(world.scene().frameRate_hz);
    std::vector<std::pair<double, std::vector<MarkerModel>>> checkpoints;

    for (std::int64_t f = 0; f < frames; ++f) {
        simFrames.next(static_cast<std::uint64_t>(f), observation, points);
        learning.update(observation.time_s, points);
        if (trace) {
            // The true marker each calibration marker was seen as: first and last label, frames.
            calibrator.forEachMember([&](const ObjectCalibrator::MemberView& v) {
                if (!v.visible)
                    return;
                const std::optional<std::pair<int, int>> label =
                    trueMarkerAt(observation, v.position_rig_mm);
                if (!label)
                    return;
                Seen& seen = seenAs[v.markerId];
                if (seen.frames == 0) {
                    seen.first = *label;
                    seen.firstFrame = f;
                }
                if (seen.last != *label && seen.frames > 0)
                    ++seen.relabelled;
                seen.last = *label;
                seen.lastFrame = f;
                ++seen.frames;
            });
            if (traceEvery > 0 && (f + 1) % traceEvery == 0)
                printOffMembers(f + 1);
            if (traceObject >= 0 && f >= traceFrom && f <= traceTo) {
                std::vector<CalibrationObjectView> views(config.maxObjects);
                const std::size_t n = calibrator.objectViews(views);
                for (std::size_t i = 0; i < n; ++i) {
                    if (views[i].id != static_cast<std::uint32_t>(traceObject))
                        continue;
                    std::printf("%lld #%u%s:", static_cast<long long>(f), views[i].id,
                                views[i].posed ? "" : " lost");
                    calibrator.forEachMember([&](const ObjectCalibrator::MemberView& v) {
                        if (v.objectId != views[i].id || !v.visible)
                            return;
                        const auto it = seenAs.find(v.markerId);
                        const double residual =
                            (views[i].T_rig_from_object.apply(v.model_mm) - v.position_rig_mm)
                                .norm();
                        std::printf(" %u=%d:%d%s/%.1f", v.markerId,
                                    it != seenAs.end() ? it->second.last.first : -1,
                                    it != seenAs.end() ? it->second.last.second : -1,
                                    v.established ? "e" : "", residual);
                    });
                    std::printf("\n");
                }
            }
        }
        // A marker can be learnt while three others of its object are seen with it.
        sim::separatelyVisible(observation, visible);
        std::vector<int> visibleOf(layouts.size(), 0);
        for (const int source : visible)
            if (static_cast<std::size_t>(source) < observation.markers.size())
                ++visibleOf[static_cast<std::size_t>(
                    observation.markers[static_cast<std::size_t>(source)].object)];
        std::vector<std::uint64_t> together(layouts.size(), 0);
        for (const int source : visible)
            if (static_cast<std::size_t>(source) < observation.markers.size()) {
                const sim::MarkerView& m = observation.markers[static_cast<std::size_t>(source)];
                if (m.marker < 64)
                    together[static_cast<std::size_t>(m.object)] |= std::uint64_t{1} << m.marker;
            }
        for (std::size_t k = 0; k < layouts.size(); ++k) {
            if (layouts[k].size() <= 64 && std::popcount(together[k]) >= 3)
                seenTogether[k].insert(together[k]);
            inViewPerFrame[k].push_back(together[k]);
        }
        for (const int source : visible)
            if (static_cast<std::size_t>(source) < observation.markers.size()) {
                const sim::MarkerView& m = observation.markers[static_cast<std::size_t>(source)];
                if (visibleOf[static_cast<std::size_t>(m.object)] >= 4)
                    ++framesSeen[static_cast<std::size_t>(m.object)]
                                [static_cast<std::size_t>(m.marker)];
            }
        if ((f + 1) % perSecond == 0) {
            const std::size_t count = calibrator.exportLayouts(models);
            if (verbose) {
                std::vector<CalibrationObjectView> views(config.maxObjects);
                const std::size_t n = calibrator.objectViews(views);
                std::printf("%6.1f s:", static_cast<double>(f + 1) / world.scene().frameRate_hz);
                for (std::size_t i = 0; i < n; ++i)
                    std::printf(" [#%u %zu/%zu est, %zu vis%s]", views[i].id, views[i].markers,
                                views[i].established, views[i].visible,
                                views[i].posed ? "" : " lost");
                std::printf("\n");
                // Which true markers each object holds (visible members only): "object:marker".
                std::map<std::uint32_t, std::string> held;
                calibrator.forEachMember([&](const ObjectCalibrator::MemberView& v) {
                    if (!v.visible)
                        return;
                    const std::optional<std::pair<int, int>> label =
                        trueMarkerAt(observation, v.position_rig_mm);
                    held[v.objectId] += label ? " " + std::to_string(label->first) + ":" +
                                                    std::to_string(label->second)
                                              : std::string(" ?");
                });
                for (const auto& [id, labels] : held)
                    std::printf("     #%u:%s\n", id, labels.c_str());
            }
            std::vector<MarkerModel> copy;
            for (std::size_t i = 0; i < count; ++i) {
                copy.emplace_back(config.maxMarkersPerObject);
                copy.back().assign(models[i]);
            }
            checkpoints.emplace_back(static_cast<double>(f + 1) / world.scene().frameRate_hz,
                                     std::move(copy));
        }
    }

    const auto minFrames = static_cast<int>(minSeen_s * world.scene().frameRate_hz);
    std::vector<std::vector<bool>> expected;
    for (const std::vector<int>& seen : framesSeen) {
        expected.emplace_back();
        for (int n : seen)
            expected.back().push_back(n >= minFrames);
    }
    std::size_t count = calibrator.exportModels(models);
    const Report online = evaluate(std::span(models).first(count), layouts, expected);
    CompletionCounters completionCounters;
    std::vector<LayoutPrecision> precision;
    std::vector<UntiedPieces> untied;
    double completion_s = 0.0;
    if (!onlineOnly) {
        const auto start = std::chrono::steady_clock::now();
        models = learning.complete();
        count = models.size();
        completion_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        completionCounters = learning.completionCounters();
        const std::span<const LayoutPrecision> p = learning.completionPrecision();
        precision.assign(p.begin(), p.end());
        const std::span<const UntiedPieces> u = learning.completionUntiedPieces();
        untied.assign(u.begin(), u.end());
    }
    const Report final = evaluate(std::span(models).first(count), layouts, expected);
    double completeAt = -1.0;
    for (const auto& [time_s, saved] : checkpoints)
        if (complete(evaluate(saved, layouts, expected))) {
            completeAt = time_s;
            break;
        }

    const CalibrationCounters& c = calibrator.counters();
    std::printf("scene %s, %lld frames (%.1f s), level %s, seed %llu\n", sceneName.c_str(),
                static_cast<long long>(frames),
                static_cast<double>(frames) / world.scene().frameRate_hz, level.c_str(),
                static_cast<unsigned long long>(seed));
    if (!onlineOnly) {
        std::printf("online stage: models %zu, stray %zu, false markers %zu, %s\n", online.models,
                    online.strayModels, online.falseMarkers,
                    complete(online) ? "complete" : "incomplete");
        const CompletionCounters& k = completionCounters;
        std::printf("completion: %.2f s, %llu seeds, %llu discovered, %llu rounds, %llu frames "
                    "followed, %llu posed from triangles, joined "
                    "%llu by motion, %llu by tracks and %llu by layout, dropped "
                    "%llu and %llu seen "
                    "too briefly, markers "
                    "added %llu and removed "
                    "%llu, not rigid %llu markers and %llu objects, not fixed %llu, overflow "
                    "sites/models/markers %llu/%llu/%llu\n",
                    completion_s, static_cast<unsigned long long>(k.seeds),
                    static_cast<unsigned long long>(k.discovered),
                    static_cast<unsigned long long>(k.rounds),
                    static_cast<unsigned long long>(k.framesFollowed),
                    static_cast<unsigned long long>(k.framesFromTriangles),
                    static_cast<unsigned long long>(k.joinedByMotion),
                    static_cast<unsigned long long>(k.joinedByTracks),
                    static_cast<unsigned long long>(k.joinedByLayout),
                    static_cast<unsigned long long>(k.dropped),
                    static_cast<unsigned long long>(k.droppedSeenBriefly),
                    static_cast<unsigned long long>(k.markersAdded),
                    static_cast<unsigned long long>(k.markersRemoved),
                    static_cast<unsigned long long>(k.markersNotRigid),
                    static_cast<unsigned long long>(k.droppedNotRigid),
                    static_cast<unsigned long long>(k.markersNotFixed),
                    static_cast<unsigned long long>(k.siteOverflow),
                    static_cast<unsigned long long>(k.modelOverflow),
                    static_cast<unsigned long long>(k.markerOverflow));
    }
    std::printf("models %zu (objects in scene %zu), stray models %zu, false markers %zu\n",
                final.models, layouts.size(), final.strayModels, final.falseMarkers);
    // Completion's word that two models are pieces of one object, checked against the truth.
    for (const UntiedPieces& u : untied)
        if (u.second < final.objectOfModel.size())
            std::printf("  untied pieces: models %zu and %zu share %zu markers (%s)\n", u.first,
                        u.second, u.sharedMarkers,
                        final.objectOfModel[u.first] == final.objectOfModel[u.second]
                            ? "one object"
                            : "two objects");
    for (std::size_t k = 0; k < final.objects.size(); ++k) {
        const ObjectReport& o = final.objects[k];
        std::printf("  object %zu (%s, %zu markers): models %d, found %zu of %zu in view >= %.1f s,"
                    " duplicates %zu, RMS %.3f mm%s\n",
                    k, world.scene().objects[k].object.name.c_str(), layouts[k].size(), o.models,
                    o.found, o.expected, minSeen_s, o.duplicates, o.rms_mm,
                    learnable(o) ? "" : " (not learnable: fewer than 4 markers in view so long)");
        // Sets seen together, merged while they share three markers, are what geometry alone
        // ties into one rigid layout; due markers in two or more such groups can be joined only
        // through motion across the frames between them.
        if (visibleSets) {
            // Runs of frames that show the same markers: which markers were ever seen together,
            // for how long, is what ties an object's pieces.
            const std::vector<std::uint64_t>& inView = inViewPerFrame[k];
            std::size_t start = 0;
            for (std::size_t f = 1; f <= inView.size(); ++f) {
                if (f < inView.size() && inView[f] == inView[start])
                    continue;
                if (std::popcount(inView[start]) >= 3) {
                    std::printf("    frames %zu-%zu:", start, f - 1);
                    for (int m = 0; m < 64; ++m)
                        if ((inView[start] >> m) & 1U)
                            std::printf(" %d", m);
                    std::printf("\n");
                }
                start = f;
            }
        }
        // Three shared markers on one line leave the turn about it open (two faces of a box
        // that share only markers on their common edge): sets are merged while they share
        // markers as far off one line as the tracker asks of a pose's, as completion's own rigid
        // groups are.
        std::vector<completion_detail::MarkerBits> views;
        for (const std::uint64_t v : seenTogether[k])
            views.push_back({v, 0});
        std::vector<std::uint64_t> groups;
        for (const completion_detail::MarkerBits& g : completion_detail::rigidGroupsOf(
                 views, layouts[k], CompletionConfig{}.tracking.minPoseSpread_mm))
            groups.push_back(g[0]);
        std::uint64_t due = 0;
        for (std::size_t m = 0; m < expected[k].size() && m < 64; ++m)
            if (expected[k][m])
                due |= std::uint64_t{1} << m;
        // A group whose due markers all lie in another group adds nothing to tie. Due markers
        // seen only on one line with the others (a plate's row of four) are in no group: nothing
        // ties them to the rest.
        std::vector<std::uint64_t> duePart;
        std::uint64_t grouped = 0;
        for (const std::uint64_t g : groups) {
            grouped |= g;
            if ((g & due) != 0)
                duePart.push_back(g & due);
        }
        if ((due & ~grouped) != 0)
            duePart.push_back(due & ~grouped);
        std::sort(duePart.begin(), duePart.end());
        duePart.erase(std::unique(duePart.begin(), duePart.end()), duePart.end());
        const auto tiedGroups = std::count_if(duePart.begin(), duePart.end(), [&](std::uint64_t d) {
            return std::none_of(duePart.begin(), duePart.end(), [&](std::uint64_t other) {
                return other != d && (other & d) == d;
            });
        });
        if (learnable(o) && layouts[k].size() <= 64 && tiedGroups > 1)
            std::printf("    its due markers lie in %lld rigid groups that never share three "
                        "markers off one line in view\n",
                        static_cast<long long>(tiedGroups));
    }
    for (std::size_t i = 0; i < count; ++i) {
        std::printf("  model %zu: %zu markers, %zu edges, s_min %u%s", i,
                    models[i].markers_model_mm.size(), models[i].edges.size(), models[i].sMin,
                    models[i].sameShapeAs >= 0 ? " (same shape as another)" : "");
        if (i < precision.size())
            std::printf(", fixed to %.3f mm RMS (worst marker %.3f, point noise %.3f mm%s)",
                        precision[i].markerRms_mm, precision[i].worstMarker_mm,
                        precision[i].pointSigma_mm,
                        precision[i].looseModes > 0 ? ", loose modes" : "");
        std::printf("\n");
        if (visibleSets && !final.layoutMarkersOfModel[i].empty()) {
            std::printf("    on object %zu's markers:", final.objectOfModel[i]);
            for (const int m : final.layoutMarkersOfModel[i])
                std::printf(" %d", m);
            std::printf("\n");
        }
    }
    if (verbose)
        for (std::size_t i = 0; i < count; ++i) {
            // Where each false marker lies: a marker learnt out of place, or one of another body.
            std::string off;
            for (const double d : final.falseMarkerDistances_mm[i]) {
                char text[32];
                std::snprintf(text, sizeof text, " %.1f", d);
                off += text;
            }
            if (!off.empty())
                std::printf(
                    "  model %zu on object %zu: false markers at (mm from the nearest):%s\n", i,
                    final.objectOfModel[i], off.c_str());
        }
    if (verbose) {
        // Which true markers each model holds, and, per pair of models of one object, in how
        // many frames each was in view with four of its markers while the other had markers
        // in view that it lacks: the frames that could have tied them together.
        std::vector<std::uint64_t> heldBy(count, 0);
        for (std::size_t i = 0; i < count; ++i) {
            const std::size_t k = final.objectOfModel[i];
            if (layouts[k].size() > 64)
                continue;
            const test::ModelAlignment a = test::alignModel(models[i], layouts[k], kMatch_mm);
            std::string held;
            for (const int m : a.layoutMarkerOf)
                if (m >= 0) {
                    heldBy[i] |= std::uint64_t{1} << m;
                    held += " " + std::to_string(m);
                }
            std::printf("  model %zu holds of object %zu (RMS %.3f mm):%s\n", i, k, a.rms_mm,
                        held.c_str());
            // Two model markers on one true marker: how far apart, and each from the truth.
            const auto& pm = models[i].markers_model_mm;
            for (std::size_t x = 0; x < pm.size(); ++x)
                for (std::size_t y = x + 1; y < pm.size(); ++y) {
                    const int m = a.layoutMarkerOf[x];
                    if (m < 0 || a.layoutMarkerOf[y] != m)
                        continue;
                    const Vec3& truth = layouts[k][static_cast<std::size_t>(m)];
                    std::printf("    duplicate of true marker %d: model markers %zu and %zu, "
                                "%.2f mm apart, %.2f and %.2f mm from the truth\n",
                                m, x, y, (pm[x] - pm[y]).norm(),
                                (a.T_layout_from_model.apply(pm[x]) - truth).norm(),
                                (a.T_layout_from_model.apply(pm[y]) - truth).norm());
                }
        }
        for (std::size_t i = 0; i < count; ++i)
            for (std::size_t j = 0; j < count; ++j) {
                const std::size_t k = final.objectOfModel[i];
                if (i == j || final.objectOfModel[j] != k || layouts[k].size() > 64)
                    continue;
                long aWithOther = 0, both4 = 0, both3 = 0;
                for (const std::uint64_t v : inViewPerFrame[k]) {
                    const int a = std::popcount(v & heldBy[i]);
                    const int b = std::popcount(v & heldBy[j]);
                    aWithOther += a >= 4 && std::popcount(v & heldBy[j] & ~heldBy[i]) > 0;
                    both4 += a >= 4 && b >= 4;
                    both3 += a >= 3 && b >= 3;
                }
                std::printf("  models %zu, %zu: frames %zu in view by 4 with markers of %zu it "
                            "lacks %ld; both by 4 %ld, by 3 %ld\n",
                            i, j, i, j, aWithOther, both4, both3);
            }
        if (timeline && !layouts.empty() && count <= 9) {
            // Markers of each model in view, every 5th frame (one digit per model, then those of
            // the first object that no model holds).
            std::string line;
            for (std::size_t f = 0; f < inViewPerFrame[0].size(); f += 5) {
                for (std::size_t i = 0; i < count; ++i)
                    line += static_cast<char>(
                        '0' + std::min(9, std::popcount(inViewPerFrame[0][f] & heldBy[i])));
                std::uint64_t anyModel = 0;
                for (std::size_t i = 0; i < count; ++i)
                    anyModel |= heldBy[i];
                line += '+';
                line += static_cast<char>(
                    '0' + std::min(9, std::popcount(inViewPerFrame[0][f] & ~anyModel)));
                line += (f / 5 + 1) % 10 == 0 ? '\n' : ' ';
            }
            std::printf("%s\n", line.c_str());
        }
    }
    if (trace)
        printOffMembers(frames);
    if (completeAt >= 0.0)
        std::printf("online stage complete after %.0f s of motion\n", completeAt);
    else
        std::printf("online stage never complete\n");
    const bool anyLearnable = std::any_of(final.objects.begin(), final.objects.end(), learnable);
    // A run that refused data for lack of room is not right, whatever its models: the capacities
    // are the configuration's promise to hold a session like this one.
    const CompletionCounters& refused = completionCounters;
    const bool overflowed = c.markerOverflow + c.objectOverflow + c.memberOverflow +
                                refused.siteOverflow + refused.modelOverflow +
                                refused.markerOverflow >
                            0;
    if (overflowed)
        std::printf("capacity overflow: data was refused\n");
    // The measure: a learnt model's markers within 0.1 mm RMS of the true layout.
    constexpr double kRightRms_mm = 0.1;
    bool precise = true;
    for (const ObjectReport& o : final.objects)
        if (learnable(o) && o.models > 0 && o.rms_mm > kRightRms_mm) {
            if (precise)
                std::printf("marker RMS above %.1f mm\n", kRightRms_mm);
            precise = false;
        }
    // Whether the session's frames could have done better: the precision the least squares
    // predicts for each model of an object above the bound (an estimate that errs by more than
    // its prediction has a fault; one that errs as predicted is what the data allow).
    for (std::size_t i = 0; i < count && i < precision.size(); ++i) {
        const ObjectReport& o = final.objects[final.objectOfModel[i]];
        if (learnable(o) && o.rms_mm > kRightRms_mm && !final.layoutMarkersOfModel[i].empty())
            std::printf(
                "  model %zu of object %zu (RMS %.3f mm) is fixed by the frames to %.3f mm RMS\n",
                i, final.objectOfModel[i], o.rms_mm, precision[i].markerRms_mm);
    }
    std::printf("result: %s\n", !anyLearnable ? "not learnable"
                                : complete(final, allowMissing) && !overflowed && precise
                                    ? "right"
                                    : "WRONG");
    std::printf(
        "counters: born %llu, reappeared %llu, invalid %llu, edges broken %llu, splits %llu,"
        " collapsed %llu, merged %llu, deferred %llu, refound %llu (budget out %llu),"
        " rebased %llu, stale removed %llu,"
        " overflow m/o/mem %llu/%llu/%llu, evicted %llu\n",
        static_cast<unsigned long long>(c.markersBorn),
        static_cast<unsigned long long>(c.markersReappeared),
        static_cast<unsigned long long>(c.invalidRemoved),
        static_cast<unsigned long long>(c.edgesBroken), static_cast<unsigned long long>(c.splits),
        static_cast<unsigned long long>(c.collapsed), static_cast<unsigned long long>(c.merged),
        static_cast<unsigned long long>(c.clusteringDeferred),
        static_cast<unsigned long long>(c.refound),
        static_cast<unsigned long long>(c.refindBudgetExhausted),
        static_cast<unsigned long long>(c.rebased),
        static_cast<unsigned long long>(c.ghostsRemoved),
        static_cast<unsigned long long>(c.markerOverflow),
        static_cast<unsigned long long>(c.objectOverflow),
        static_cast<unsigned long long>(c.memberOverflow),
        static_cast<unsigned long long>(c.objectsEvicted));

    int status = 0;
    if (requireObjects >= 0 && final.models != static_cast<std::size_t>(requireObjects)) {
        std::printf("FAIL: %zu models, expected %d\n", final.models, requireObjects);
        status = 1;
    }
    if (requireRms >= 0.0)
        for (std::size_t k = 0; k < final.objects.size(); ++k)
            if (final.objects[k].rms_mm > requireRms || final.objects[k].models == 0) {
                std::printf("FAIL: object %zu RMS %.3f mm (limit %.3f)\n", k,
                            final.objects[k].rms_mm, requireRms);
                status = 1;
            }
    if (requireComplete && !complete(final, allowMissing)) {
        std::printf("FAIL: models incomplete, duplicated, stray or with false markers\n");
        status = 1;
    }
    return status;
}
