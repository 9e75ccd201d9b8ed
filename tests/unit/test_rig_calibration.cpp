// Tests of rig calibration by wand on synthetic sightings: accuracy, start, outliers, refusals.
#include <random>

#include <gtest/gtest.h>

#include "core/rig_calibration.hpp"
#include "tests/support/rig_knock.hpp"
#include "tests/unit/rig_fixtures.hpp"

using namespace edgetrack;

namespace {

const std::array<double, 2> kWand{55.0, 102.0};

struct Session {
    std::vector<WandFramePair> pairs;
};

/// \a frames wand poses in the working volume, seen by \a rig with blob noise \a sigma_px
/// (standard deviation per coordinate).
Session waveWand(const StereoRig& rig, const WandSpec& wand, int frames, double sigma_px,
                 unsigned seed) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> x(-250.0, 300.0), y(-180.0, 180.0), z(400.0, 900.0);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    std::normal_distribution<double> noise(0.0, sigma_px);
    Session session;
    while (session.pairs.size() < static_cast<std::size_t>(frames)) {
        const Vec3 origin(x(random), y(random), z(random));
        const Vec3 direction = Vec3(unit(random), unit(random), 0.5 * unit(random)).normalized();
        WandFramePair pair;
        pair.frame = static_cast<std::int64_t>(session.pairs.size());
        bool inView = true;
        for (int c = 0; c < 2; ++c) {
            WandSighting& s = pair.sightings[static_cast<std::size_t>(c)];
            s.markerCount = wand.markerCount;
            s.endsAmbiguous = wand.isSymmetric();
            for (std::size_t k = 0; k < wand.markerCount; ++k) {
                const auto p = rig.camera(c).project(origin + wand.offset_mm(k) * direction);
                inView = inView && p && p->x() >= 0 && p->x() < 1280 && p->y() >= 0 && p->y() < 800;
                if (p)
                    s.pixels[k] = *p + Vec2(noise(random), noise(random));
            }
        }
        if (inView)
            session.pairs.push_back(pair);
    }
    return session;
}

} // namespace

TEST(RigCalibration, FindsCameraOnesPoseFromAFarStart) {
    const StereoRig truth = test::desktopRig();
    const WandSpec wand = WandSpec::fromSpacings(kWand);
    const double sigma_px = 0.05;
    const Session session = waveWand(truth, wand, 600, sigma_px, 1);
    const StereoRig start = test::knockedRig(truth, 50.0, 5.0);
    ASSERT_GT(test::cameraOneTurn_deg(start, truth), 4.9);

    const Result<RigCalibrationResult> result = calibrateRig(start, wand, session.pairs, {});
    ASSERT_TRUE(result) << result.error().message;
    EXPECT_LT(test::cameraOneTurn_deg(result->rig, truth), 0.01);
    EXPECT_LT(test::cameraOneShift_mm(result->rig, truth), 0.1);
    const RigCalibrationReport& report = result->report;
    EXPECT_EQ(report.framesUsed, 600u);
    // A marker's 2D error has RMS sigma * sqrt(2); each wand pose takes 5 of its 12 numbers.
    const double expected = sigma_px * std::sqrt(2.0) * std::sqrt(7.0 / 12.0);
    for (double rms : report.reprojectionRms_px)
        EXPECT_NEAR(rms, expected, 0.1 * expected);
    EXPECT_LT(report.lengthErrorRms_mm, 0.3);
    EXPECT_NEAR(report.rotationChange_deg, 5.0, 0.02);
    EXPECT_TRUE(report.good()) << report.warnings.front();
}

TEST(RigCalibration, RefinedIntrinsicsFindTheFocalLengths) {
    const StereoRig truth = test::desktopRig();
    const WandSpec wand = WandSpec::fromSpacings(kWand);
    const Session session = waveWand(truth, wand, 800, 0.05, 2);
    StereoRig start = test::knockedRig(truth, 30.0, 2.0);
    std::array<CameraModel, 2> cameras{start.camera(0), start.camera(1)};
    for (CameraModel& camera : cameras) {
        CameraIntrinsics in = camera.intrinsics();
        in.fx_px *= 1.01;
        in.fy_px *= 0.99;
        in.cx_px += 6.0;
        camera = CameraModel(in, camera.extrinsics());
    }
    start = StereoRig(cameras[0], cameras[1]);

    RigCalibrationConfig config;
    config.refineIntrinsics = true;
    const Result<RigCalibrationResult> result = calibrateRig(start, wand, session.pairs, config);
    ASSERT_TRUE(result) << result.error().message;
    for (int c = 0; c < 2; ++c) {
        const CameraIntrinsics& found = result->rig.camera(c).intrinsics();
        const CameraIntrinsics& real = truth.camera(c).intrinsics();
        EXPECT_NEAR(found.fx_px / real.fx_px, 1.0, 0.001) << "camera " << c;
        EXPECT_NEAR(found.fy_px / real.fy_px, 1.0, 0.001) << "camera " << c;
    }
    EXPECT_LT(test::cameraOneTurn_deg(result->rig, truth), 0.02);
    EXPECT_LT(test::cameraOneShift_mm(result->rig, truth), 0.3);

    // Without refinement the wrong focal lengths stay: the pose absorbs part of them, the
    // reprojection shows the rest.
    const Result<RigCalibrationResult> fixed = calibrateRig(start, wand, session.pairs, {});
    ASSERT_TRUE(fixed);
    EXPECT_GT(fixed->report.reprojectionRms_px[0], 2.0 * result->report.reprojectionRms_px[0]);
}

