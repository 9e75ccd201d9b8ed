// Object calibration on a real Vicon recording: a rigid box among a person's skin markers.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/calibration_completion.hpp"
#include "core/calibration_session.hpp"
#include "core/model_tracker.hpp"
#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"
#include "firmware_app/formats/c3d.hpp"
#include "tests/support/model_alignment.hpp"

namespace edgetrack {
namespace {

const std::filesystem::path kVicon =
    std::filesystem::path(EDGETRACK_REALDATA_DIR) / "ezc3d-testFiles" / "Vicon.c3d";

// The C3D points labelled as the box's markers.
std::vector<std::size_t> boxPoints(const recording::C3dPoints& c3d) {
    std::vector<std::size_t> box;
    for (std::size_t p = 0; p < c3d.pointCount; ++p)
        if (c3d.labels[p].rfind("boite:", 0) == 0)
            box.push_back(p);
    return box;
}

// The frame's valid points (mm), labels ignored.
void framePoints(const recording::C3dPoints& c3d, std::size_t frame, std::vector<Vec3>& points) {
    points.clear();
    for (std::size_t p = 0; p < c3d.pointCount; ++p)
        if (c3d.isValid(frame, p))
            points.push_back(c3d.position(frame, p));
}

// The box's labelled layout: every frame with all eight markers fitted onto the first such frame,
// and averaged (mm, in that frame's coordinates).
std::vector<Vec3> labelledBox(const recording::C3dPoints& c3d,
                              const std::vector<std::size_t>& box) {
    std::vector<Vec3> reference, sum(box.size(), Vec3::Zero());
    int frames = 0;
    for (std::size_t f = 0; f < c3d.frameCount; ++f) {
        std::vector<Vec3> now;
        for (std::size_t p : box)
            if (c3d.isValid(f, p))
                now.push_back(c3d.position(f, p));
        if (now.size() != box.size())
            continue;
        if (reference.empty())
            reference = now;
        const std::optional<RigidFit> fit = fitRigid(now, reference);
        if (!fit)
            continue;
        for (std::size_t i = 0; i < now.size(); ++i)
            sum[i] += fit->transform.apply(now[i]);
        ++frames;
    }
    for (Vec3& p : sum)
        p /= static_cast<double>(frames);
    return sum;
}

TEST(CalibrationRealData, ViconBoxIsOneObjectOfItsEightMarkers) {
    if (!std::filesystem::exists(kVicon))
        GTEST_SKIP() << kVicon << " is absent (the shared real-data folder is not here)";
    const Result<recording::C3dPoints> c3d = recording::readC3d(kVicon);
    ASSERT_TRUE(c3d) << c3d.error().message;
    const std::vector<std::size_t> box = boxPoints(*c3d);
    ASSERT_EQ(box.size(), 8u);
    const std::vector<Vec3> layout = labelledBox(*c3d, box);

    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < c3d->frameCount; ++f) {
        framePoints(*c3d, f, points);
        calibrator.update(static_cast<double>(f) / c3d->frameRate_hz, points);
    }
    std::vector<MarkerModel> models;
    for (std::size_t i = 0; i < config.maxObjects; ++i)
        models.emplace_back(config.maxMarkersPerObject);
    const std::size_t count = calibrator.exportModels(models);

