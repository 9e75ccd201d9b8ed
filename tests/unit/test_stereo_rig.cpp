// Tests of the stereo rig's rectification: matching blobs share a rectified row.
#include <random>

#include <gtest/gtest.h>

#include "core/stereo_rig.hpp"
#include "tests/unit/rig_fixtures.hpp"

using namespace edgetrack;

namespace {

// Points in the desktop working volume, 350 to 800 mm in front of the rig.
std::vector<Vec3> workingVolumePoints(int count, unsigned seed) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> x(-150.0, 250.0), y(-150.0, 150.0), z(350.0, 800.0);
    std::vector<Vec3> points;
    for (int i = 0; i < count; ++i)
        points.emplace_back(x(random), y(random), z(random));
    return points;
}

} // namespace

TEST(StereoRig, CorrespondingPixelsShareARectifiedRow) {
    const StereoRig rig = test::desktopRig();
    ASSERT_TRUE(rig.isValid());
    EXPECT_NEAR(rig.baseline_mm(), 120.0, 1e-9);
    for (const Vec3& point : workingVolumePoints(500, 1)) {
        const auto pixel0 = rig.camera(0).project(point);
        const auto pixel1 = rig.camera(1).project(point);
        ASSERT_TRUE(pixel0 && pixel1);
        const auto rect0 = rig.rectify(0, *pixel0);
        const auto rect1 = rig.rectify(1, *pixel1);
        ASSERT_TRUE(rect0 && rect1);
        EXPECT_NEAR(rect0->y(), rect1->y(), 1e-7);
        // Camera 1 is to the right, so a point appears further left in it: positive disparity.
        EXPECT_GT(rect0->x() - rect1->x(), 0.0);
    }
}

TEST(StereoRig, DisparityGivesDepthAlongTheRectifiedAxis) {
    const StereoRig rig = test::desktopRig();
    for (const Vec3& point : workingVolumePoints(50, 2)) {
        const auto rect0 = rig.rectifyPoint(0, point);
        const auto rect1 = rig.rectifyPoint(1, point);
        ASSERT_TRUE(rect0 && rect1);
        const double depth_rect_mm =
            (rig.rotation_rect_from_rig() * (point - rig.camera(0).centre_rig_mm())).z();
        const double disparity_px = rect0->x() - rect1->x();
        EXPECT_NEAR(rig.rectifiedFocal_px() * rig.baseline_mm() / disparity_px, depth_rect_mm,
                    1e-6);
    }
}

TEST(StereoRig, VerticalBaselineRectifiesToo) {
    CameraExtrinsics ex1;
    ex1.translation_cam_from_rig_mm = {0.0, -90.0, 0.0}; // camera 1 sits 90 mm below camera 0
    const StereoRig rig(CameraModel(test::desktopIntrinsics(), CameraExtrinsics{}),
                        CameraModel(test::desktopIntrinsics(), ex1));
    ASSERT_TRUE(rig.isValid());
    for (const Vec3& point : workingVolumePoints(100, 3)) {
        const auto rect0 = rig.rectifyPoint(0, point);
        const auto rect1 = rig.rectifyPoint(1, point);
        ASSERT_TRUE(rect0 && rect1);
        EXPECT_NEAR(rect0->y(), rect1->y(), 1e-7);
    }
}

TEST(StereoRig, RefusesDegenerateRigs) {
    const CameraModel camera(test::desktopIntrinsics(), CameraExtrinsics{});
    EXPECT_FALSE(StereoRig(camera, camera).isValid());

    CameraExtrinsics ahead;
    ahead.translation_cam_from_rig_mm = {0.0, 0.0, -100.0}; // baseline along the optical axis
    EXPECT_FALSE(StereoRig(camera, CameraModel(test::desktopIntrinsics(), ahead)).isValid());

    EXPECT_FALSE(StereoRig(camera, CameraModel()).isValid());
}
