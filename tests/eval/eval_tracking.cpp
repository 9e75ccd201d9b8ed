// Measures model-based tracking on simulated scenes against the simulator's true poses.
//
//   eval_tracking --scene two_cubes [--models MODELDIR | --calibrate-frames N [--calibrate-seed S]
//                 [--write-models DIR] [--other-session]] [--frames 2000] [--seed 3]
//                 [--level images|points]
//                 [--require-found 0.995] [--require-wrong 0.001]
//                 [--require-position-rms 0.3] [--require-rotation-rms 0.2]
//
// Models come from MODELDIR (written by `edgetrack calibrate`), or from a calibration run of N
// frames of the same scene with another seed at the same level (the CalibrationSession, online
// stage and completion, that `edgetrack calibrate` runs; at images level this saves writing
// gigabytes of images),
// or else from the true layouts (every pair co-visible, S_min by the analysis calibrate uses),
// which isolates the tracker from the calibration. Each model is laid onto the true layout it
// matches (copies of one layout are told apart by where they are first found). Per body and frame:
// eligible when at least S_min of its markers were reconstructed; found; wrong when found more than
// 5 mm or 2 degrees from the truth (another body's pose, or none). Reports found shares, wrong
// poses, and the distribution of position and rotation errors of the right poses in the eligible
// frames (the targets' population), and apart from them the errors of the poses held by prediction
// with fewer markers. Exits 1 on a missed target.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "core/calibration_session.hpp"
#include "core/model_tracker.hpp"
#include "core/stereo_matcher.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"
#include "tests/eval/sim_image_pipeline.hpp"
#include "tests/support/model_alignment.hpp"
#include "tests/support/sim_models.hpp"

using namespace edgetrack;

namespace {

constexpr double kAlign_mm = 1.5;
// A reconstructed point this close to a visible true marker is that marker.
constexpr double kAttribute_mm = 1.5;
// A pose further than this from its body's truth is wrong, not merely inaccurate.
constexpr double kWrong_mm = 5.0;
constexpr double kWrong_deg = 2.0;

struct BodyStats {
    std::size_t eligible = 0;      // frames with >= S_min of its markers reconstructed
    std::size_t foundEligible = 0; // of those, found
    std::size_t foundOther = 0;    // found with fewer than S_min reconstructed (by prediction)
    std::size_t wrong = 0;         // found, but far from its truth
    // Returns: an eligible frame after kAbsence_frames or more in which the body was neither
    // eligible nor found (out of view, hidden, turned away), and of them, found right at once.
    std::size_t returns = 0;
    std::size_t returnsFoundAtOnce = 0;
    std::size_t absentFor = 0;
    std::vector<double> position_mm;
    std::vector<double> rotation_deg;
    std::vector<double> fitRms_mm;
    // Errors of the frames with fewer than S_min markers reconstructed (found by prediction).
    std::vector<double> positionFew_mm;
    std::vector<double> rotationFew_deg;
};

constexpr std::size_t kAbsence_frames = 10;

double percentile(std::vector<double> values, double share) {
    if (values.empty())
        return 0.0;
    std::sort(values.begin(), values.end());
    return values[static_cast<std::size_t>(share * static_cast<double>(values.size() - 1))];
}

double rms(const std::vector<double>& values) {
    double sum = 0.0;
    for (double v : values)
        sum += v * v;
    return values.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(values.size()));
}

/// Object calibration over \a frames frames of \a sceneName (seed \a seed), as `calibrate` runs
/// it: the online stage, then completion over every frame of the session.
std::vector<MarkerModel> calibrate(const std::string& sceneName, std::uint64_t seed,
                                   std::int64_t frames, const std::string& level) {
    const sim::World world(*sim::makeScene(sceneName, seed), seed);
    test::SimFrames source(world, seed, level == "images");
    CalibrationSession session(CalibrationConfig{}, CompletionConfig{},
                               static_cast<std::size_t>(frames),
                               static_cast<std::size_t>(frames) * 256);
    std::vector<Vec3> points;
    sim::Observation observation;
    for (std::int64_t f = 0; f < frames; ++f) {
        source.next(static_cast<std::uint64_t>(f), observation, points);
        session.update(observation.time_s, points);
    }
    std::vector<MarkerModel> models = session.complete();
    std::printf("calibrated on %lld frames of seed %llu: %zu models\n",
                static_cast<long long>(frames), static_cast<unsigned long long>(seed),
                models.size());
    return models;
}

} // namespace

