// Tests of how a field calibration's learnt models join the models on the board.
#include <algorithm>
#include <random>

#include <gtest/gtest.h>

#include "core/session_buffer.hpp"
#include "firmware_app/firmware/known_in_session.hpp"
#include "firmware_app/firmware/model_merge.hpp"
#include "hal/sim/scene.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack::app {
namespace {

std::vector<Vec3> layoutOf(const sim::MarkerObject& object, std::size_t count = SIZE_MAX) {
    std::vector<Vec3> layout;
    for (const sim::SimMarker& m : object.markers)
        if (layout.size() < count)
            layout.push_back(m.position_object_mm);
    return layout;
}

/// A layout that is no part of a cube: points scattered in a 300 mm box.
std::vector<Vec3> scattered(std::size_t count, unsigned seed) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> u(-150.0, 150.0);
    std::vector<Vec3> layout;
    for (std::size_t i = 0; i < count; ++i)
        layout.push_back(Vec3(u(random), u(random), u(random)));
    return layout;
}

NamedModel known(const std::vector<Vec3>& layout, std::uint32_t id, const char* name) {
    return {test::fullyConnectedModel(layout, id), name};
}

std::vector<MarkerModel> learnt(std::initializer_list<std::vector<Vec3>> layouts) {
    std::vector<MarkerModel> models;
    std::uint32_t id = 100;
    for (const std::vector<Vec3>& layout : layouts)
        models.push_back(test::fullyConnectedModel(layout, id++));
    return models;
}

const SminConfig kShape{};

TEST(ModelMerge, NewObjectsTakeTheLowestFreeIds) {
    const std::vector<MarkerModel> l =
        learnt({layoutOf(sim::makeCube70()), layoutOf(sim::makeCube50())});
    const MergedModels m = mergeLearntModels({}, l, {}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 2u);
    EXPECT_EQ(m.added, 2u);
    EXPECT_EQ(m.models[0].model.id, 0u);
    EXPECT_EQ(m.models[1].model.id, 1u);
    EXPECT_EQ(m.models[1].name, "body 1");
    EXPECT_GE(m.models[0].model.sMin, 4u);
}

TEST(ModelMerge, ARecalibratedBodyKeepsItsIdAndNameAndOthersStay) {
    std::vector<NamedModel> k;
    k.push_back(known(layoutOf(sim::makeCube70()), 5, "big cube"));
    k.push_back(known(layoutOf(sim::makeCube50()), 2, "small cube"));
    const std::vector<MarkerModel> l = learnt({layoutOf(sim::makeCube50()), scattered(6, 1)});
    const MergedModels m = mergeLearntModels(k, l, {}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 3u);
    EXPECT_EQ(m.updated, 1u);
    EXPECT_EQ(m.added, 1u);
    EXPECT_EQ(m.models[0].model.id, 5u);
    EXPECT_EQ(m.models[0].name, "big cube");
    EXPECT_EQ(m.models[1].model.id, 2u);
    EXPECT_EQ(m.models[1].name, "small cube");
    EXPECT_EQ(m.models[1].model.markers_model_mm.size(), 24u);
    EXPECT_EQ(m.models[2].model.id, 0u) << "the lowest id not in use";
    EXPECT_EQ(m.models[2].model.markers_model_mm.size(), 6u);
    // Which learnt model each is, for what the session measured of it.
    EXPECT_EQ(m.learntIndex, (std::vector<int>{-1, 0, 1}));
}

