// Tests of the board's rig session: sightings from blobs, and the old rig kept when a new one
// fits only the sightings it was made from.
#include <random>

#include <gtest/gtest.h>

#include "firmware_app/firmware/rig_session.hpp"
#include "hal/sim/devices.hpp"
#include "hal/sim/scene.hpp"

namespace edgetrack::app {
namespace {

/// Blobs of the wand of \a settings with marker 0 at \a origin (mm) along \a direction, in
/// camera \a c of \a rig, shifted by \a shift_px.
std::vector<Blob> wandBlobs(const StereoRig& rig, int c, const WandSpec& wand, const Vec3& origin,
                            const Vec3& direction, const Vec2& shift_px) {
    std::vector<Blob> blobs;
    for (std::size_t k = 0; k < wand.markerCount; ++k) {
        Blob b;
        b.centre_px = *rig.camera(c).project(origin + wand.offset_mm(k) * direction) + shift_px;
        blobs.push_back(b);
    }
    return blobs;
}

/// Feeds \a frames frames of a waved wand; every second frame's camera 1 blobs are shifted by
/// \a biasOnEven_px (a flaw the sightings share only in half of them).
void wave(RigSession& session, const StereoRig& rig, const WandSpec& wand, int frames,
          const Vec2& biasOnEven_px) {
    std::mt19937 random(3);
    std::uniform_real_distribution<double> x(-200.0, 300.0), y(-150.0, 150.0), z(450.0, 800.0);
    std::uniform_real_distribution<double> unit(-1.0, 1.0);
    std::normal_distribution<double> noise(0.0, 0.05);
    for (int f = 0; f < frames; ++f) {
        const Vec3 origin(x(random), y(random), z(random));
        const Vec3 direction =
            Vec3(unit(random), 0.5 * unit(random), 0.3 * unit(random)).normalized();
        std::array<std::vector<Blob>, 2> blobs;
        for (int c = 0; c < 2; ++c) {
            const Vec2 shift = c == 1 && f % 2 == 0 ? biasOnEven_px : Vec2::Zero();
            blobs[static_cast<std::size_t>(c)] = wandBlobs(rig, c, wand, origin, direction, shift);
            for (Blob& b : blobs[static_cast<std::size_t>(c)])
                b.centre_px += Vec2(noise(random), noise(random));
        }
        ASSERT_EQ(session.update(0.01 * f, rig, blobs[0], blobs[1]), RigSessionStep::Continue);
    }
}

} // namespace

TEST(RigSession, CollectsTheWandFromBothCamerasBlobs) {
    const StereoRig rig = sim::makeRig({});
    RigCalibrationSettings settings;
    RigSession session(settings);
    ASSERT_TRUE(session.isValid());
    session.open(0.0);
    wave(session, rig, WandSpec::fromSpacings(settings.wand_mm), 200, Vec2::Zero());
    EXPECT_GE(session.pairs(), 190u);
    EXPECT_EQ(session.finderCounters(0).images, 200u);
    // The session ends by itself at its duration.
    const std::vector<Blob> none;
    EXPECT_EQ(session.update(settings.duration_s, rig, none, none), RigSessionStep::TimeUp);
}

TEST(RigSession, ANewRigThatFitsOnlyItsOwnSightingsIsNotAdopted) {
    const StereoRig rig = sim::makeRig({});
    RigCalibrationSettings settings;
    sim::SimFlash flash(64u << 10, 4096);
    RigStore store(flash);

    // Half the sightings carry a 1.5 px flaw in camera 1: the rig fitted to them explains them,
    // but not the other half, which the rig in use (the true one) fits to the noise.
    RigSession flawed(settings);
    flawed.open(0.0);
    wave(flawed, rig, WandSpec::fromSpacings(settings.wand_mm), 300, Vec2(1.5, 0.0));
    flawed.finish(rig, store);
    const std::optional<FinishedRigCalibration> kept = flawed.wait();
    ASSERT_TRUE(kept);
    ASSERT_TRUE(kept->calibrated) << kept->error;
    ASSERT_TRUE(kept->previous);
    EXPECT_FALSE(kept->adopted);
    EXPECT_GT(kept->heldOut_px, meanReprojection_px(*kept->previous));
    EXPECT_FALSE(store.load()) << "nothing saved";

    // The same session without the flaw, from a rig knocked by 0.3 degrees: adopted and saved.
    CameraExtrinsics ex = rig.camera(1).extrinsics();
    ex.rotation_cam_from_rig =
        Eigen::AngleAxisd(0.3 * M_PI / 180.0, Vec3::UnitX()).toRotationMatrix() *
        ex.rotation_cam_from_rig;
    const StereoRig knocked(rig.camera(0), CameraModel(rig.camera(1).intrinsics(), ex));
    RigSession clean(settings);
    clean.open(0.0);
    wave(clean, rig, WandSpec::fromSpacings(settings.wand_mm), 300, Vec2::Zero());
    clean.finish(knocked, store);
    const std::optional<FinishedRigCalibration> adopted = clean.wait();
    ASSERT_TRUE(adopted && adopted->calibrated);
    EXPECT_TRUE(adopted->adopted);
    EXPECT_TRUE(adopted->saved);
    EXPECT_TRUE(adopted->good());
    const Result<StoredRig> stored = store.load();
    ASSERT_TRUE(stored);
    EXPECT_LT(Eigen::AngleAxisd(stored->rig.camera(1).extrinsics().rotation_cam_from_rig *
                                rig.camera(1).extrinsics().rotation_cam_from_rig.transpose())
                  .angle(),
              0.01 * M_PI / 180.0);
}

} // namespace edgetrack::app