    // Exactly one model holds box markers; it holds all eight and nothing else, within 1 mm.
    int boxModels = 0;
    for (std::size_t i = 0; i < count; ++i) {
        const test::ModelAlignment a = test::alignModel(models[i], layout, 1.0);
        if (a.matched < 3)
            continue;
        ++boxModels;
        EXPECT_EQ(a.matched, 8u);
        EXPECT_EQ(models[i].markers_model_mm.size(), 8u) << "skin markers merged into the box";
        EXPECT_LT(a.rms_mm, 1.0);
        for (std::size_t m = 0; m < models[i].markers_model_mm.size(); ++m)
            if (a.layoutMarkerOf[m] >= 0) {
                EXPECT_LT((a.T_layout_from_model.apply(models[i].markers_model_mm[m]) -
                           layout[static_cast<std::size_t>(a.layoutMarkerOf[m])])
                              .norm(),
                          1.0);
            }
        RecordProperty("box_rms_mm", std::to_string(a.rms_mm));
    }
    EXPECT_EQ(boxModels, 1);
}

// The whole calibration as `edgetrack calibrate` runs it (online stage, then completion), with
// each frame's points in the file's order and in 19 shuffled ones (one under the sanitizers and
// qemu, where a run takes minutes): one model holds the box's eight markers and no skin marker,
// and every order gives the same models. The box's markers scatter
// 1-2 mm about their places, more than the 1.5 mm place radius the simulated markers need:
// completion takes the radius from the scatter, or it keeps only six.
TEST(CalibrationRealData, ViconBoxCompletedTheSameWhateverTheOrderOfPoints) {
    if (!std::filesystem::exists(kVicon))
        GTEST_SKIP() << kVicon << " is absent (the shared real-data folder is not here)";
    const Result<recording::C3dPoints> c3d = recording::readC3d(kVicon);
    ASSERT_TRUE(c3d) << c3d.error().message;
    const std::vector<Vec3> layout = labelledBox(*c3d, boxPoints(*c3d));

    auto learn = [&](unsigned shuffleSeed) {
        CalibrationSession session(CalibrationConfig{}, CompletionConfig{}, c3d->frameCount,
                                   c3d->frameCount * 64);
        std::mt19937 shuffler(shuffleSeed);
        std::vector<Vec3> points;
        for (std::size_t f = 0; f < c3d->frameCount; ++f) {
            framePoints(*c3d, f, points);
            if (shuffleSeed != 0)
                std::shuffle(points.begin(), points.end(), shuffler);
            session.update(static_cast<double>(f) / c3d->frameRate_hz, points);
        }
        std::vector<MarkerModel> models = session.complete();
        return models;
    };
    const std::vector<MarkerModel> models = learn(0);
    int boxModels = 0;
    for (const MarkerModel& model : models) {
        const test::ModelAlignment a = test::alignModel(model, layout, 1.0);
        if (a.matched < 3)
            continue;
        ++boxModels;
        EXPECT_EQ(a.matched, 8u);
        EXPECT_EQ(model.markers_model_mm.size(), a.matched) << "skin markers in the box's model";
        EXPECT_LT(a.rms_mm, 1.0);
        RecordProperty("completed_box_markers", std::to_string(a.matched));
    }
    EXPECT_EQ(boxModels, 1);
#ifdef EDGETRACK_SLOW_TARGET
    constexpr unsigned kShuffledOrders = 1;
#else
    constexpr unsigned kShuffledOrders = 19;
#endif
    for (unsigned order = 1; order <= kShuffledOrders; ++order) {
        const std::vector<MarkerModel> shuffled = learn(order);
        ASSERT_EQ(shuffled.size(), models.size()) << "order " << order;
        for (std::size_t m = 0; m < models.size(); ++m) {
            ASSERT_EQ(shuffled[m].markers_model_mm.size(), models[m].markers_model_mm.size());
            for (std::size_t k = 0; k < models[m].markers_model_mm.size(); ++k)
                EXPECT_EQ(shuffled[m].markers_model_mm[k], models[m].markers_model_mm[k]);
        }
    }
}

const std::filesystem::path kQualisys =
    std::filesystem::path(EDGETRACK_REALDATA_DIR) / "ezc3d-testFiles" / "Qualisys.c3d";

// The whole calibration of a recording in one point order (0: the file's; else shuffled).
std::vector<MarkerModel> learnC3d(const recording::C3dPoints& c3d, const CalibrationConfig& config,
                                  unsigned shuffleSeed) {
    CalibrationSession session(config, CompletionConfig{}, c3d.frameCount,
                               c3d.frameCount * c3d.pointCount);
    std::mt19937 shuffler(shuffleSeed);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < c3d.frameCount; ++f) {
        framePoints(c3d, f, points);
        if (shuffleSeed != 0)
            std::shuffle(points.begin(), points.end(), shuffler);
        session.update(static_cast<double>(f) / c3d.frameRate_hz, points);
    }
    return session.complete();
}

