// Unit tests of model-based tracking: search, prediction, several bodies, copies, budget, memory.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/model_tracker.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack {
namespace {

MarkerModel completeModel(const std::vector<Vec3>& layout, std::uint32_t id, std::uint32_t sMin) {
    return test::fullyConnectedModel(layout, id, sMin);
}

RigidTransform pose(double angle_rad, const Vec3& axis, const Vec3& translation_mm) {
    RigidTransform T;
    T.rotation = Quat(Eigen::AngleAxisd(angle_rad, axis.normalized()));
    T.translation_mm = translation_mm;
    return T;
}

/// Appends the markers of \a layout placed by \a T_rig_from_model whose index passes \a visible.
template <typename Visible>
void place(const std::vector<Vec3>& layout, const RigidTransform& T_rig_from_model, Visible visible,
           std::vector<Vec3>& points) {
    for (std::size_t i = 0; i < layout.size(); ++i)
        if (visible(i))
            points.push_back(T_rig_from_model.apply(layout[i]));
}

void expectPose(const TrackedBody& body, const RigidTransform& truth, double tolerance_mm,
                double tolerance_rad = 1e-6) {
    ASSERT_TRUE(body.found());
    EXPECT_LT((body.T_rig_from_model.translation_mm - truth.translation_mm).norm(), tolerance_mm);
    EXPECT_LT(rotationAngleBetween_rad(body.T_rig_from_model.rotation, truth.rotation),
              tolerance_rad);
}

const auto all = [](std::size_t) { return true; };

/// Every marker of \a layout placed by \a T_rig_from_model, each moved by noise of \a sigma_mm
/// in every axis (random seed \a seed).
std::vector<Vec3> placedOff(const std::vector<Vec3>& layout, const RigidTransform& T_rig_from_model,
                            double sigma_mm, unsigned seed) {
    std::mt19937 random(seed);
    std::normal_distribution<double> off(0.0, sigma_mm);
    std::vector<Vec3> points;
    place(layout, T_rig_from_model, all, points);
    for (Vec3& p : points)
        p += Vec3(off(random), off(random), off(random));
    return points;
}

/// Models are move-only (their storage is sized once), so lists of them are built by moves.
template <typename... Models>
std::vector<MarkerModel> modelList(Models&&... models) {
    std::vector<MarkerModel> list;
    (list.push_back(std::move(models)), ...);
    return list;
}

TEST(ModelTracker, FindsABodyByTheSubgraphSearch) {
    const std::vector<Vec3> layout = test::irregularLayout(12, 3, 12.0);
    const MarkerModel model = completeModel(layout, 7, 4);
    ModelTracker tracker(std::span(&model, 1), ModelTrackingConfig{});
    ASSERT_TRUE(tracker.isValid());

    const RigidTransform truth = pose(0.8, {1, 2, 3}, {20.0, -10.0, 560.0});
    std::vector<Vec3> points;
    place(layout, truth, all, points);
    tracker.update(0.0, points);

    const TrackedBody& body = tracker.bodies()[0];
    EXPECT_EQ(body.modelId, 7u);
    EXPECT_EQ(body.source, PoseSource::Searched);
    EXPECT_EQ(body.markers, 12u);
    EXPECT_LT(body.rms_mm, 1e-6);
    expectPose(body, truth, 1e-6);
    for (const std::int16_t owner : tracker.pointOwners())
        EXPECT_EQ(owner, 0);
}

TEST(ModelTracker, FindsAPartlyHiddenBodyAmongSpuriousPoints) {
    const std::vector<Vec3> layout = test::irregularLayout(20, 5, 12.0);
    const MarkerModel model = completeModel(layout, 0, 5);
    ModelTracker tracker(std::span(&model, 1), ModelTrackingConfig{});

    const RigidTransform truth = pose(2.1, {0, 1, 1}, {-40.0, 30.0, 600.0});
    std::vector<Vec3> points;
    // Only the markers on one side, as when the body faces away; noise of a tenth of a mm.
    place(
        layout, truth, [&](std::size_t i) { return layout[i].x() > 0.0; }, points);
    const std::size_t visible = points.size();
    ASSERT_GE(visible, 5u);
    std::mt19937 random(11);
    std::normal_distribution<double> noise(0.0, 0.1);
    for (Vec3& p : points)
        p += Vec3(noise(random), noise(random), noise(random));
    std::uniform_real_distribution<double> volume(-150.0, 150.0);
    for (int i = 0; i < 25; ++i)
        points.push_back(Vec3(volume(random), volume(random), 600.0 + volume(random)));

    tracker.update(0.0, points);
    const TrackedBody& body = tracker.bodies()[0];
    expectPose(body, truth, 0.3, 0.01);
    EXPECT_EQ(body.markers, visible);
    EXPECT_LT(body.rms_mm, 0.3);
    for (std::size_t j = 0; j < points.size(); ++j)
        EXPECT_EQ(tracker.pointOwners()[j], j < visible ? 0 : -1) << "point " << j;
}

TEST(ModelTracker, NeedsSminMarkersToFindButFewerToFollow) {
    const std::vector<Vec3> layout = test::irregularLayout(10, 8, 12.0);
    const MarkerModel model = completeModel(layout, 0, 6);
    ModelTracker tracker(std::span(&model, 1), ModelTrackingConfig{});

    std::vector<Vec3> points;
    const auto five = [](std::size_t i) { return i < 5; };
    place(layout, pose(0.3, {0, 0, 1}, {0.0, 0.0, 500.0}), five, points);
    tracker.update(0.0, points);
    EXPECT_FALSE(tracker.bodies()[0].found()) << "five markers are below S_min 6";

    for (int f = 1; f <= 3; ++f) {
        points.clear();
        place(layout, pose(0.3 + 0.01 * f, {0, 0, 1}, {0.5 * f, 0.0, 500.0}), all, points);
        tracker.update(0.01 * f, points);
    }
    ASSERT_TRUE(tracker.bodies()[0].found());
    points.clear();
    const RigidTransform truth = pose(0.34, {0, 0, 1}, {2.0, 0.0, 500.0});
    place(layout, truth, five, points);
    tracker.update(0.04, points);
    EXPECT_EQ(tracker.bodies()[0].source, PoseSource::Predicted);
    expectPose(tracker.bodies()[0], truth, 1e-6);
}

TEST(ModelTracker, GivesNoPoseFromMarkersOnOneLine) {
    // A row of four markers 20 mm apart, within 0.3 mm of one line as a measured row is, and two
    // markers off it: the row alone says next to nothing of the turn about its line, so it must
    // neither find nor carry the body.
    const std::vector<Vec3> layout = {{0, 0, 0},     {20, 0.3, 0}, {40, -0.2, 0.2},
                                      {60, 0, -0.3}, {25, 30, 0},  {45, 10, 25}};
    const MarkerModel model = completeModel(layout, 0, 4);
    ModelTracker tracker(std::span(&model, 1), ModelTrackingConfig{});
    const auto row = [](std::size_t i) { return i < 4; };
    std::vector<Vec3> points;

    place(layout, pose(0.3, {0, 1, 1}, {0.0, 0.0, 500.0}), row, points);
    tracker.update(0.0, points);
    EXPECT_FALSE(tracker.bodies()[0].found()) << "four markers on one line";

    // Found with the markers off the line, then followed as they leave: lost with them.
    for (int f = 1; f <= 3; ++f) {
        points.clear();
        place(layout, pose(0.3 + 0.01 * f, {0, 1, 1}, {0.5 * f, 0.0, 500.0}), all, points);
        tracker.update(0.01 * f, points);
        ASSERT_TRUE(tracker.bodies()[0].found()) << "frame " << f;
    }
    const auto rowAndOne = [](std::size_t i) { return i < 5; };
    points.clear();
    place(layout, pose(0.34, {0, 1, 1}, {2.0, 0.0, 500.0}), rowAndOne, points);
    tracker.update(0.04, points);
    EXPECT_TRUE(tracker.bodies()[0].found()) << "one marker 30 mm off the line is enough";
    points.clear();
    place(layout, pose(0.35, {0, 1, 1}, {2.5, 0.0, 500.0}), row, points);
    tracker.update(0.05, points);
    EXPECT_FALSE(tracker.bodies()[0].found()) << "followed onto the row alone";
    EXPECT_GT(tracker.counters().degeneratePoses, 0u);
}

TEST(ModelTracker, FollowsAMovingBodyByPrediction) {
    const std::vector<Vec3> layout = test::irregularLayout(15, 21, 12.0);
    const MarkerModel model = completeModel(layout, 0, 4);
    ModelTracker tracker(std::span(&model, 1), ModelTrackingConfig{});

    std::vector<Vec3> points;
    for (int f = 0; f < 200; ++f) {
        const double t = 0.01 * f;
        // 0.5 m/s and 3 rad/s: 5 mm and 1.7 degrees a frame.
        const RigidTransform truth = pose(3.0 * t, {1, 1, 0}, {500.0 * t - 500.0, 0.0, 600.0});
        points.clear();
        place(layout, truth, all, points);
        tracker.update(t, points);
        expectPose(tracker.bodies()[0], truth, 1e-6);
        if (f > 0) {
            EXPECT_EQ(tracker.bodies()[0].source, PoseSource::Predicted) << "frame " << f;
        }
    }
    EXPECT_EQ(tracker.counters().searches, 1u);
    EXPECT_EQ(tracker.counters().predictedHits, 199u);
}

TEST(ModelTracker, KeepsSeveralBodiesApart) {
    const std::vector<Vec3> a = test::irregularLayout(14, 31, 12.0);
    const std::vector<Vec3> b = test::irregularLayout(10, 32, 12.0);
    const std::vector<Vec3> c = test::irregularLayout(8, 33, 12.0);
    const std::vector<MarkerModel> models =
        modelList(completeModel(a, 0, 4), completeModel(b, 1, 4), completeModel(c, 2, 4));
    ModelTracker tracker(models, ModelTrackingConfig{});

    const RigidTransform ta = pose(0.5, {1, 0, 0}, {-100.0, 0.0, 600.0});
    const RigidTransform tb = pose(1.5, {0, 1, 0}, {0.0, 0.0, 600.0});
    const RigidTransform tc = pose(2.5, {0, 0, 1}, {90.0, 0.0, 600.0});
    std::vector<Vec3> points;
    place(c, tc, all, points);
    place(a, ta, all, points);
    place(b, tb, all, points);
    tracker.update(0.0, points);
    expectPose(tracker.bodies()[0], ta, 1e-6);
    expectPose(tracker.bodies()[1], tb, 1e-6);
    expectPose(tracker.bodies()[2], tc, 1e-6);
    const std::span<const std::int16_t> owners = tracker.pointOwners();
    for (std::size_t j = 0; j < points.size(); ++j)
        EXPECT_EQ(owners[j], j < 8 ? 2 : (j < 22 ? 0 : 1)) << "point " << j;
}

TEST(ModelTracker, TwoCopiesKeepTheirIdentityThroughAGap) {
    // Two bodies of one layout (calibrated separately: a tenth of a millimetre apart).
    const std::vector<Vec3> layout = test::irregularLayout(12, 41, 12.0);
    std::vector<Vec3> copy = layout;
    copy[0] += Vec3(0.1, 0.0, 0.0);
    const std::vector<MarkerModel> models =
        modelList(completeModel(layout, 0, 4), completeModel(copy, 1, 4));
    ModelTracker tracker(models, ModelTrackingConfig{});

    std::vector<Vec3> points;
    auto frame = [&](int f, bool visible) {
        const double t = 0.01 * f;
        // Body 0 starts on the left, body 1 on the right; both drift towards the middle.
        const RigidTransform t0 = pose(0.2 * t, {0, 1, 0}, {-150.0 + 20.0 * t, 0.0, 600.0});
        const RigidTransform t1 = pose(-0.3 * t, {1, 0, 0}, {150.0 - 20.0 * t, 0.0, 600.0});
        points.clear();
        if (visible) {
            // The right body first, so that a search by data order would meet it first.
            place(layout, t1, all, points);
            place(layout, t0, all, points);
        }
        tracker.update(t, points);
        if (visible) {
            SCOPED_TRACE(f);
            expectPose(tracker.bodies()[0], t0, 0.2, 0.01);
            expectPose(tracker.bodies()[1], t1, 0.2, 0.01);
        }
    };
    // Known from the start: body 0 is the left one, given the left one alone first.
    points.clear();
    place(layout, pose(0.0, {0, 1, 0}, {-150.0, 0.0, 600.0}), all, points);
    tracker.update(-0.01, points);
    ASSERT_TRUE(tracker.bodies()[0].found());
    for (int f = 0; f < 50; ++f)
        frame(f, true);
    // Both hidden for half a second (beyond prediction), then back: found by search, each by
    // where it was.
    for (int f = 50; f < 100; ++f)
        frame(f, false);
    EXPECT_FALSE(tracker.bodies()[0].found());
    for (int f = 100; f < 110; ++f)
        frame(f, true);
    EXPECT_GT(tracker.counters().identityYields, 0u) << "the right body was met first";
}

TEST(ModelTracker, BoundsTheWorkOfAFloodOfSpuriousPoints) {
    const std::vector<Vec3> layout = test::irregularLayout(12, 51, 12.0);
    const MarkerModel model = completeModel(layout, 0, 4);
    ModelTrackingConfig config;
    config.searchBudget = 5000;
    ModelTracker tracker(std::span(&model, 1), config);

    // 250 points in a 10 cm cube: every distance a model has appears many times over.
    std::mt19937 random(61);
    std::uniform_real_distribution<double> volume(-50.0, 50.0);
    std::vector<Vec3> points;
    for (int i = 0; i < 250; ++i)
        points.push_back(Vec3(volume(random), volume(random), 600.0 + volume(random)));
    tracker.update(0.0, points);
    EXPECT_EQ(tracker.counters().budgetExhausted, 1u);
    EXPECT_GE(tracker.counters().searchesSkipped, 1u);

    // With the default budget the body is still found among 60 spurious points.
    ModelTracker roomy(std::span(&model, 1), ModelTrackingConfig{});
    const RigidTransform truth = pose(1.0, {1, 0, 1}, {0.0, 0.0, 600.0});
    points.clear();
    for (int i = 0; i < 60; ++i)
        points.push_back(Vec3(volume(random) * 2.0, volume(random) * 2.0, 600.0 + volume(random)));
    place(layout, truth, all, points);
    roomy.update(0.0, points);
    expectPose(roomy.bodies()[0], truth, 1e-6);
}

// A body whose points all lie about half a millimetre off its layout is matched whole by nearly
// every 4-clique of a search and refused by the RMS gate each time; the search refuses the
// cliques that match as a refused one without refitting (everything after the first matching
// follows from those matches). The same points under a wider gate are found.
TEST(ModelTracker, RefusesAtOnceCliquesThatMatchAsARefusedOne) {
    const std::vector<Vec3> layout = test::irregularLayout(12, 23, 12.0);
    const MarkerModel model = completeModel(layout, 0, 4);
    const std::vector<Vec3> points =
        placedOff(layout, pose(0.6, {1, -1, 2}, {10.0, 5.0, 580.0}), 0.5, 5);

    ModelTrackingConfig tight;
    tight.maxRms_mm = 0.3;
    ModelTracker tracker(std::span(&model, 1), tight);
    tracker.update(0.0, points);
    EXPECT_FALSE(tracker.bodies()[0].found());
    const ModelTrackingCounters& c = tracker.counters();
    EXPECT_GT(c.repeatedRefusals, 0u);
    EXPECT_LT(c.repeatedRefusals, c.hypotheses);

    ModelTrackingConfig wide;
    wide.maxRms_mm = 1.5;
    wide.rmsGateFloor_mm = 1.5;
    ModelTracker lenient(std::span(&model, 1), wide);
    lenient.update(0.0, points);
    ASSERT_TRUE(lenient.bodies()[0].found());
    EXPECT_EQ(lenient.bodies()[0].markers, 12u);
    EXPECT_EQ(lenient.counters().repeatedRefusals, 0u);
}

// A clique is the same hypothesis whichever of its points the search started from: four points
// a little off a four-marker layout (distances within the tolerance, fit above the gate) are
// one clique, looked at once, not once from each of its points.
TEST(ModelTracker, LooksAtEachCliqueOnceWhicheverPointItStartsFrom) {
    const std::vector<Vec3> layout = test::irregularLayout(4, 31, 12.0);
    const MarkerModel model = completeModel(layout, 0, 4);
    const std::vector<Vec3> points =
        placedOff(layout, pose(1.2, {2, 1, -1}, {-15.0, 20.0, 590.0}), 0.15, 3);

    ModelTrackingConfig tight;
    tight.maxRms_mm = 0.02;
    ModelTracker tracker(std::span(&model, 1), tight);
    tracker.update(0.0, points);
    EXPECT_FALSE(tracker.bodies()[0].found());
    EXPECT_EQ(tracker.counters().searches, 1u);
    EXPECT_EQ(tracker.counters().hypotheses, 1u);

    // Within the gate the same points are the body.
    ModelTracker lenient(std::span(&model, 1), ModelTrackingConfig{});
    lenient.update(0.0, points);
    ASSERT_TRUE(lenient.bodies()[0].found());
    EXPECT_EQ(lenient.bodies()[0].markers, 4u);
}

TEST(ModelTracker, CountsPointsBeyondCapacity) {
    const std::vector<Vec3> layout = test::irregularLayout(6, 71, 12.0);
    const MarkerModel model = completeModel(layout, 0, 4);
    ModelTrackingConfig config;
    config.maxPoints = 8;
    ModelTracker tracker(std::span(&model, 1), config);
    std::vector<Vec3> points;
    place(layout, pose(0.0, {0, 0, 1}, {0.0, 0.0, 500.0}), all, points);
    for (int i = 0; i < 5; ++i)
        points.push_back(Vec3(300.0 + 20.0 * i, 0.0, 500.0));
    tracker.update(0.0, points);
    EXPECT_EQ(tracker.counters().pointOverflow, 3u);
    EXPECT_TRUE(tracker.bodies()[0].found());
    EXPECT_EQ(tracker.pointOwners().size(), 8u);
}

TEST(ModelTracker, RefusesModelsAndSettingsItCannotHold) {
    const MarkerModel big = completeModel(test::irregularLayout(129, 81, 1.0), 0, 4);
    EXPECT_FALSE(ModelTracker(std::span(&big, 1), ModelTrackingConfig{}).isValid());
    const MarkerModel small = completeModel(test::irregularLayout(6, 82, 10.0), 0, 4);
    ModelTrackingConfig config;
    config.distanceTolerance_mm = 0.0;
    EXPECT_FALSE(ModelTracker(std::span(&small, 1), config).isValid());
    config = ModelTrackingConfig{};
    config.minTrackedMarkers = 2;
    EXPECT_FALSE(ModelTracker(std::span(&small, 1), config).isValid());
    // No models and no points: nothing to do, and nothing breaks.
    ModelTracker empty(std::span<const MarkerModel>{}, ModelTrackingConfig{});
    ASSERT_TRUE(empty.isValid());
    empty.update(0.0, {});
    EXPECT_TRUE(empty.bodies().empty());
}

TEST(ModelTracker, ForgetsHistoryOnReset) {
    const std::vector<Vec3> layout = test::irregularLayout(8, 91, 12.0);
    const MarkerModel model = completeModel(layout, 0, 4);
    ModelTracker tracker(std::span(&model, 1), ModelTrackingConfig{});
    std::vector<Vec3> points;
    place(layout, pose(0.0, {0, 0, 1}, {0.0, 0.0, 500.0}), all, points);
    tracker.update(0.0, points);
    tracker.reset();
    EXPECT_FALSE(tracker.bodies()[0].found());
    EXPECT_TRUE(std::isinf(tracker.bodies()[0].lastFound_s));
    tracker.update(0.01, points);
    EXPECT_EQ(tracker.bodies()[0].source, PoseSource::Searched);
}

TEST(ModelTracker, AllocatesNothingPerFrame) {
    const std::vector<Vec3> a = test::irregularLayout(30, 101, 10.0);
    const std::vector<Vec3> b = test::irregularLayout(30, 102, 10.0);
    const std::vector<MarkerModel> models =
        modelList(completeModel(a, 0, 4), completeModel(b, 1, 4));
    ModelTracker tracker(models, ModelTrackingConfig{});
    std::mt19937 random(103);
    std::uniform_real_distribution<double> volume(-200.0, 200.0);
    std::vector<Vec3> points;
    points.reserve(200);
    auto frame = [&](int f) {
        const double t = 0.01 * f;
        points.clear();
        // Each body hidden now and then, so that both prediction and search run.
        if (f % 50 < 45)
            place(
                a, pose(t, {0, 1, 0}, {-100.0, 0.0, 600.0}),
                [&](std::size_t i) { return a[i].z() > -10.0; }, points);
        if (f % 70 < 60)
            place(b, pose(-t, {1, 0, 0}, {100.0, 0.0, 600.0}), all, points);
        for (int i = 0; i < 10; ++i)
            points.push_back(Vec3(volume(random), volume(random), 600.0 + volume(random)));
        tracker.update(t, points);
    };
    for (int f = 0; f < 100; ++f)
        frame(f);
    const std::uint64_t allocations = test::countAllocations([&] {
        for (int f = 100; f < 1100; ++f)
            frame(f);
    });
    EXPECT_EQ(allocations, 0u);
    EXPECT_GT(tracker.counters().searchHits, 10u);
    EXPECT_GT(tracker.counters().predictedHits, 1500u);
}

} // namespace
} // namespace edgetrack