int main(int argc, char** argv) {
    CLI::App app{"Model-based tracking quality on a simulated scene"};
    std::string sceneName = "two_cubes";
    std::string modelDir;
    std::int64_t frames = 2000;
    std::uint64_t seed = 3;
    std::string level = "images";
    double requireFound = -1.0;
    double requireWrong = -1.0;
    double requirePositionRms = -1.0;
    double requireRotationRms = -1.0;
    app.add_option("--scene", sceneName);
    app.add_option("--models", modelDir, "models from edgetrack calibrate (default: true layouts)");
    app.add_option("--frames", frames)->check(CLI::PositiveNumber);
    app.add_option("--seed", seed);
    app.add_option("--level", level)->check(CLI::IsMember({"images", "points"}));
    std::int64_t calibrateFrames = 0;
    std::uint64_t calibrateSeed = 2;
    std::string writeModels;
    app.add_option("--calibrate-frames", calibrateFrames, "calibrate on this many frames first");
    app.add_option("--calibrate-seed", calibrateSeed, "seed of the calibration run");
    app.add_option("--write-models", writeModels, "write the calibrated models here");
    ModelTrackingConfig trackingConfig;
    app.add_option("--max-rms", trackingConfig.maxRms_mm, "largest accepted fit residual (mm)");
    app.add_option("--tolerance", trackingConfig.distanceTolerance_mm, "distance tolerance (mm)");
    bool cold = false;
    app.add_flag("--cold", cold, "forget every body before each frame: the search alone");
    double sminTolerance_mm = 0.0;
    app.add_option("--smin-tolerance", sminTolerance_mm,
                   "compute the models' S_min again at this tolerance (mm): with --cold, whether "
                   "an S_min is sound");
    bool verbose = false;
    app.add_flag("--verbose", verbose, "print every wrong pose");
    bool allPairs = false;
    app.add_flag("--all-pairs", allPairs,
                 "give the tracker every pair of each model as an edge, S_min computed again");
    bool otherSession = false;
    app.add_flag("--other-session", otherSession,
                 "track in another session of the calibration's objects (sim::anotherSession of "
                 "--calibrate-seed's scene, drawn from --seed): other motion, viewing directions, "
                 "clutter and a passing hand");
    app.add_option("--require-found", requireFound, "share of eligible frames found");
    app.add_option("--require-wrong", requireWrong, "largest share of found frames that are wrong");
    app.add_option("--require-position-rms", requirePositionRms, "mm");
    app.add_option("--require-rotation-rms", requireRotationRms, "degrees");
    CLI11_PARSE(app, argc, argv);

    std::optional<sim::Scene> scene =
        sim::makeScene(sceneName, otherSession ? calibrateSeed : seed);
    if (scene && otherSession)
        scene = sim::anotherSession(*scene, seed);
    if (!scene) {
        std::fprintf(stderr, "unknown scene %s\n", sceneName.c_str());
        return 2;
    }
    const sim::World world(std::move(*scene), seed);
    std::vector<MarkerModel> models;
    if (calibrateFrames > 0) {
        models = calibrate(sceneName, calibrateSeed, calibrateFrames, level);
        if (!writeModels.empty())
            std::filesystem::create_directories(writeModels);
        if (!writeModels.empty())
            for (const MarkerModel& m : models)
                if (Status s = app::writeModelJson(app::modelPath(writeModels, m.id), m,
                                                   "body " + std::to_string(m.id));
                    !s) {
                    std::fprintf(stderr, "%s\n", s.error().message.c_str());
                    return 2;
                }
    } else if (modelDir.empty()) {
        models = test::truthModels(world.scene());
    } else {
        auto read = app::readModelDirectory(modelDir, MarkerSet::kCapacity);
        if (!read) {
            std::fprintf(stderr, "%s\n", read.error().message.c_str());
            return 2;
        }
        for (app::NamedModel& named : *read)
            models.push_back(std::move(named.model));
    }

    if (allPairs) {
        for (MarkerModel& m : models) {
            m.edges.clear();
            for (std::size_t i = 0; i < m.markers_model_mm.size(); ++i)
                for (std::size_t j = i + 1; j < m.markers_model_mm.size(); ++j)
                    m.edges.push_back({static_cast<std::uint16_t>(i), static_cast<std::uint16_t>(j),
                                       (m.markers_model_mm[i] - m.markers_model_mm[j]).norm()});
        }
        computeSmin(models, SminConfig{});
    }
    if (sminTolerance_mm > 0.0) {
        SminConfig smin;
        smin.tolerance_mm = sminTolerance_mm;
        computeSmin(models, smin);
    }

    // Lay each model onto the layouts; copies of one layout list every object they fit.
    std::vector<std::vector<Vec3>> layouts;
    for (const sim::SceneObject& o : world.scene().objects) {
        layouts.emplace_back();
        for (const sim::SimMarker& m : o.object.markers)
            layouts.back().push_back(m.position_object_mm);
    }
    struct Fit {
        std::size_t object;
        RigidTransform T_object_from_model;
    };
    std::vector<std::vector<Fit>> fits(models.size());
    // Learnt whole: every object one model of all its markers and no other (for the summary).
    std::vector<std::size_t> wholeModelsOf(layouts.size(), 0);
    for (std::size_t b = 0; b < models.size(); ++b) {
        std::size_t bestMatched = 0;
        for (std::size_t k = 0; k < layouts.size(); ++k) {
            const test::ModelAlignment a = test::alignModel(models[b], layouts[k], kAlign_mm);
            wholeModelsOf[k] += a.matched == layouts[k].size() &&
                                models[b].markers_model_mm.size() == layouts[k].size();
            if (a.matched < 4 || a.matched + 1 < bestMatched)
                continue;
            if (a.matched > bestMatched + 1)
                fits[b].clear();
            bestMatched = std::max(bestMatched, a.matched);
            fits[b].push_back(Fit{k, a.T_layout_from_model});
        }
        if (fits[b].empty())
            std::printf("model %u matches no object of the scene\n", models[b].id);
    }
    // objectOf[b]: fixed when only one object fits, else at the body's first pose.
    std::vector<int> objectOf(models.size(), -1);
    for (std::size_t b = 0; b < models.size(); ++b)
        if (fits[b].size() == 1)
            objectOf[b] = static_cast<int>(fits[b][0].object);

    ModelTracker tracker(models, trackingConfig);
    if (!tracker.isValid()) {
        std::fprintf(stderr, "tracker refused the models\n");
        return 2;
    }
    test::SimFrames source(world, seed, level == "images");
    std::vector<BodyStats> stats(models.size());
    std::vector<Vec3> points;
    std::vector<int> visible;
    std::vector<std::size_t> reconstructed(layouts.size());
    sim::Observation observation;
    std::vector<double> frameTimes_us;

    for (std::int64_t f = 0; f < frames; ++f) {
        source.next(static_cast<std::uint64_t>(f), observation, points);
        if (cold)
            tracker.reset();
        const auto start = std::chrono::steady_clock::now();
        tracker.update(observation.time_s, points);
        frameTimes_us.push_back(
            std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - start)
                .count());

        std::fill(reconstructed.begin(), reconstructed.end(), 0);
        for (const Vec3& p : points)
            for (const sim::MarkerView& m : observation.markers)
                if ((m.position_rig_mm - p).norm() < kAttribute_mm) {
                    ++reconstructed[static_cast<std::size_t>(m.object)];
                    break;
                }

        for (std::size_t b = 0; b < models.size(); ++b) {
            const TrackedBody& body = tracker.bodies()[b];
            if (objectOf[b] < 0 && body.found() && !fits[b].empty()) {
                // A copy: its object is the one it is first found on.
                double nearest = 1e300;
                for (const Fit& fit : fits[b]) {
                    const RigidTransform truth =
                        observation.objectPoses[fit.object] * fit.T_object_from_model;
                    const double d =
                        (truth.translation_mm - body.T_rig_from_model.translation_mm).norm();
                    if (d < nearest) {
                        nearest = d;
                        objectOf[b] = static_cast<int>(fit.object);
                    }
                }
            }
            if (objectOf[b] < 0)
                continue;
            const auto k = static_cast<std::size_t>(objectOf[b]);
            RigidTransform T_object_from_model;
            for (const Fit& fit : fits[b])
                if (fit.object == k)
                    T_object_from_model = fit.T_object_from_model;
            BodyStats& s = stats[b];
            const bool eligible = reconstructed[k] >= models[b].sMin;
            s.eligible += eligible;
            const bool returning = eligible && s.absentFor >= kAbsence_frames;
            s.returns += returning;
            s.absentFor = eligible || body.found() ? 0 : s.absentFor + 1;
            if (!body.found()) {
                if (verbose && eligible)
                    std::printf("frame %lld body %u missed with %zu markers reconstructed\n",
                                static_cast<long long>(f), models[b].id, reconstructed[k]);
                continue;
            }
            (eligible ? s.foundEligible : s.foundOther) += 1;
            const RigidTransform truth = observation.objectPoses[k] * T_object_from_model;
            const double position =
                (truth.translation_mm - body.T_rig_from_model.translation_mm).norm();
            const double rotation =
                rotationAngleBetween_rad(truth.rotation, body.T_rig_from_model.rotation) * 180.0 /
                std::numbers::pi;
            s.returnsFoundAtOnce += returning && position <= kWrong_mm && rotation <= kWrong_deg;
            if (position > kWrong_mm || rotation > kWrong_deg) {
                ++s.wrong;
                if (verbose)
                    std::printf("frame %lld body %u wrong: %s, %u markers (%zu reconstructed), "
                                "rms %.3f mm, off by %.1f mm / %.1f deg\n",
                                static_cast<long long>(f), models[b].id,
                                body.source == PoseSource::Predicted ? "predicted" : "searched",
                                body.markers, reconstructed[k], body.rms_mm, position, rotation);
                if (verbose)
                    for (std::size_t j = 0; j < points.size(); ++j) {
                        if (tracker.pointOwners()[j] != static_cast<std::int16_t>(b))
                            continue;
                        double nearest = 1e9;
                        for (const sim::MarkerView& m : observation.markers)
                            if (m.object == static_cast<int>(k))
                                nearest = std::min(nearest, (m.position_rig_mm - points[j]).norm());
                        std::printf("    point %zu: %.2f mm from a true marker\n", j, nearest);
                    }
                continue;
            }
            s.fitRms_mm.push_back(body.rms_mm);
            if (eligible) {
                s.position_mm.push_back(position);
                s.rotation_deg.push_back(rotation);
            } else {
                s.positionFew_mm.push_back(position);
                s.rotationFew_deg.push_back(rotation);
            }
        }
    }

    std::printf(
        "scene %s, %lld frames, level %s, seed %llu, models %s\n", sceneName.c_str(),
        static_cast<long long>(frames), level.c_str(), static_cast<unsigned long long>(seed),
        calibrateFrames > 0 ? "calibrated here"
                            : (modelDir.empty() ? "from the true layouts" : modelDir.c_str()));
    int status = 0;
    for (std::size_t b = 0; b < models.size(); ++b) {
        const BodyStats& s = stats[b];
        const std::size_t found = s.foundEligible + s.foundOther;
        const double foundShare =
            s.eligible ? static_cast<double>(s.foundEligible) / static_cast<double>(s.eligible)
                       : 1.0;
        const double wrongShare =
            found ? static_cast<double>(s.wrong) / static_cast<double>(found) : 0.0;
        const double positionRms = rms(s.position_mm);
        const double rotationRms = rms(s.rotation_deg);
        std::printf(
            "body %u (%s, %zu markers, s_min %u):\n", models[b].id,
            objectOf[b] >= 0
                ? world.scene().objects[static_cast<std::size_t>(objectOf[b])].object.name.c_str()
                : "no object",
            models[b].markers_model_mm.size(), models[b].sMin);
        std::printf("  found in %zu of %zu eligible frames (%.2f%%), missed %zu; also found in %zu"
                    " frames with fewer than s_min markers\n",
                    s.foundEligible, s.eligible, 100.0 * foundShare, s.eligible - s.foundEligible,
                    s.foundOther);
        std::printf("  wrong pose in %zu of %zu found frames (%.3f%%)\n", s.wrong, found,
                    100.0 * wrongShare);
        std::printf("  returns (eligible after %zu or more frames absent): %zu, found in that very "
                    "frame: %zu\n",
                    kAbsence_frames, s.returns, s.returnsFoundAtOnce);
        std::printf("  position error mm: rms %.3f, median %.3f, 95%% %.3f, 99%% %.3f, max %.3f\n",
                    positionRms, percentile(s.position_mm, 0.5), percentile(s.position_mm, 0.95),
                    percentile(s.position_mm, 0.99), percentile(s.position_mm, 1.0));
        std::printf("  rotation error deg: rms %.3f, median %.3f, 95%% %.3f, 99%% %.3f, max %.3f\n",
                    rotationRms, percentile(s.rotation_deg, 0.5), percentile(s.rotation_deg, 0.95),
                    percentile(s.rotation_deg, 0.99), percentile(s.rotation_deg, 1.0));
        std::printf("  fit residual (eq. 6) mm: median %.3f, 99%% %.3f, max %.3f\n",
                    percentile(s.fitRms_mm, 0.5), percentile(s.fitRms_mm, 0.99),
                    percentile(s.fitRms_mm, 1.0));
        std::printf(
            "  frames with fewer than s_min markers: position rms %.3f mm, rotation rms %.3f"
            " deg, 95%% %.3f deg\n",
            rms(s.positionFew_mm), rms(s.rotationFew_deg), percentile(s.rotationFew_deg, 0.95));
        if (objectOf[b] < 0)
            continue; // a model of nothing in the scene (a stray calibration fragment)
        if (requireFound >= 0.0 && foundShare < requireFound) {
            std::printf("FAIL: body %u found in %.2f%% (target %.2f%%)\n", models[b].id,
                        100.0 * foundShare, 100.0 * requireFound);
            status = 1;
        }
        if (requireWrong >= 0.0 && wrongShare > requireWrong) {
            std::printf("FAIL: body %u wrong in %.3f%% (limit %.3f%%)\n", models[b].id,
                        100.0 * wrongShare, 100.0 * requireWrong);
            status = 1;
        }
        if (requirePositionRms >= 0.0 && positionRms > requirePositionRms) {
            std::printf("FAIL: body %u position rms %.3f mm (limit %.3f)\n", models[b].id,
                        positionRms, requirePositionRms);
            status = 1;
        }
        if (requireRotationRms >= 0.0 && rotationRms > requireRotationRms) {
            std::printf("FAIL: body %u rotation rms %.3f deg (limit %.3f)\n", models[b].id,
                        rotationRms, requireRotationRms);
            status = 1;
        }
    }
    // One line for sweeps (tests/eval/cross_session_sweep.sh): the totals over the bodies.
    BodyStats all;
    for (const BodyStats& s : stats) {
        all.eligible += s.eligible;
        all.foundEligible += s.foundEligible;
        all.wrong += s.wrong;
        all.returns += s.returns;
        all.returnsFoundAtOnce += s.returnsFoundAtOnce;
    }
    const bool whole =
        models.size() == layouts.size() && std::all_of(wholeModelsOf.begin(), wholeModelsOf.end(),
                                                       [](std::size_t n) { return n == 1; });
    std::printf("summary: whole %d eligible %zu found %zu wrong %zu returns %zu at-once %zu\n",
                whole ? 1 : 0, all.eligible, all.foundEligible, all.wrong, all.returns,
                all.returnsFoundAtOnce);
    const ModelTrackingCounters& c = tracker.counters();
    std::printf(
        "tracker: %.1f us a frame on average, 99%% %.1f us, max %.1f us (this machine)\n",
        [&] {
            double sum = 0.0;
            for (double t : frameTimes_us)
                sum += t;
            return sum / static_cast<double>(frameTimes_us.size());
        }(),
        percentile(frameTimes_us, 0.99), percentile(frameTimes_us, 1.0));
    std::printf("counters: predicted %llu (failed %llu), searches %llu (found %llu), hypotheses "
                "%llu, candidates dropped %llu, budget out %llu frames, searches skipped %llu, "
                "identity yields %llu\n",
                static_cast<unsigned long long>(c.predictedHits),
                static_cast<unsigned long long>(c.predictionFailures),
                static_cast<unsigned long long>(c.searches),
                static_cast<unsigned long long>(c.searchHits),
                static_cast<unsigned long long>(c.hypotheses),
                static_cast<unsigned long long>(c.candidateOverflow),
                static_cast<unsigned long long>(c.budgetExhausted),
                static_cast<unsigned long long>(c.searchesSkipped),
                static_cast<unsigned long long>(c.identityYields));
    return status;
}