// The Qualisys recording's headband (L_HDF, L_HDB, R_HDB, R_HDF) sits on skin: its markers keep
// their distances only within about +-1.7 mm while the trunk's and limbs' move 10 mm and more
// against it. With the default edge tolerance (2 mm) no model holds it; with the setting
// docs/object-calibration.md gives for markers on skin ([calibration] edge_break_mm = 5) it is
// one model of its four markers, with none of the trunk's, in every point order.
TEST(CalibrationRealData, QualisysHeadbandIsOneModelWithTheSkinTolerance) {
    if (!std::filesystem::exists(kQualisys))
        GTEST_SKIP() << kQualisys << " is absent (the shared real-data folder is not here)";
    const Result<recording::C3dPoints> c3d = recording::readC3d(kQualisys);
    ASSERT_TRUE(c3d) << c3d.error().message;
    std::vector<std::size_t> headband;
    for (std::size_t p = 0; p < c3d->pointCount; ++p)
        for (const char* label : {"L_HDF", "L_HDB", "R_HDB", "R_HDF"})
            if (c3d->labels[p] == label)
                headband.push_back(p);
    ASSERT_EQ(headband.size(), 4u);
    const std::vector<Vec3> layout = labelledBox(*c3d, headband);

    // Within 3 mm of the labelled layout: the markers wander up to 1.7 mm on the skin.
    auto headbandModels = [&](const std::vector<MarkerModel>& models) {
        std::vector<test::ModelAlignment> found;
        for (const MarkerModel& model : models) {
            test::ModelAlignment a = test::alignModel(model, layout, 3.0);
            if (a.matched >= 3) {
                EXPECT_EQ(model.markers_model_mm.size(), a.matched)
                    << "markers of the trunk or limbs in the headband's model";
                found.push_back(std::move(a));
            }
        }
        return found;
    };
    EXPECT_TRUE(headbandModels(learnC3d(*c3d, CalibrationConfig{}, 0)).empty())
        << "the default tolerance was expected to refuse skin markers";

    CalibrationConfig skin;
    skin.edgeBreak_mm = 5.0;
    const std::vector<MarkerModel> models = learnC3d(*c3d, skin, 0);
    const std::vector<test::ModelAlignment> found = headbandModels(models);
    ASSERT_EQ(found.size(), 1u);
    EXPECT_EQ(found[0].matched, 4u);
    RecordProperty("headband_rms_mm", std::to_string(found[0].rms_mm));
#ifdef EDGETRACK_SLOW_TARGET
    constexpr unsigned kShuffledOrders = 1;
#else
    constexpr unsigned kShuffledOrders = 5;
#endif
    for (unsigned order = 1; order <= kShuffledOrders; ++order) {
        const std::vector<MarkerModel> shuffled = learnC3d(*c3d, skin, order);
        ASSERT_EQ(shuffled.size(), models.size()) << "order " << order;
        for (std::size_t m = 0; m < models.size(); ++m) {
            ASSERT_EQ(shuffled[m].markers_model_mm.size(), models[m].markers_model_mm.size());
            for (std::size_t k = 0; k < models[m].markers_model_mm.size(); ++k)
                EXPECT_EQ(shuffled[m].markers_model_mm[k], models[m].markers_model_mm[k]);
        }
    }
}