TEST(ModelMerge, AFragmentOfALearntOrKnownBodyIsDropped) {
    const std::vector<Vec3> cube = layoutOf(sim::makeCube70());
    const std::vector<Vec3> piece = layoutOf(sim::makeCube70(), 6);
    MergedModels m =
        mergeLearntModels({}, learnt({cube, piece}), {}, 16, kShape, kShape.tolerance_mm);
    EXPECT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.fragments, 1u);
    EXPECT_EQ(m.models[0].model.markers_model_mm.size(), 30u);
    EXPECT_EQ(m.learntIndex, (std::vector<int>{0}));

    // A glimpse of a known body must not replace the whole body's model.
    std::vector<NamedModel> k;
    k.push_back(known(cube, 3, "cube"));
    m = mergeLearntModels(k, learnt({piece}), {}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.fragments, 1u);
    EXPECT_EQ(m.updated, 0u);
    EXPECT_EQ(m.models[0].model.markers_model_mm.size(), 30u);
}

TEST(ModelMerge, CopiesOfOneLayoutAreKeptAndMarkedAsCopies) {
    const std::vector<Vec3> cube = layoutOf(sim::makeCube70());
    const MergedModels m =
        mergeLearntModels({}, learnt({cube, cube}), {}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 2u);
    EXPECT_EQ(m.fragments, 0u);
    EXPECT_EQ(m.models[0].model.sameShapeAs, 1);
    EXPECT_EQ(m.models[1].model.sameShapeAs, 0);
}

TEST(ModelMerge, WhatDoesNotFitMaxModelsIsRefusedAndCounted) {
    std::vector<NamedModel> k;
    k.push_back(known(layoutOf(sim::makeCube70()), 0, "a"));
    const MergedModels m = mergeLearntModels(k, learnt({scattered(6, 2), scattered(7, 3)}), {}, 2,
                                             kShape, kShape.tolerance_mm);
    EXPECT_EQ(m.models.size(), 2u);
    EXPECT_EQ(m.added, 1u);
    EXPECT_EQ(m.refused, 1u);
}

/// \a layout (mm) in another frame: how a new calibration may express the same object.
std::vector<Vec3> moved(const std::vector<Vec3>& layout, const RigidTransform& T) {
    std::vector<Vec3> out;
    for (const Vec3& p : layout)
        out.push_back(T.apply(p));
    return out;
}

const RigidTransform kOtherFrame{Quat(Eigen::AngleAxisd(1.15, Vec3(0.3, -0.8, 0.5).normalized())),
                                 Vec3(2.0, -31.0, 7.5)};

/// Whether every marker of \a model lies within \a tolerance_mm of one of \a layout's.
bool onLayout(const MarkerModel& model, const std::vector<Vec3>& layout, double tolerance_mm) {
    for (const Vec3& m : model.markers_model_mm)
        if (std::none_of(layout.begin(), layout.end(),
                         [&](const Vec3& p) { return (p - m).norm() <= tolerance_mm; }))
            return false;
    return true;
}

TEST(ModelMerge, ARelearntBodyKeepsTheFrameOfItsModelFromBefore) {
    // A host fixed a virtual object to body 2's frame: learnt again (the new layout comes in a
    // frame of its own, turned by 66 degrees, with noise), its markers stay where they were.
    const std::vector<Vec3> layout = test::irregularLayout(9, 17, 12.0);
    std::vector<NamedModel> k;
    k.push_back(known(layout, 2, "wand"));
    std::vector<Vec3> noisy = moved(layout, kOtherFrame);
    std::mt19937 random(4);
    std::normal_distribution<double> noise(0.0, 0.03);
    for (Vec3& p : noisy)
        p += Vec3(noise(random), noise(random), noise(random));
    const MergedModels m =
        mergeLearntModels(k, learnt({noisy}), {}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.updated, 1u);
    EXPECT_EQ(m.models[0].model.id, 2u);
    EXPECT_TRUE(onLayout(m.models[0].model, layout, 0.15)) << "the frame from before";
    EXPECT_FALSE(onLayout(m.models[0].model, noisy, 0.15));
}

