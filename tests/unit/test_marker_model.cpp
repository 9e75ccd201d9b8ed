// Tests of marker models: canonical frames and S_min from congruences.
#include <cmath>
#include <map>
#include <optional>
#include <random>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "core/marker_model.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack {
namespace {

MarkerModel fullyConnected(const std::vector<Vec3>& layout) {
    return test::fullyConnectedModel(layout);
}

std::vector<Vec3> irregularLayout(std::size_t count, unsigned seed) {
    return test::irregularLayout(count, seed, 12.0);
}

TEST(CanonicalFrame, IsTheSameWhereverTheLayoutWasMeasured) {
    const std::vector<Vec3> layout = irregularLayout(10, 3);
    RigidTransform motion;
    motion.rotation = quaternionFromWxyz(0.3, -0.5, 0.7, 0.1);
    motion.translation_mm = Vec3(120.0, -40.0, 560.0);
    std::vector<Vec3> moved;
    for (const Vec3& p : layout)
        moved.push_back(motion.apply(p));
    const RigidTransform a = canonicalFrame(layout).inverse();
    const RigidTransform b = canonicalFrame(moved).inverse();
    for (std::size_t i = 0; i < layout.size(); ++i)
        EXPECT_LT((a.apply(layout[i]) - b.apply(moved[i])).norm(), 1e-9);
    // The origin is the centroid.
    Vec3 centroid = Vec3::Zero();
    for (const Vec3& p : layout)
        centroid += a.apply(p);
    EXPECT_LT(centroid.norm() / static_cast<double>(layout.size()), 1e-9);
}

TEST(Smin, IrregularLayoutNeedsOnlyTheFloor) {
    MarkerModel model = fullyConnected(irregularLayout(8, 5));
    computeSmin(std::span(&model, 1), SminConfig{});
    EXPECT_EQ(model.sMin, 4u);
    EXPECT_EQ(model.sameShapeAs, -1);
}

TEST(Smin, SymmetricLayoutCannotBeIdentifiedByAnySubset) {
    // Two squares, one above the other and turned by 45 degrees: a quarter turn maps all eight
    // markers onto each other, so no number of them fixes the orientation.
    std::vector<Vec3> layout;
    for (int k = 0; k < 4; ++k) {
        const double a = k * M_PI / 2.0;
        layout.emplace_back(30.0 * std::cos(a), 30.0 * std::sin(a), 0.0);
        layout.emplace_back(20.0 * std::cos(a + M_PI / 4.0), 20.0 * std::sin(a + M_PI / 4.0), 25.0);
    }
    MarkerModel model = fullyConnected(layout);
    computeSmin(std::span(&model, 1), SminConfig{});
    EXPECT_EQ(model.sMin, 8u);
}

TEST(Smin, PartialSymmetryRaisesSminAboveTheSymmetricPart) {
    // A symmetric square of four plus two markers that break the symmetry: four markers fit two
    // ways, so identifying it takes five.
    std::vector<Vec3> layout{{30, 0, 0},  {0, 30, 0},  {-30, 0, 0},
                             {0, -30, 0}, {12, 5, 35}, {-20, 14, 52}};
    MarkerModel model = fullyConnected(layout);
    computeSmin(std::span(&model, 1), SminConfig{});
    EXPECT_EQ(model.sMin, 5u);
}

TEST(SameShape, FindsCopiesMeasuredInOtherFramesAndWithMissingMarkers) {
    const std::vector<Vec3> layout = irregularLayout(20, 21);
    RigidTransform motion;
    motion.rotation = quaternionFromWxyz(0.2, 0.9, -0.3, 0.4);
    motion.translation_mm = Vec3(5.0, 70.0, -30.0);
    std::vector<Vec3> copy;
    // The copy was calibrated elsewhere: moved, a tenth of a millimetre off, and two markers
    // were never seen.
    std::mt19937 random(22);
    std::normal_distribution<double> noise(0.0, 0.1);
    for (std::size_t i = 2; i < layout.size(); ++i)
        copy.push_back(motion.apply(layout[i]) + Vec3(noise(random), noise(random), noise(random)));
    const SminConfig config;
    EXPECT_TRUE(sameShape(fullyConnected(layout), fullyConnected(copy), config));
    EXPECT_TRUE(sameShape(fullyConnected(copy), fullyConnected(layout), config));
    EXPECT_FALSE(
        sameShape(fullyConnected(layout), fullyConnected(irregularLayout(20, 23)), config));
    // Half a model is not a copy of it.
    const std::vector<Vec3> half(layout.begin(), layout.begin() + 10);
    EXPECT_FALSE(sameShape(fullyConnected(layout), fullyConnected(half), config));
}

TEST(Smin, IdenticalModelsAreMarkedAsTheSameShape) {
    const std::vector<Vec3> layout = irregularLayout(9, 11);
    std::vector<MarkerModel> models;
    models.push_back(fullyConnected(layout));
    models.push_back(fullyConnected(layout));
    models.push_back(fullyConnected(irregularLayout(9, 12)));
    computeSmin(models, SminConfig{});
    EXPECT_EQ(models[0].sameShapeAs, 1);
    EXPECT_EQ(models[1].sameShapeAs, 0);
    EXPECT_EQ(models[2].sameShapeAs, -1);
    // A copy does not raise S_min: with the third model alone beside it, the copy's S_min is the
    // same as when the two copies are together.
    std::vector<MarkerModel> pair;
    pair.push_back(fullyConnected(layout));
    pair.push_back(fullyConnected(irregularLayout(9, 12)));
    computeSmin(pair, SminConfig{});
    EXPECT_EQ(models[0].sMin, pair[0].sMin);
    EXPECT_EQ(models[1].sMin, pair[0].sMin);
}

/// Keeps every pair computeSmin finds, and counts what it was told and asked.
class PairsKept final : public SminPairMemory {
public:
    std::optional<std::size_t> recall(std::size_t a, std::size_t b) const override {
        ++recalls;
        const auto it = largest.find({a, b});
        return it == largest.end() ? std::nullopt : std::optional<std::size_t>(it->second);
    }
    void remember(std::size_t a, std::size_t b, std::size_t l) override {
        largest[{a, b}] = l;
        ++remembered;
    }
    std::map<std::pair<std::size_t, std::size_t>, std::size_t> largest;
    mutable std::size_t recalls = 0;
    std::size_t remembered = 0;
};

TEST(Smin, PairsRememberedFromAnEarlierRunGiveTheSameResult) {
    // A symmetric square with two more markers (S_min 5), a copy of an irregular layout and the
    // layout itself (the same shape), and another irregular one.
    const std::vector<Vec3> square{{30, 0, 0},  {0, 30, 0},  {-30, 0, 0},
                                   {0, -30, 0}, {12, 5, 35}, {-20, 14, 52}};
    const std::vector<Vec3> irregular = irregularLayout(9, 11);
    auto fresh = [&] {
        std::vector<MarkerModel> models;
        models.push_back(fullyConnected(square));
        models.push_back(fullyConnected(irregular));
        models.push_back(fullyConnected(irregular));
        models.push_back(fullyConnected(irregularLayout(9, 12)));
        return models;
    };
    std::vector<MarkerModel> plain = fresh();
    computeSmin(plain, SminConfig{});

    SminWorkspace workspace;
    PairsKept kept;
    std::vector<MarkerModel> first = fresh();
    computeSmin(first, SminConfig{}, workspace, &kept);
    EXPECT_EQ(kept.remembered, 10u); // every pair a <= b of four models
    std::vector<MarkerModel> again = fresh();
    computeSmin(again, SminConfig{}, workspace, &kept);
    EXPECT_EQ(kept.remembered, 10u); // nothing computed again
    EXPECT_EQ(kept.recalls, 20u);
    for (std::size_t m = 0; m < plain.size(); ++m)
        for (const std::vector<MarkerModel>* run : {&first, &again}) {
            EXPECT_EQ((*run)[m].sMin, plain[m].sMin) << "model " << m;
            EXPECT_EQ((*run)[m].sameShapeAs, plain[m].sameShapeAs) << "model " << m;
        }
    EXPECT_EQ(plain[0].sMin, 5u);
    EXPECT_EQ(plain[1].sameShapeAs, 2);

    // What the memory says is what S_min takes: a pair remembered as congruent on all six
    // markers makes the first model need all of them.
    kept.largest[{0, 0}] = 6;
    std::vector<MarkerModel> told = fresh();
    computeSmin(told, SminConfig{}, workspace, &kept);
    EXPECT_EQ(told[0].sMin, 6u);
}

TEST(MarkerModel, AssignRefusesWhatDoesNotFit) {
    MarkerModel big = fullyConnected(irregularLayout(8, 2));
    MarkerModel small(4);
    EXPECT_FALSE(small.assign(big));
    MarkerModel roomy(16);
    ASSERT_TRUE(roomy.assign(big));
    EXPECT_EQ(roomy.markers_model_mm.size(), 8u);
    EXPECT_EQ(roomy.edges.size(), 28u);
    EXPECT_TRUE(roomy.hasEdge(7, 2));
}

} // namespace
} // namespace edgetrack