// Learn on one half, track the box through the other half with every model learnt. The issue asks
// for first half -> second half; after the first 2.9 s the calibrator holds no established box
// (docs/model-tracking.md, "Real data"), so the halves are taken the other way round.
TEST(TrackingRealData, ViconBoxLearntOnTheSecondHalfTrackedThroughTheFirst) {
    if (!std::filesystem::exists(kVicon))
        GTEST_SKIP() << kVicon << " is absent (the shared real-data folder is not here)";
    const Result<recording::C3dPoints> c3d = recording::readC3d(kVicon);
    ASSERT_TRUE(c3d) << c3d.error().message;
    const std::vector<std::size_t> box = boxPoints(*c3d);
    ASSERT_EQ(box.size(), 8u);
    const std::vector<Vec3> layout = labelledBox(*c3d, box);
    const std::size_t half = c3d->frameCount / 2;

    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points;
    for (std::size_t f = half; f < c3d->frameCount; ++f) {
        framePoints(*c3d, f, points);
        calibrator.update(static_cast<double>(f) / c3d->frameRate_hz, points);
    }
    std::vector<MarkerModel> models;
    for (std::size_t i = 0; i < config.maxObjects; ++i)
        models.emplace_back(config.maxMarkersPerObject);
    models.resize(calibrator.exportModels(models));
    std::size_t boxModel = models.size();
    test::ModelAlignment alignment;
    for (std::size_t i = 0; i < models.size(); ++i) {
        test::ModelAlignment a = test::alignModel(models[i], layout, 1.0);
        if (a.matched >= 4 && a.matched > alignment.matched) {
            alignment = std::move(a);
            boxModel = i;
        }
    }
    ASSERT_LT(boxModel, models.size()) << "the second half gave no model of the box";

    ModelTracker tracker(models, ModelTrackingConfig{});
    ASSERT_TRUE(tracker.isValid());
    std::size_t eligible = 0, hits = 0, hitsEligible = 0;
    double sumSquares = 0.0, worst = 0.0;
    std::size_t residuals = 0, far = 0;
    for (std::size_t f = 0; f < half; ++f) {
        framePoints(*c3d, f, points);
        tracker.update(static_cast<double>(f) / c3d->frameRate_hz, points);
        std::size_t seen = 0;
        for (std::size_t p : box)
            seen += c3d->isValid(f, p) ? 1U : 0U;
        const bool isEligible = seen >= models[boxModel].sMin;
        eligible += isEligible;
        const TrackedBody& body = tracker.bodies()[boxModel];
        if (!body.found())
            continue;
        ++hits;
        hitsEligible += isEligible;
        // Residual of each labelled marker against the model marker the pose puts there.
        for (std::size_t m = 0; m < models[boxModel].markers_model_mm.size(); ++m) {
            if (alignment.layoutMarkerOf[m] < 0)
                continue;
            const std::size_t point = box[static_cast<std::size_t>(alignment.layoutMarkerOf[m])];
            if (!c3d->isValid(f, point))
                continue;
            const double r = (body.T_rig_from_model.apply(models[boxModel].markers_model_mm[m]) -
                              c3d->position(f, point))
                                 .norm();
            sumSquares += r * r;
            worst = std::max(worst, r);
            far += r > 2.0 ? 1U : 0U;
            ++residuals;
        }
    }
    const double rms =
        std::sqrt(sumSquares / static_cast<double>(std::max<std::size_t>(residuals, 1)));
    RecordProperty("box_hits", std::to_string(hits));
    RecordProperty("box_eligible", std::to_string(eligible));
    RecordProperty("box_residual_rms_mm", std::to_string(rms));
    std::printf(
        "box: model %zu of %zu (%zu markers, s_min %u); first half %zu frames: found in %zu,"
        " %zu of %zu with >= s_min labelled markers; residual rms %.3f mm, max %.3f mm, %zu of %zu "
        "above 2 mm\n",
        boxModel, models.size(), models[boxModel].markers_model_mm.size(), models[boxModel].sMin,
        half, hits, hitsEligible, eligible, rms, worst, far, residuals);
    EXPECT_GE(static_cast<double>(hitsEligible), 0.99 * static_cast<double>(eligible));
    EXPECT_LT(rms, 1.0);
    // Around frames 206-220 the labelled markers themselves are not rigid (fitted onto the box's
    // layout they are off by up to 3 mm), so a few residuals are large however good the pose.
    EXPECT_LE(static_cast<double>(far), 0.01 * static_cast<double>(residuals))
        << far << " of " << residuals << " residuals above 2 mm";
}

} // namespace
} // namespace edgetrack