TEST(ModelMerge, TiedByPositionIdenticalObjectsKeepTheirOwnIds) {
    // Two identical objects: only where they were in the session says which learnt model is
    // which body; shape alone would give the first learnt one the first id.
    const std::vector<Vec3> layout = test::irregularLayout(8, 5, 12.0);
    std::vector<NamedModel> k;
    k.push_back(known(layout, 4, "left"));
    k.push_back(known(layout, 7, "right"));
    const std::vector<Vec3> a = moved(layout, kOtherFrame);
    const std::vector<Vec3> b = moved(layout, kOtherFrame.inverse());
    const SameObject ties[2] = {{1, 0, kOtherFrame.inverse(), 8}, {0, 1, kOtherFrame, 8}};
    const MergedModels m =
        mergeLearntModels(k, learnt({a, b}), ties, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 2u);
    EXPECT_EQ(m.updated, 2u);
    EXPECT_EQ(m.added, 0u);
    EXPECT_EQ(m.learntIndex, (std::vector<int>{1, 0}));
    EXPECT_EQ(m.models[0].model.id, 4u);
    EXPECT_EQ(m.models[1].model.id, 7u);
    EXPECT_TRUE(onLayout(m.models[0].model, layout, 1e-6));
    EXPECT_TRUE(onLayout(m.models[1].model, layout, 1e-6));
}

TEST(ModelMerge, ALayoutThatWouldTrackWorseLeavesTheModelFromBefore) {
    // The body was in view, but the session learnt 26 of its 30 markers: fewer markers find it
    // in fewer views. Nor is it a new body.
    const std::vector<Vec3> cube = layoutOf(sim::makeCube70());
    std::vector<NamedModel> k;
    k.push_back(known(cube, 3, "cube"));
    const std::vector<Vec3> part = moved(layoutOf(sim::makeCube70(), 26), kOtherFrame);
    const SameObject tie{0, 0, kOtherFrame.inverse(), 20};
    MergedModels m =
        mergeLearntModels(k, learnt({part}), {&tie, 1}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.updated, 0u);
    EXPECT_EQ(m.added, 0u);
    EXPECT_EQ(m.kept, (std::vector<std::uint32_t>{3}));
    EXPECT_EQ(m.models[0].model.markers_model_mm.size(), 30u);
    EXPECT_EQ(m.learntIndex, (std::vector<int>{-1}));

    // One that needs more markers in view to be found: a layout with a near copy of a triangle
    // of its own. S_min judged in the same set for both.
    std::vector<Vec3> regular = test::irregularLayout(6, 9, 15.0);
    std::vector<Vec3> copied = regular;
    const RigidTransform shift{Quat::Identity(), Vec3(90.0, 0.0, 0.0)};
    for (int i = 0; i < 5; ++i)
        copied.push_back(shift.apply(regular[static_cast<std::size_t>(i)]));
    std::vector<Vec3> plain = copied;
    plain[10] = shift.apply(regular[4]) + Vec3(0.0, 25.0, -20.0);
    k.clear();
    k.push_back(known(plain, 5, "plain"));
    const SameObject same{0, 0, RigidTransform{}, 10};
    m = mergeLearntModels(k, learnt({copied}), {&same, 1}, 16, kShape, kShape.tolerance_mm);
    ASSERT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.kept, (std::vector<std::uint32_t>{5})) << "S_min " << m.models[0].model.sMin;
    EXPECT_TRUE(onLayout(m.models[0].model, plain, 1e-9));
}

TEST(ModelMerge, AModelThatNeedsMoreMarkersThanItsSessionShowedIsSaidSeldomFindable) {
    MarkerModel sphere = test::fullyConnectedModel(test::irregularLayout(24, 3, 10.0), 0, 11);
    const std::optional<std::string> why = seldomFindable(sphere, 10);
    ASSERT_TRUE(why.has_value());
    EXPECT_EQ(why->rfind("needs 11 of its markers in view to be found, and the session showed at "
                         "most 10 at once",
                         0),
              0u)
        << *why;
    EXPECT_NE(why->find("less regular"), std::string::npos);
    EXPECT_FALSE(seldomFindable(sphere, 11).has_value());
    EXPECT_FALSE(seldomFindable(sphere, 0).has_value()) << "nothing known of its session";
}