TEST(RigCalibration, WrongSightingsAreRefusedAndDoNotPullTheRig) {
    const StereoRig truth = test::desktopRig();
    const WandSpec wand = WandSpec::fromSpacings(kWand);
    Session session = waveWand(truth, wand, 500, 0.05, 3);
    // One pair in ten has a marker 6 px off in camera 1 (a reflection taken for it).
    for (std::size_t i = 0; i < session.pairs.size(); i += 10)
        session.pairs[i].sightings[1].pixels[1] += Vec2(6.0, -2.0);
    const Result<RigCalibrationResult> result =
        calibrateRig(test::knockedRig(truth, 20.0, 3.0), wand, session.pairs, {});
    ASSERT_TRUE(result) << result.error().message;
    EXPECT_EQ(result->report.framesRefused, 50u);
    EXPECT_EQ(result->report.framesUsed, 450u);
    EXPECT_LT(test::cameraOneTurn_deg(result->rig, truth), 0.01);
    EXPECT_LT(test::cameraOneShift_mm(result->rig, truth), 0.1);
}

TEST(RigCalibration, ATwoMarkerWandNeedsTheStartOnlyToPairItsEnds) {
    const StereoRig truth = test::desktopRig();
    const std::array<double, 1> stick{150.0};
    const WandSpec wand = WandSpec::fromSpacings(stick);
    Session session = waveWand(truth, wand, 600, 0.05, 4);
    // Each camera reads the two blobs in its own order, half the time reversed.
    std::mt19937 random(5);
    for (WandFramePair& pair : session.pairs)
        for (WandSighting& s : pair.sightings)
            if (random() % 2)
                std::swap(s.pixels[0], s.pixels[1]);
    const Result<RigCalibrationResult> result =
        calibrateRig(test::knockedRig(truth, 40.0, 4.0), wand, session.pairs, {});
    ASSERT_TRUE(result) << result.error().message;
    EXPECT_LT(test::cameraOneTurn_deg(result->rig, truth), 0.01);
    EXPECT_LT(test::cameraOneShift_mm(result->rig, truth), 0.1);
    // A wand lying along an epipolar line reads the same both ways: a few such pairs fit
    // neither reading well and are refused.
    EXPECT_GE(result->report.framesUsed, 590u);
}

TEST(RigCalibration, TooFewSightingsOrABadWandGiveAnErrorNotARig) {
    const StereoRig truth = test::desktopRig();
    const WandSpec wand = WandSpec::fromSpacings(kWand);
    const Session few = waveWand(truth, wand, 20, 0.05, 6);
    const Result<RigCalibrationResult> tooFew = calibrateRig(truth, wand, few.pairs, {});
    ASSERT_FALSE(tooFew);
    EXPECT_NE(tooFew.error().message.find("only 20 frame pairs"), std::string::npos);

    const Result<RigCalibrationResult> noWand = calibrateRig(truth, WandSpec{}, few.pairs, {});
    EXPECT_FALSE(noWand);

    // Sightings of pure noise: no pose fits them.
    Session noise = waveWand(truth, wand, 200, 0.05, 7);
    std::mt19937 random(8);
    std::uniform_real_distribution<double> u(0.0, 1279.0), v(0.0, 799.0);
    for (WandFramePair& pair : noise.pairs)
        for (WandSighting& s : pair.sightings)
            for (std::size_t k = 0; k < s.markerCount; ++k)
                s.pixels[k] = Vec2(u(random), v(random));
    const Result<RigCalibrationResult> garbage = calibrateRig(truth, wand, noise.pairs, {});
    if (garbage) {
        EXPECT_FALSE(garbage->report.good());
    }
}

TEST(RigCalibration, AssessingARigTellsTheTrueOneFromAMovedOne) {
    const StereoRig truth = test::desktopRig();
    const WandSpec wand = WandSpec::fromSpacings(kWand);
    const Session session = waveWand(truth, wand, 400, 0.05, 9);
    const Result<RigCalibrationReport> fits = assessRig(truth, wand, session.pairs, {});
    ASSERT_TRUE(fits) << fits.error().message;
    const double expected = 0.05 * std::sqrt(2.0) * std::sqrt(7.0 / 12.0);
    EXPECT_NEAR(fits->reprojectionRms_px[1], expected, 0.1 * expected);
    EXPECT_NEAR(fits->rotationChange_deg, 0.0, 1e-9);

    // Camera 1 knocked by 0.2 degrees and 1 mm: the wand poses cannot make up for it.
    const Result<RigCalibrationReport> knocked =
        assessRig(test::knockedRig(truth, 1.0, 0.2), wand, session.pairs, {});
    ASSERT_TRUE(knocked);
    EXPECT_GT(knocked->reprojectionRms_px[1], 10.0 * fits->reprojectionRms_px[1]);
}
