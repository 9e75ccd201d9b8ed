// Tests of object calibration on synthetic rigid layouts moving apart, with occlusion and noise.
#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/object_calibrator.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack {
namespace {

std::vector<Vec3> irregularLayout(std::size_t count, unsigned seed) {
    return test::irregularLayout(count, seed, 15.0);
}

// Rig-from-object pose of a body turning about its own axis while drifting (mm, rad, s).
RigidTransform poseAt(double t_s, const Vec3& centre, const Vec3& axis, double rate_radps,
                      double phase) {
    RigidTransform pose;
    pose.rotation = Quat(Eigen::AngleAxisd(rate_radps * t_s + phase, axis.normalized()));
    pose.translation_mm = centre + Vec3(30.0 * std::sin(0.7 * t_s + phase),
                                        20.0 * std::cos(0.5 * t_s), 15.0 * std::sin(0.3 * t_s));
    return pose;
}

// Adds independent measurement noise to every point (mm).
void addNoise(std::vector<Vec3>& points, std::mt19937& random,
              std::normal_distribution<double>& noise) {
    for (Vec3& p : points)
        p += Vec3(noise(random), noise(random), noise(random));
}

std::vector<double> sortedDistances(std::span<const Vec3> points) {
    std::vector<double> d;
    for (std::size_t i = 0; i < points.size(); ++i)
        for (std::size_t j = i + 1; j < points.size(); ++j)
            d.push_back((points[i] - points[j]).norm());
    std::sort(d.begin(), d.end());
    return d;
}

// Same layout up to a rigid motion and marker order: every pairwise distance agrees.
bool sameShape(std::span<const Vec3> a, std::span<const Vec3> b, double tolerance_mm) {
    if (a.size() != b.size())
        return false;
    const std::vector<double> da = sortedDistances(a), db = sortedDistances(b);
    for (std::size_t i = 0; i < da.size(); ++i)
        if (std::abs(da[i] - db[i]) > tolerance_mm)
            return false;
    return true;
}

// For failure messages: each model's size and how close it is to each true layout.
std::string describe(std::span<const MarkerModel> models, const std::vector<Vec3> (&layouts)[2]) {
    std::string text;
    for (const MarkerModel& m : models) {
        text += "\n  model of " + std::to_string(m.markers_model_mm.size()) + " markers";
        for (int k = 0; k < 2; ++k)
            text += sameShape(m.markers_model_mm.span(), layouts[k], 0.2)
                        ? ", same shape as body " + std::to_string(k)
                        : "";
    }
    return text;
}

class TwoBodies : public ::testing::Test {
protected:
    // Markers of body k visible at time t: a body hides the markers on its far side, as an
    // object's own surface does, when `selfOcclusion` is set.
    void frame(double t_s, bool selfOcclusion, std::vector<Vec3>& points) {
        points.clear();
        for (std::size_t k = 0; k < 2; ++k) {
            const RigidTransform pose = bodyPose(k, t_s);
            for (const Vec3& m : layouts[k]) {
                const Vec3 p = pose.apply(m);
                // Facing away from the cameras (at the rig origin): hidden behind the body.
                if (selfOcclusion && (p - pose.translation_mm).dot(-p.normalized()) < -15.0)
                    continue;
                points.push_back(p + Vec3(noise(random), noise(random), noise(random)));
            }
        }
        std::shuffle(points.begin(), points.end(), random);
    }

    // Rig-from-object pose of body k at time t.
    static RigidTransform bodyPose(std::size_t k, double t_s) {
        return k == 0 ? poseAt(t_s, {-60.0, 0.0, 550.0}, {0.2, 1.0, 0.1}, 0.8, 0.0)
                      : poseAt(t_s, {70.0, 10.0, 560.0}, {1.0, 0.3, -0.2}, -0.6, 1.3);
    }

    // The points of a frame at time t that belong to body 0 (within 80 mm of its centre).
    static void keepBodyZero(double t_s, const std::vector<Vec3>& points, std::vector<Vec3>& out) {
        out.clear();
        const Vec3 centre = bodyPose(0, t_s).translation_mm;
        for (const Vec3& p : points)
            if ((p - centre).norm() < 80.0)
                out.push_back(p);
    }

    // The models the calibrator exports now (room for four).
    static std::vector<MarkerModel> exported(const ObjectCalibrator& calibrator,
                                             const CalibrationConfig& config) {
        std::vector<MarkerModel> models;
        for (int i = 0; i < 4; ++i)
            models.emplace_back(config.maxMarkersPerObject);
        models.resize(calibrator.exportModels(models));
        return models;
    }