TEST(ModelMerge, SminIsWhatTheTrackerNeedsAtTheToleranceItPairsDistancesWith) {
    // The jittered sphere's layout nearly maps onto itself in many ways: within 2 mm, ten
    // markers at once; within the tracker's 1 mm, seven.
    const std::vector<Vec3> sphere = layoutOf(sim::makeSphere70());
    EXPECT_EQ(mergeLearntModels({}, learnt({sphere}), {}, 16, kShape, 2.0).models[0].model.sMin,
              11u);
    EXPECT_EQ(mergeLearntModels({}, learnt({sphere}), {}, 16, kShape, 1.0).models[0].model.sMin,
              8u);
}

TEST(KnownInSession, TiesEachLearntModelToTheBodyThatWasWhereItIs) {
    // Two objects in view, each known; the session learnt both (in frames of their own). The
    // board's tracker last found known body 0 (layout X) and body 1 (layout Y) where they were.
    const std::vector<Vec3> x = test::irregularLayout(7, 21, 12.0);
    const std::vector<Vec3> y = test::irregularLayout(7, 22, 12.0);
    std::vector<MarkerModel> knownModels;
    knownModels.push_back(test::fullyConnectedModel(x, 0));
    knownModels.push_back(test::fullyConnectedModel(y, 1));
    knownModels.push_back(test::fullyConnectedModel(test::irregularLayout(7, 23, 12.0), 2));
    std::vector<MarkerModel> learntModels;
    learntModels.push_back(test::fullyConnectedModel(moved(y, kOtherFrame), 0));
    learntModels.push_back(test::fullyConnectedModel(moved(x, kOtherFrame.inverse()), 1));

    SessionBuffer frames(200, 200 * 20);
    auto poseOf = [](std::size_t object, double t) {
        return RigidTransform{Quat(Eigen::AngleAxisd(0.4 * t + static_cast<double>(object),
                                                     Vec3(0.2, 1.0, 0.1).normalized())),
                              Vec3(object == 0 ? -150.0 : 150.0, 10.0 * t, 900.0)};
    };
    double t = 0.0;
    for (int f = 0; f < 100; ++f) {
        t = f * 0.01;
        std::vector<Vec3> points = moved(x, poseOf(0, t));
        for (const Vec3& p : moved(y, poseOf(1, t)))
            points.push_back(p);
        ASSERT_TRUE(frames.append(t, points));
    }
    const KnownSighting sightings[2] = {{0, t, poseOf(0, t)}, {1, t, poseOf(1, t)}};
    const std::vector<SameObject> same = findKnownInSession(
        frames, knownModels, sightings, learntModels, ModelTrackingConfig{}, 2.0);
    ASSERT_EQ(same.size(), 2u);
    for (const SameObject& s : same) {
        EXPECT_EQ(s.learnt, s.known == 0 ? 1u : 0u) << "known " << s.known;
        EXPECT_EQ(s.sharedMarkers, 7u);
        for (std::size_t i = 0; i < 7; ++i)
            EXPECT_LT((s.T_known_from_learnt.apply(learntModels[s.learnt].markers_model_mm[i]) -
                       knownModels[s.known].markers_model_mm[i])
                          .norm(),
                      1e-6);
    }
    // A body the session showed nowhere near its last sighting is tied to nothing.
    const KnownSighting elsewhere{
        2, t, poseOf(0, t) * RigidTransform{Quat::Identity(), Vec3(0.0, 0.0, 400.0)}};
    EXPECT_TRUE(findKnownInSession(frames, knownModels, {&elsewhere, 1}, learntModels,
                                   ModelTrackingConfig{}, 2.0)
                    .empty());
}

} // namespace
} // namespace edgetrack::app
