// Tests of the camera model: projection, undistortion by Newton iteration, rays.
#include <random>

#include <gtest/gtest.h>

#include "core/camera_model.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/unit/rig_fixtures.hpp"

using namespace edgetrack;

TEST(CameraModel, ProjectsPinholeWithoutDistortion) {
    CameraIntrinsics in = test::desktopIntrinsics();
    in.fx_px = 910.0;
    in.fy_px = 910.0;
    in.cx_px = 640.0;
    in.cy_px = 400.0;
    const CameraModel camera(in, CameraExtrinsics{});
    ASSERT_TRUE(camera.isValid());
    const auto pixel = camera.project({100.0, 50.0, 1000.0});
    ASSERT_TRUE(pixel);
    EXPECT_NEAR(pixel->x(), 731.0, 1e-12);
    EXPECT_NEAR(pixel->y(), 445.5, 1e-12);
}

TEST(CameraModel, PointBehindCameraHasNoProjection) {
    const CameraModel camera(test::desktopIntrinsics(), CameraExtrinsics{});
    EXPECT_FALSE(camera.project({0.0, 0.0, -500.0}));
    EXPECT_FALSE(camera.project({10.0, 0.0, 0.0}));
}

TEST(CameraModel, StrongDistortionRoundTripsOverWholeImage) {
    // The acceptance case: k1 = -0.3, k2 = 0.1, plus tangential terms, every 4 px and every edge.
    CameraIntrinsics in = test::desktopIntrinsics(-0.3, 0.1);
    in.distortion[2] = 0.001;
    in.distortion[3] = -0.0008;
    const CameraModel camera(in, CameraExtrinsics{});
    double worst_px = 0.0;
    for (int v = 0; v <= in.height_px; v += 4) {
        for (int u = 0; u <= in.width_px; u += 4) {
            const Vec2 pixel{u == in.width_px ? u - 1.0 : u, v == in.height_px ? v - 1.0 : v};
            const auto normalized = camera.undistortPixel(pixel);
            ASSERT_TRUE(normalized) << "pixel " << pixel.transpose();
            const Vec2 back = camera.pixelFromNormalized(camera.distortNormalized(*normalized));
            worst_px = std::max(worst_px, (back - pixel).norm());
        }
    }
    EXPECT_LT(worst_px, 1e-3);
}

TEST(CameraModel, ProjectThenUndistortRecoversTheDirection) {
    const CameraModel camera(test::desktopIntrinsics(-0.3, 0.1), CameraExtrinsics{});
    std::mt19937 random(3);
    std::uniform_real_distribution<double> lateral(-0.6, 0.6);
    for (int i = 0; i < 2000; ++i) {
        const Vec3 point{lateral(random) * 500.0, lateral(random) * 320.0, 500.0};
        const auto pixel = camera.project(point);
        ASSERT_TRUE(pixel);
        const auto normalized = camera.undistortPixel(*pixel);
        ASSERT_TRUE(normalized);
        EXPECT_NEAR(normalized->x(), point.x() / point.z(), 1e-9);
        EXPECT_NEAR(normalized->y(), point.y() / point.z(), 1e-9);
    }
}

TEST(CameraModel, PixelOutsideInvertibleRegionIsRefused) {
    // r_d = r - 0.3 r^3 peaks at about 0.70: a distorted radius of 1.0 has no undistorted preimage.
    const CameraModel camera(test::desktopIntrinsics(-0.3, 0.0), CameraExtrinsics{});
    const CameraIntrinsics& in = camera.intrinsics();
    EXPECT_FALSE(camera.undistortPixel({in.cx_px + in.fx_px, in.cy_px}));
}

TEST(CameraModel, RayPassesThroughThePoint) {
    CameraExtrinsics ex;
    ex.rotation_cam_from_rig =
        Eigen::AngleAxisd(0.3, Vec3(0.2, 1.0, 0.1).normalized()).toRotationMatrix();
    ex.translation_cam_from_rig_mm = {-35.0, 12.0, 40.0};
    const CameraModel camera(test::desktopIntrinsics(-0.2, 0.05), ex);
    ASSERT_TRUE(camera.isValid());
    const Vec3 point_rig{-80.0, 40.0, 650.0};
    const auto pixel = camera.project(point_rig);
    ASSERT_TRUE(pixel);
    const auto ray = camera.ray(*pixel);
    ASSERT_TRUE(ray);
    EXPECT_NEAR(ray->direction_rig.norm(), 1.0, 1e-12);
    EXPECT_LT((ray->origin_rig_mm - camera.centre_rig_mm()).norm(), 1e-12);
    const Vec3 toPoint = point_rig - ray->origin_rig_mm;
    const double offLine_mm =
        (toPoint - toPoint.dot(ray->direction_rig) * ray->direction_rig).norm();
    EXPECT_LT(offLine_mm, 1e-6);
    EXPECT_GT(toPoint.dot(ray->direction_rig), 0.0);
}

TEST(CameraModel, InvalidParametersAreReported) {
    CameraIntrinsics noFocal = test::desktopIntrinsics();
    noFocal.fx_px = 0.0;
    EXPECT_FALSE(CameraModel(noFocal, CameraExtrinsics{}).isValid());

    CameraIntrinsics noSize = test::desktopIntrinsics();
    noSize.height_px = 0;
    EXPECT_FALSE(CameraModel(noSize, CameraExtrinsics{}).isValid());

    CameraExtrinsics scaled;
    scaled.rotation_cam_from_rig *= 1.1;
    EXPECT_FALSE(CameraModel(test::desktopIntrinsics(), scaled).isValid());

    CameraExtrinsics mirrored;
    mirrored.rotation_cam_from_rig(0, 0) = -1.0;
    EXPECT_FALSE(CameraModel(test::desktopIntrinsics(), mirrored).isValid());

    CameraIntrinsics nanDistortion = test::desktopIntrinsics();
    nanDistortion.distortion[4] = std::nan("");
    EXPECT_FALSE(CameraModel(nanDistortion, CameraExtrinsics{}).isValid());

    EXPECT_FALSE(CameraModel().isValid());
}

TEST(CameraModel, UndistortionDoesNotAllocate) {
    const CameraModel camera(test::desktopIntrinsics(-0.3, 0.1), CameraExtrinsics{});
    double sink = 0.0;
    const auto count = test::countAllocations([&] {
        for (int i = 0; i < 1000; ++i)
            if (auto ray = camera.ray({static_cast<double>(i), 400.0}))
                sink += ray->direction_rig.x();
    });
    EXPECT_EQ(count, 0u);
    EXPECT_NE(sink, 0.0);
}
