// Tests of ray-pair triangulation: exact on noiseless rays, honest residual on skew ones.
#include <random>

#include <gtest/gtest.h>

#include "core/triangulation.hpp"
#include "tests/unit/rig_fixtures.hpp"

using namespace edgetrack;

TEST(Triangulation, NoiselessRaysAreExact) {
    const StereoRig rig = test::desktopRig();
    std::mt19937 random(11);
    std::uniform_real_distribution<double> x(-150.0, 250.0), y(-150.0, 150.0), z(350.0, 800.0);
    double worst_mm = 0.0;
    for (int i = 0; i < 1000; ++i) {
        const Vec3 point{x(random), y(random), z(random)};
        // Through the whole camera model: distort to pixels, undistort back to rays.
        const auto ray0 = rig.camera(0).ray(*rig.camera(0).project(point));
        const auto ray1 = rig.camera(1).ray(*rig.camera(1).project(point));
        ASSERT_TRUE(ray0 && ray1);
        const auto result = triangulate(*ray0, *ray1);
        ASSERT_TRUE(result);
        worst_mm = std::max(worst_mm, (result->point_rig_mm - point).norm());
        EXPECT_LT(result->rayGap_mm, 1e-6);
        EXPECT_GT(result->range0_mm, 0.0);
        EXPECT_GT(result->range1_mm, 0.0);
    }
    EXPECT_LT(worst_mm, 1e-6);
}

TEST(Triangulation, SkewRaysGiveMidpointAndGap) {
    const Ray along_x{Vec3::Zero(), Vec3::UnitX()};
    const Ray along_y{Vec3{0.0, 10.0, 3.0}, Vec3::UnitY()};
    const auto result = triangulate(along_x, along_y);
    ASSERT_TRUE(result);
    EXPECT_NEAR(result->rayGap_mm, 3.0, 1e-12);
    EXPECT_NEAR((result->point_rig_mm - Vec3(0.0, 0.0, 1.5)).norm(), 0.0, 1e-12);
    EXPECT_NEAR(result->range0_mm, 0.0, 1e-12);
    EXPECT_NEAR(result->range1_mm, -10.0, 1e-12); // behind ray 1's origin: callers reject this
}

TEST(Triangulation, ParallelRaysHaveNoAnswer) {
    const Ray a{Vec3::Zero(), Vec3::UnitZ()};
    const Ray b{Vec3{120.0, 0.0, 0.0}, Vec3::UnitZ()};
    EXPECT_FALSE(triangulate(a, b));
}
