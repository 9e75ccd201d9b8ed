// Tests of the joint least squares' precision: loose parts found, errors predicted.
#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/layout_precision.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack {
namespace {

// A pose (rig from body) turned about a random axis and moved in front of the rig (mm).
RigidTransform randomPose(std::mt19937& random) {
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    RigidTransform pose;
    pose.rotation = Quat(Eigen::AngleAxisd(
        3.0 * unit(random), Vec3(unit(random), unit(random), unit(random) + 2.0).normalized()));
    pose.translation_mm = Vec3(50.0 * unit(random), 50.0 * unit(random), 600.0);
    return pose;
}

struct NormalEquations {
    Eigen::MatrixXd reduced;
    Eigen::VectorXd rhs;
    std::vector<std::uint32_t> counts;
};

// The normal equations of \a layout seen in \a frames frames, each showing the markers of one of
// \a views in turn, without noise.
NormalEquations normalEquations(const std::vector<Vec3>& layout,
                                const std::vector<std::vector<std::size_t>>& views,
                                std::size_t frames, unsigned seed) {
    std::mt19937 random(seed);
    NormalEquations e;
    const auto dimension = static_cast<Eigen::Index>(3 * layout.size());
    e.reduced = Eigen::MatrixXd::Zero(dimension, dimension);
    e.rhs = Eigen::VectorXd::Zero(dimension);
    e.counts.assign(layout.size(), 0);
    for (std::size_t f = 0; f < frames; ++f) {
        const std::vector<std::size_t>& which = views[f % views.size()];
        const RigidTransform pose = randomPose(random);
        std::vector<Vec3> markers, points;
        for (const std::size_t k : which) {
            markers.push_back(layout[k]);
            points.push_back(pose.apply(layout[k]));
            ++e.counts[k];
        }
        addToReducedSystem(pose, markers, points, which, e.reduced, e.rhs);
    }
    return e;
}

// Two sides of an object that share only two markers, never seen together: each side's frames
// fix its own shape, but the turn of one side about the line through the shared two is in none
// of them. That is one loose mode, and no marker's place is known; a single view of three
// markers of one side with one of the other ties them.
TEST(LayoutPrecision, CountsASideTurningAboutTwoSharedMarkersAsLoose) {
    const std::vector<Vec3> layout = test::irregularLayout(6, 3, 15.0);
    const std::vector<std::size_t> left{0, 1, 2, 3};
    const std::vector<std::size_t> right{2, 3, 4, 5};
    NormalEquations hinged = normalEquations(layout, {left, right}, 40, 1);
    const LayoutPrecision loose = layoutPrecision(hinged.reduced, hinged.counts, 3.0, 300.0);
    EXPECT_EQ(loose.looseModes, 1U);
    EXPECT_TRUE(std::isinf(loose.markerRms_mm));
    EXPECT_DOUBLE_EQ(loose.pointSigma_mm, 0.1);

    NormalEquations tied = normalEquations(layout, {left, right, {1, 2, 3, 4}}, 40, 1);
    const LayoutPrecision fixed = layoutPrecision(tied.reduced, tied.counts, 3.0, 300.0);
    EXPECT_EQ(fixed.looseModes, 0U);
    EXPECT_GT(fixed.markerRms_mm, 0.0);
    EXPECT_LT(fixed.markerRms_mm, 0.1);
    EXPECT_GE(fixed.worstMarker_mm, fixed.markerRms_mm);
}

// Four times the frames, half the error; twice the noise, twice the error.
TEST(LayoutPrecision, FallsWithTheRootOfTheFramesAndGrowsWithTheNoise) {
    const std::vector<Vec3> layout = test::irregularLayout(8, 4, 15.0);
    const std::vector<std::vector<std::size_t>> views{{0, 1, 2, 3, 4}, {2, 3, 4, 5, 6, 7}};
    const NormalEquations few = normalEquations(layout, views, 100, 2);
    const NormalEquations many = normalEquations(layout, views, 400, 2);
    const double fewRms = layoutPrecision(few.reduced, few.counts, 0.01, 1.0).markerRms_mm;
    const double manyRms = layoutPrecision(many.reduced, many.counts, 0.01, 1.0).markerRms_mm;
    const double noisyRms = layoutPrecision(many.reduced, many.counts, 0.04, 1.0).markerRms_mm;
    ASSERT_TRUE(std::isfinite(fewRms) && std::isfinite(manyRms));
    EXPECT_NEAR(fewRms / manyRms, 2.0, 0.2);
    EXPECT_NEAR(noisyRms / manyRms, 2.0, 1e-9);
}

} // namespace
} // namespace edgetrack
