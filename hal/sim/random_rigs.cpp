// Stereo rigs of any build, drawn from a seed: the rigs quality runs sweep instead of our own.
#include "hal/sim/random_rigs.hpp"

#include <algorithm>
#include <array>
#include <cmath>

#include "hal/sim/random.hpp"

namespace edgetrack::sim {

namespace {

struct ImageSize {
    int width_px;
    int height_px;
};

// Sensors of global-shutter cameras that such boards carry (OV9281, AR0234, IMX296, ...).
constexpr std::array<ImageSize, 6> kImageSizes{
    {{640, 480}, {752, 480}, {1280, 800}, {1280, 1024}, {1440, 1080}, {1600, 1300}}};

// The scene's centre seen from both cameras within this share of the half-width and half-height.
constexpr double kCentreInImageShare = 0.7;

bool seesSceneCentre(const RigSpec& spec) {
    const StereoRig rig = makeRig(spec);
    const Vec3 centre_rig_mm = rigFromScene(spec).apply(kSceneCentre_mm);
    for (int c = 0; c < 2; ++c) {
        const CameraIntrinsics& in = rig.camera(c).intrinsics();
        const std::optional<Vec2> pixel = rig.camera(c).project(centre_rig_mm);
        if (!pixel || std::abs(pixel->x() - in.cx_px) > kCentreInImageShare * 0.5 * in.width_px ||
            std::abs(pixel->y() - in.cy_px) > kCentreInImageShare * 0.5 * in.height_px)
            return false;
    }
    return true;
}

} // namespace

bool monotonicOverImage(const RigSpec& spec) {
    // The distorted radius r (1 + k1 r^2 + k2 r^4 + k3 r^6) must grow with r out to the corner
    // (with a margin, for camera 1's other focal length and principal point).
    const double corner = 1.05 * std::hypot(0.5 * spec.width_px, 0.5 * spec.height_px) /
                          (spec.focal_px * std::min(1.0, spec.focalRatio1));
    constexpr int kSteps = 200;
    for (int i = 0; i <= kSteps; ++i) {
        const double r = corner * i / kSteps;
        const double r2 = r * r;
        const double slope =
            1.0 + 3.0 * spec.k1 * r2 + 5.0 * spec.k2 * r2 * r2 + 7.0 * spec.k3 * r2 * r2 * r2;
        if (!(slope > 0.2))
            return false;
    }
    return true;
}

RigSpec randomRig(std::uint64_t seed) {
    if (seed == 0)
        return RigSpec{};
    Random random(seed * 0x9E3779B97F4A7C15ull + 0x51A7);
    for (;;) {
        RigSpec spec;
        const ImageSize size = kImageSizes[random.below(kImageSizes.size())];
        spec.width_px = size.width_px;
        spec.height_px = size.height_px;
        spec.focal_px = random.uniform(500.0, 1500.0);
        spec.focalRatio1 = random.uniform(0.98, 1.02);
        spec.baseline_mm = random.uniform(60.0, 400.0);
        spec.convergence_deg = random.uniform(0.0, 25.0);
        spec.viewingDistance_mm = random.uniform(450.0, 700.0);
        spec.rigRoll_deg = random.uniform(-20.0, 20.0);
        spec.cameraRoll_deg = {random.uniform(-2.0, 2.0), random.uniform(-2.0, 2.0)};
        spec.k1 = random.uniform(-0.4, 0.0);
        spec.k2 = random.uniform(0.0, 0.25);
        spec.k3 = random.uniform(-0.05, 0.02);
        spec.aperture_mm = random.uniform(0.6, 2.0);
        spec.focusDistance_mm = spec.viewingDistance_mm;
        if (monotonicOverImage(spec) && seesSceneCentre(spec))
            return spec;
    }
}

} // namespace edgetrack::sim
