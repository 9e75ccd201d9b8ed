// Tests of how a field calibration's learnt models join the models on the board.
#include <random>

#include <gtest/gtest.h>

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
    const MergedModels m = mergeLearntModels({}, l, 16, kShape);
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
    const MergedModels m = mergeLearntModels(k, l, 16, kShape);
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
    MergedModels m = mergeLearntModels({}, learnt({cube, piece}), 16, kShape);
    EXPECT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.fragments, 1u);
    EXPECT_EQ(m.models[0].model.markers_model_mm.size(), 30u);
    EXPECT_EQ(m.learntIndex, (std::vector<int>{0}));

    // A glimpse of a known body must not replace the whole body's model.
    std::vector<NamedModel> k;
    k.push_back(known(cube, 3, "cube"));
    m = mergeLearntModels(k, learnt({piece}), 16, kShape);
    ASSERT_EQ(m.models.size(), 1u);
    EXPECT_EQ(m.fragments, 1u);
    EXPECT_EQ(m.updated, 0u);
    EXPECT_EQ(m.models[0].model.markers_model_mm.size(), 30u);
}

TEST(ModelMerge, CopiesOfOneLayoutAreKeptAndMarkedAsCopies) {
    const std::vector<Vec3> cube = layoutOf(sim::makeCube70());
    const MergedModels m = mergeLearntModels({}, learnt({cube, cube}), 16, kShape);
    ASSERT_EQ(m.models.size(), 2u);
    EXPECT_EQ(m.fragments, 0u);
    EXPECT_EQ(m.models[0].model.sameShapeAs, 1);
    EXPECT_EQ(m.models[1].model.sameShapeAs, 0);
}

TEST(ModelMerge, WhatDoesNotFitMaxModelsIsRefusedAndCounted) {
    std::vector<NamedModel> k;
    k.push_back(known(layoutOf(sim::makeCube70()), 0, "a"));
    const MergedModels m =
        mergeLearntModels(k, learnt({scattered(6, 2), scattered(7, 3)}), 2, kShape);
    EXPECT_EQ(m.models.size(), 2u);
    EXPECT_EQ(m.added, 1u);
    EXPECT_EQ(m.refused, 1u);
}

} // namespace
} // namespace edgetrack::app