    // Exports the models and checks there is exactly one of each body's shape; returns them.
    std::vector<MarkerModel> expectOneModelPerBody(const ObjectCalibrator& calibrator,
                                                   const CalibrationConfig& config) {
        std::vector<MarkerModel> models = exported(calibrator, config);
        EXPECT_EQ(models.size(), 2u) << describe(models, layouts);
        for (int k = 0; k < 2; ++k)
            EXPECT_EQ(std::count_if(models.begin(), models.end(),
                                    [&](const MarkerModel& m) {
                                        return sameShape(m.markers_model_mm.span(), layouts[k],
                                                         0.2);
                                    }),
                      1)
                << "body " << k << describe(models, layouts);
        return models;
    }

    std::vector<Vec3> layouts[2] = {irregularLayout(12, 1), irregularLayout(10, 2)};
    std::mt19937 random{42};
    std::normal_distribution<double> noise{0.0, 0.05};
};

TEST_F(TwoBodies, LearnsTwoRigidObjectsThatMoveApart) {
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    ASSERT_TRUE(calibrator.isValid());
    std::vector<Vec3> points;
    for (int f = 0; f < 1500; ++f) {
        frame(f / 100.0, false, points);
        calibrator.update(f / 100.0, points);
    }
    const std::vector<MarkerModel> models = expectOneModelPerBody(calibrator, config);
    EXPECT_GT(calibrator.counters().splits, 0u);
    for (std::size_t i = 0; i < models.size(); ++i) {
        // All markers seen together: every pair is an edge.
        const std::size_t n = models[i].markers_model_mm.size();
        EXPECT_EQ(models[i].edges.size(), n * (n - 1) / 2);
        EXPECT_GE(models[i].sMin, 4u);
    }
}

TEST_F(TwoBodies, OccludedMarkersAreRecognisedWhenTheyReappear) {
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points;
    for (int f = 0; f < 3000; ++f) {
        frame(f / 100.0, true, points);
        calibrator.update(f / 100.0, points);
    }
    const std::vector<MarkerModel> models = expectOneModelPerBody(calibrator, config);
    EXPECT_GT(calibrator.counters().markersReappeared, 20u);
}

TEST_F(TwoBodies, ShortLivedReflectionsDoNotBecomeMarkers) {
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points;
    std::uniform_real_distribution<double> place(-100.0, 100.0);
    Vec3 glint = Vec3::Zero();
    for (int f = 0; f < 1500; ++f) {
        frame(f / 100.0, false, points);
        // A glint appears for three frames every half second, somewhere new each time.
        if (f % 50 == 0)
            glint = Vec3(place(random), place(random), 550.0 + place(random));
        if (f % 50 < 3)
            points.push_back(glint);
        calibrator.update(f / 100.0, points);
    }
    EXPECT_GT(calibrator.counters().invalidRemoved, 20u);
    const std::vector<MarkerModel> models = exported(calibrator, config);
    ASSERT_EQ(models.size(), 2u) << describe(models, layouts);
    std::size_t total = 0;
    for (const MarkerModel& model : models)
        total += model.markers_model_mm.size();
    EXPECT_EQ(total, 22u);
}

TEST_F(TwoBodies, NoHeapAllocationPerFrameAfterWarmUp) {
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<std::vector<Vec3>> frames(1200);
    for (std::size_t f = 0; f < frames.size(); ++f)
        frame(static_cast<double>(f) / 100.0, true, frames[f]);
    for (std::size_t f = 0; f < 200; ++f)
        calibrator.update(static_cast<double>(f) / 100.0, frames[f]);
    const std::uint64_t allocations = test::countAllocations([&] {
        for (std::size_t f = 200; f < frames.size(); ++f)
            calibrator.update(static_cast<double>(f) / 100.0, frames[f]);
    });
    EXPECT_EQ(allocations, 0u);
    EXPECT_EQ(calibrator.counters().frames, 1200u);

    // Exporting (S_min included) works in storage sized at construction too.
    std::vector<MarkerModel> models;
    for (std::size_t i = 0; i < config.maxObjects; ++i)
        models.emplace_back(config.maxMarkersPerObject);
    std::size_t exported = 0;
    EXPECT_EQ(test::countAllocations([&] { exported = calibrator.exportModels(models); }), 0u);
    EXPECT_EQ(exported, 2u);

    // The layouts alone (a progress view's export): the same markers and edges, S_min not
    // computed, and no allocation either.
    std::vector<MarkerModel> layoutsOnly;
    for (std::size_t i = 0; i < config.maxObjects; ++i)
        layoutsOnly.emplace_back(config.maxMarkersPerObject);
    std::size_t exportedLayouts = 0;
    EXPECT_EQ(
        test::countAllocations([&] { exportedLayouts = calibrator.exportLayouts(layoutsOnly); }),
        0u);
    ASSERT_EQ(exportedLayouts, exported);
    for (std::size_t m = 0; m < exported; ++m) {
        EXPECT_EQ(layoutsOnly[m].sMin, 4u);
        ASSERT_EQ(layoutsOnly[m].markers_model_mm.size(), models[m].markers_model_mm.size());
        for (std::size_t k = 0; k < models[m].markers_model_mm.size(); ++k)
            EXPECT_EQ(layoutsOnly[m].markers_model_mm[k], models[m].markers_model_mm[k]);
        ASSERT_EQ(layoutsOnly[m].edges.size(), models[m].edges.size());
        for (std::size_t e = 0; e < models[m].edges.size(); ++e) {
            EXPECT_EQ(layoutsOnly[m].edges[e].from, models[m].edges[e].from);
            EXPECT_EQ(layoutsOnly[m].edges[e].to, models[m].edges[e].to);
        }
    }
}

TEST_F(TwoBodies, ABodyTakenOutAndBroughtBackIsFoundAgain) {
    // The paper's future work: the user takes the object out of view (or pauses) for two
    // seconds; when it is back, its markers must rejoin the model instead of starting a new one.
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points, first;
    for (int f = 0; f < 3000; ++f) {
        frame(f / 100.0, true, points);
        keepBodyZero(f / 100.0, points, first);
        const bool away = f >= 900 && f < 1100;
        calibrator.update(f / 100.0, away ? std::span<const Vec3>() : std::span<const Vec3>(first));
    }
    const std::vector<MarkerModel> models = exported(calibrator, config);
    ASSERT_EQ(models.size(), 1u) << describe(models, layouts);
    EXPECT_TRUE(sameShape(models[0].markers_model_mm.span(), layouts[0], 0.2))
        << describe(models, layouts);
    EXPECT_GT(calibrator.counters().refound + calibrator.counters().merged, 0u);
}

// A body of 60 markers taken out of view for two seconds and brought back: the search for its
// layout among the points finishes within its step budget and finds it. (Scanning every member
// for each triangle's third corner, as the search first did, ran out of steps here.)
TEST(ObjectCalibrator, ALargeBodyBroughtBackIsFoundWithinTheSearchBudget) {
    const std::vector<Vec3> layout = irregularLayout(60, 5);
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::mt19937 random{7};
    std::normal_distribution<double> noise{0.0, 0.05};
    std::vector<Vec3> points;
    for (int f = 0; f < 2000; ++f) {
        const double t_s = f / 100.0;
        points.clear();
        if (f < 900 || f >= 1100) {
            const RigidTransform pose =
                poseAt(t_s, Vec3(0.0, 0.0, 600.0), Vec3(0.3, 1.0, 0.2), 0.5, 0.0);
            for (const Vec3& m : layout)
                points.push_back(pose.apply(m));
            addNoise(points, random, noise);
        }
        calibrator.update(t_s, points);
    }
    EXPECT_EQ(calibrator.counters().refindBudgetExhausted, 0u);
    EXPECT_GT(calibrator.counters().refound + calibrator.counters().merged, 0u);
    std::vector<MarkerModel> models;
    for (int i = 0; i < 4; ++i)
        models.emplace_back(config.maxMarkersPerObject);
    models.resize(calibrator.exportLayouts(models)); // S_min of 60 markers takes seconds
    ASSERT_EQ(models.size(), 1u);
    EXPECT_TRUE(sameShape(models[0].markers_model_mm.span(), layout, 0.2));
}

TEST_F(TwoBodies, IdenticalBodiesSeenApartStayTwoWhenOneLeaves) {
    // Two bodies with one layout, seen side by side; then one leaves for good. The lost one fits
    // the other's layout exactly, but having been seen apart they are two objects, not one body
    // that came back.
    layouts[1] = layouts[0];
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points, staying;
    for (int f = 0; f < 3000; ++f) {
        frame(f / 100.0, true, points);
        if (f >= 1500) {
            keepBodyZero(f / 100.0, points, staying);
            points.swap(staying);
        }
        calibrator.update(f / 100.0, points);
    }
    const std::vector<MarkerModel> models = exported(calibrator, config);
    ASSERT_EQ(models.size(), 2u) << describe(models, layouts);
    for (const MarkerModel& model : models)
        EXPECT_TRUE(sameShape(model.markers_model_mm.span(), layouts[0], 0.2))
            << describe(models, layouts);
}

TEST(ObjectCalibrator, NewMarkersOfAPassingBodyDoNotDragThePose) {
    // A learnt body (8 markers, established) is joined by 5 markers of another body that moves
    // with it and drifts away at 4 mm/s: until they could be established they stay within the
    // pose threshold of where they joined. The pose must come from the established markers
    // alone; in a fit of all agreeing markers they pull it by about 5/13 of their drift, and every
    // marker placed through that pose is learnt that far out of place.
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    ASSERT_TRUE(calibrator.isValid());
    const std::vector<Vec3> body = test::irregularLayout(8, 3, 15.0);
    const std::vector<Vec3> passing = test::irregularLayout(5, 4, 15.0);
    std::mt19937 random(7);
    std::normal_distribution<double> noise(0.0, 0.02);
    std::vector<Vec3> points;
    std::vector<CalibrationObjectView> views(config.maxObjects);
    double worstResidual_mm = 0.0;
    std::size_t framesChecked = 0;
    for (int f = 0; f < 400; ++f) {
        const double t_s = f / 100.0;
        const RigidTransform pose = poseAt(t_s, {0.0, 0.0, 550.0}, {0.2, 1.0, 0.1}, 0.8, 0.0);
        points.clear();
        for (const Vec3& m : body)
            points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        if (t_s >= 1.0) {
            const Vec3 drift_mm(4.0 * (t_s - 1.0), 0.0, 0.0);
            for (const Vec3& m : passing)
                points.push_back(pose.apply(m + Vec3(100.0, 0.0, 0.0) + drift_mm) +
                                 Vec3(noise(random), noise(random), noise(random)));
        }
        calibrator.update(t_s, points);
        // Until the passing markers have been inliers long enough to be established.
        if (f < 100 || f >= 100 + static_cast<int>(config.minModelFrames))
            continue;
        // The body's markers against the object's pose: its established members, seen.
        const std::size_t count = calibrator.objectViews(views);
        for (std::size_t i = 0; i < count; ++i) {
            if (!views[i].posed)
                continue;
            calibrator.forEachMember([&](const ObjectCalibrator::MemberView& v) {
                if (v.objectId != views[i].id || !v.visible || !v.established)
                    return;
                const double residual =
                    (views[i].T_rig_from_object.apply(v.model_mm) - v.position_rig_mm).norm();
                worstResidual_mm = std::max(worstResidual_mm, residual);
            });
            ++framesChecked;
        }
    }
    EXPECT_GE(framesChecked, 25u);
    EXPECT_LT(worstResidual_mm, 0.15);
}

// A marker on a body's surface (mm and unit normal, body frame): the cameras see it only from
// within about 78 degrees of its normal, as the simulated board's markers.
struct SurfaceMarker {
    Vec3 position_mm;
    Vec3 normal;
};

// The markers of \a body in view of cameras at the rig's origin under \a pose (rig, mm).
void visibleMarkers(std::span<const SurfaceMarker> body, const RigidTransform& pose,
                    std::vector<Vec3>& points) {
    for (const SurfaceMarker& m : body) {
        const Vec3 p = pose.apply(m.position_mm);
        if ((pose.rotation * m.normal).dot(-p.normalized()) > 0.2)
            points.push_back(p);
    }
}

TEST(ObjectCalibrator, AFaceTurnedAwayKeepsItsMarkers) {
    // A box with five markers on its top face, five on its side and two on the edge between
    // them. The top is seen for 0.6 s, then turned away for 9 s while the side and the edge stay
    // in view. The top's markers are not stale: they face away. Counted as expected whenever
    // markers seen with them are seen, they were missed in over 95% of those frames and removed
    // as stale (hand_occlusion seed 36 lost five markers of its cube so).
    constexpr double kPi = std::numbers::pi;
    const Vec3 top(0.0, 0.0, 1.0), side(1.0, 0.0, 0.0), edge = Vec3(1.0, 0.0, 1.0).normalized();
    const std::vector<SurfaceMarker> box = {
        {{-22.0, -18.0, 35.0}, top}, {{15.0, -25.0, 35.0}, top},  {{25.0, 12.0, 35.0}, top},
        {{-10.0, 22.0, 35.0}, top},  {{3.0, 0.0, 35.0}, top},     {{35.0, -20.0, -15.0}, side},
        {{35.0, 18.0, -22.0}, side}, {{35.0, 24.0, 10.0}, side},  {{35.0, -5.0, 20.0}, side},
        {{35.0, 2.0, -2.0}, side},   {{33.0, -10.0, 33.0}, edge}, {{33.0, 15.0, 33.0}, edge}};
    std::vector<Vec3> layout;
    for (const SurfaceMarker& m : box)
        layout.push_back(m.position_mm);
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::mt19937 random(11);
    std::normal_distribution<double> noise(0.0, 0.05);
    std::vector<Vec3> points;
    for (int f = 0; f < 1000; ++f) {
        const double t_s = f / 100.0;
        // About the y axis: at 0.75 pi the top and the side face the cameras at 45 degrees each;
        // from 0.3 s to 0.8 s the box turns to 0.45 pi and then stays between 0.4 and 0.45 pi,
        // where only the side and the edge do.
        const double yaw = t_s < 0.3   ? 0.75 * kPi + 0.05 * kPi * std::sin(2.0 * kPi * t_s / 0.3)
                           : t_s < 0.8 ? 0.75 * kPi - 0.3 * kPi * (t_s - 0.3) / 0.5
                                       : 0.425 * kPi + 0.025 * kPi * std::cos(1.3 * (t_s - 0.8));
        RigidTransform pose;
        pose.rotation = Quat(Eigen::AngleAxisd(yaw, Vec3::UnitY()) *
                             Eigen::AngleAxisd(0.2 * std::sin(0.9 * t_s), Vec3::UnitX()));
        pose.translation_mm = Vec3(10.0 * std::sin(0.7 * t_s), 5.0 * std::cos(0.5 * t_s), 550.0);
        points.clear();
        visibleMarkers(box, pose, points);
        addNoise(points, random, noise);
        calibrator.update(t_s, points);
    }
    std::vector<MarkerModel> models;
    models.emplace_back(config.maxMarkersPerObject);
    models.emplace_back(config.maxMarkersPerObject);
    models.resize(calibrator.exportModels(models));
    ASSERT_EQ(models.size(), 1u);
    EXPECT_EQ(models[0].markers_model_mm.size(), box.size());
    EXPECT_TRUE(sameShape(models[0].markers_model_mm.span(), layout, 0.2));
    EXPECT_EQ(calibrator.counters().ghostsRemoved, 0u);
}

// Body A's pose (rig frame, mm) in the tests of two bodies that move apart.
RigidTransform poseOfA(double t_s) {
    return poseAt(t_s, {-50.0, 0.0, 560.0}, {0.2, 1.0, 0.1}, 0.6, 0.0);
}

// Body B slides away from A from 1.5 s on: its pose in A's frame (mm).
RigidTransform slideAwayFromA(double t_s) {
    const double apart_s = std::max(0.0, t_s - 1.5);
    RigidTransform relative;
    relative.translation_mm = Vec3(12.0 * apart_s, -8.0 * apart_s, 0.0);
    return relative;
}

// How body B moves away from body A in twoBodiesWithAHiddenMarker, from 1.5 s on.
enum class Parting { Slide, Turn };
// Which marker twoBodiesWithAHiddenMarker hides from 1.0 s on: one of B's for good, or one of
// A's until 4.0 s.
enum class Hidden { OfBForGood, OfAUntil4s };
constexpr std::size_t kHiddenOfA = 3, kHiddenOfB = 2;

struct TwoBodiesResult {
    std::vector<MarkerModel> models;
    /// Exported at 3.9 s, before a marker hidden until 4.0 s is seen again.
    std::vector<MarkerModel> modelsWhileHidden;
    CalibrationCounters counters;
    std::vector<Vec3> bodyA;
};

std::vector<MarkerModel> exportFrom(const ObjectCalibrator& calibrator,
                                    const CalibrationConfig& config) {
    std::vector<MarkerModel> models;
    for (int i = 0; i < 4; ++i)
        models.emplace_back(config.maxMarkersPerObject);
    models.resize(calibrator.exportModels(models));
    return models;
}

// Bodies A (8 markers) and B (5) move as one for 1.5 s, so that all 13 are established in one
// object; one marker is hidden from 1.0 s on. Then B moves away. The hidden marker's place is
// predicted through the object's pose, which follows A, so its edges to B's markers break and
// it clusters with A; it may as well be on A as on B. One of B's must not be exported as a
// marker of A (three_cubes seed 31: three markers of one cube in another's model); one of A's
// must be once it is seen again.
TwoBodiesResult twoBodiesWithAHiddenMarker(Parting parting, Hidden hidden) {
    TwoBodiesResult result;
    result.bodyA = test::irregularLayout(8, 5, 15.0);
    std::vector<Vec3> bodyB = test::irregularLayout(5, 6, 15.0);
    const Vec3 centreOfB_mm(110.0, 0.0, 0.0);
    for (Vec3& p : bodyB)
        p += centreOfB_mm;
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::mt19937 random(3);
    std::normal_distribution<double> noise(0.0, 0.05);
    std::vector<Vec3> points;
    for (int f = 0; f < 600; ++f) {
        const double t_s = f / 100.0;
        const RigidTransform pose = poseOfA(t_s);
        // B's motion in A's frame.
        RigidTransform relative = slideAwayFromA(t_s);
        if (parting == Parting::Turn) {
            const double apart_s = std::max(0.0, t_s - 1.5);
            // A turn about one of B's markers while B is carried off ever faster: no marker of
            // B stays near the turn's axis, so none moves with A for long.
            const Vec3& pivot_mm = bodyB[0];
            relative.rotation =
                Quat(Eigen::AngleAxisd(0.3 * apart_s, Vec3(0.3, 0.2, 1.0).normalized()));
            relative.translation_mm = pivot_mm - relative.rotation * pivot_mm +
                                      apart_s * apart_s * Vec3(16.0, -10.0, 0.0);
        }
        const bool hiding = t_s >= 1.0 && (hidden == Hidden::OfBForGood || t_s < 4.0);
        points.clear();
        for (std::size_t i = 0; i < result.bodyA.size(); ++i)
            if (!(hiding && hidden == Hidden::OfAUntil4s && i == kHiddenOfA))
                points.push_back(pose.apply(result.bodyA[i]));
        for (std::size_t i = 0; i < bodyB.size(); ++i)
            if (!(hiding && hidden == Hidden::OfBForGood && i == kHiddenOfB))
                points.push_back(pose.apply(relative.apply(bodyB[i])));
        addNoise(points, random, noise);
        calibrator.update(t_s, points);
        if (f == 390)
            result.modelsWhileHidden = exportFrom(calibrator, config);
    }
    result.models = exportFrom(calibrator, config);
    result.counters = calibrator.counters();
    return result;
}

std::size_t countOfShape(std::span<const MarkerModel> models, std::span<const Vec3> layout) {
    return static_cast<std::size_t>(
        std::count_if(models.begin(), models.end(), [&](const MarkerModel& m) {
            return sameShape(m.markers_model_mm.span(), layout, 0.2);
        }));
}

void expectOneModelOfAAndNoLargerModel(const TwoBodiesResult& result) {
    EXPECT_EQ(countOfShape(result.models, result.bodyA), 1u);
    for (const MarkerModel& m : result.models)
        EXPECT_LE(m.markers_model_mm.size(), result.bodyA.size());
}

TEST(ObjectCalibrator, AMarkerHiddenWhileTwoBodiesMovedApartIsInNeitherModel) {
    // A slide: all of B's markers drift from A's pose alike and B leaves as one cluster.
    const TwoBodiesResult result = twoBodiesWithAHiddenMarker(Parting::Slide, Hidden::OfBForGood);
    EXPECT_GT(result.counters.splits, 0u);
    expectOneModelOfAAndNoLargerModel(result);
}

TEST(ObjectCalibrator, AMarkerHiddenWhileABodyTurnedAwayIsInNeitherModel) {
    // A turn: B's far markers drift from A's pose first, and their drift breaks B's own edges to
    // its near markers, which still agree with the pose. B leaves one marker at a time, as
    // members of no cluster, never as a part of a split; its hidden marker must not end in A's
    // model all the same.
    const TwoBodiesResult result = twoBodiesWithAHiddenMarker(Parting::Turn, Hidden::OfBForGood);
    EXPECT_EQ(result.counters.splits, 0u);
    expectOneModelOfAAndNoLargerModel(result);
}

TEST(ObjectCalibrator, AMarkerHiddenWhileABodyTurnedAwayCountsOnceSeenAgain) {
    // The same turn with a marker of A hidden: which body it is on is as unknown, so A's model
    // leaves it out while it is hidden, and takes it as soon as it is seen where A's pose puts it.
    const TwoBodiesResult result = twoBodiesWithAHiddenMarker(Parting::Turn, Hidden::OfAUntil4s);
    std::vector<Vec3> bodyAWithoutHidden = result.bodyA;
    bodyAWithoutHidden.erase(bodyAWithoutHidden.begin() + kHiddenOfA);
    EXPECT_EQ(countOfShape(result.modelsWhileHidden, bodyAWithoutHidden), 1u);
    expectOneModelOfAAndNoLargerModel(result);
}

TEST(ObjectCalibrator, MarkersSeenOnlyBrieflyDoNotHoldTwoBodiesTogether) {
    // Bodies A (8 markers) and B (6) move as one for 1.5 s, then B slides away. Four more markers
    // of B, near A, are seen only from 0.5 to 0.7 s: too short to be established, so no pose
    // predicts where they are once hidden, and their edges to both bodies, never measured again,
    // hold. Four of them form pyramids with A's markers and with B's that share their triangles:
    // left in the clustering, they would chain the two bodies into one cluster for good
    // (cube_sphere seed 33: the sphere never split from the cube's object, which filled up).
    const std::vector<Vec3> bodyA = test::irregularLayout(8, 5, 15.0);
    std::vector<Vec3> bodyB = test::irregularLayout(6, 6, 15.0);
    for (Vec3& p : bodyB)
        p += Vec3(110.0, 0.0, 0.0);
    std::vector<Vec3> briefOfB = test::irregularLayout(4, 9, 10.0);
    for (Vec3& p : briefOfB)
        p += Vec3(55.0, 0.0, 0.0);
    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::mt19937 random(3);
    std::normal_distribution<double> noise(0.0, 0.05);
    std::vector<Vec3> points;
    for (int f = 0; f < 800; ++f) {
        const double t_s = f / 100.0;
        const RigidTransform pose = poseOfA(t_s);
        const RigidTransform relative = slideAwayFromA(t_s);
        points.clear();
        for (const Vec3& m : bodyA)
            points.push_back(pose.apply(m));
        for (const Vec3& m : bodyB)
            points.push_back(pose.apply(relative.apply(m)));
        if (t_s >= 0.5 && t_s < 0.7)
            for (const Vec3& m : briefOfB)
                points.push_back(pose.apply(relative.apply(m)));
        addNoise(points, random, noise);
        calibrator.update(t_s, points);
    }
    const std::vector<MarkerModel> models = exportFrom(calibrator, config);
    EXPECT_EQ(countOfShape(models, bodyA), 1u);
    EXPECT_EQ(countOfShape(models, bodyB), 1u);
    EXPECT_EQ(models.size(), 2u);
}

TEST(ObjectCalibrator, RefusesMoreMarkersPerObjectThanItsSetsHold) {
    CalibrationConfig config;
    config.maxMarkersPerObject = MarkerSet::kCapacity + 1;
    ObjectCalibrator calibrator(config);
    EXPECT_FALSE(calibrator.isValid());
    const Vec3 p(0.0, 0.0, 500.0);
    calibrator.update(0.0, std::span(&p, 1)); // harmless when invalid
    EXPECT_EQ(calibrator.objectCount(), 0u);
}

TEST(ObjectCalibrator, MarkersBeyondCapacityAreCountedNotStored) {
    CalibrationConfig config;
    config.maxMarkers = 120;
    config.maxMarkersPerObject = 100;
    ObjectCalibrator calibrator(config);
    ASSERT_TRUE(calibrator.isValid());
    std::vector<Vec3> points;
    for (int i = 0; i < 150; ++i)
        points.emplace_back(20.0 * (i % 10), 20.0 * (i / 10), 600.0);
    calibrator.update(0.0, points);
    EXPECT_EQ(calibrator.counters().markerOverflow, 30u);
    EXPECT_EQ(calibrator.counters().memberOverflow, 20u);
}

} // namespace
} // namespace edgetrack
