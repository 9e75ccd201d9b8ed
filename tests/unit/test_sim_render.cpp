// Tests of the simulated cameras' images: blob centres, LED dependence, merging, determinism.
#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "core/pixel_stats.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"

using namespace edgetrack;
using namespace edgetrack::sim;

namespace {

struct Rendered {
    World world;
    FrameRenderer renderer;
    std::vector<std::uint8_t> image;
    Observation observation;

    Rendered(const char* scene, std::uint64_t seed)
        : world(*makeScene(scene, seed), seed)
        , renderer(world.scene().rig.width_px, world.scene().rig.height_px,
                   world.scene().background_dn, world.scene().noiseSigma_dn, seed)
        , image(
              static_cast<std::size_t>(world.scene().rig.width_px * world.scene().rig.height_px)) {}

    void render(std::uint64_t frame, int camera, double lit) {
        world.observe(frame, observation);
        renderer.render(image, world.scene().rig.width_px, camera, observation, lit, frame);
    }
    int width() const { return world.scene().rig.width_px; }
    int height() const { return world.scene().rig.height_px; }
};

// A reference centroid for the test: intensity above the background, weighted, in a window.
Vec2 centroid(const Rendered& r, const Vec2& around, double radius_px) {
    const int reach = static_cast<int>(radius_px + 4.0);
    const int cx = static_cast<int>(std::lround(around.x()));
    const int cy = static_cast<int>(std::lround(around.y()));
    double sum = 0.0;
    Vec2 weighted = Vec2::Zero();
    for (int y = cy - reach; y <= cy + reach; ++y)
        for (int x = cx - reach; x <= cx + reach; ++x) {
            const double w =
                std::max(0.0, r.image[static_cast<std::size_t>(y * r.width() + x)] - 30.0);
            sum += w;
            weighted += w * Vec2(x, y);
        }
    return weighted / sum;
}

} // namespace

TEST(SimRender, IsolatedBlobCentresMatchProjectedTruth) {
    Rendered r("cube_sphere", 4);
    double errorSum = 0.0;
    double worst = 0.0;
    int measured = 0;
    for (std::uint64_t frame = 0; frame < 300; frame += 15) {
        for (int camera = 0; camera < 2; ++camera) {
            r.render(frame, camera, 1.0);
            const auto c = static_cast<std::size_t>(camera);
            for (const MarkerView& m : r.observation.markers) {
                if (!m.visible[c])
                    continue;
                const Vec2 p = m.pixel[c];
                const double margin = m.radius_px[c] + 8.0;
                if (p.x() < margin || p.y() < margin || p.x() > r.width() - margin ||
                    p.y() > r.height() - margin)
                    continue;
                bool isolated = true;
                for (const MarkerView& other : r.observation.markers)
                    if (&other != &m && other.visible[c] &&
                        (other.pixel[c] - p).norm() < m.radius_px[c] + other.radius_px[c] + 8.0)
                        isolated = false;
                if (!isolated)
                    continue;
                const double error = (centroid(r, p, m.radius_px[c]) - p).norm();
                errorSum += error;
                worst = std::max(worst, error);
                ++measured;
            }
        }
    }
    ASSERT_GT(measured, 300);
    const double mean = errorSum / measured;
    RecordProperty("mean_error_px", std::to_string(mean));
    EXPECT_LT(mean, 0.1);
    EXPECT_LT(worst, 0.3);
}

TEST(SimRender, ASpheresImageIsTheConicOfItsTangentCone) {
    // A 6 mm sphere's image is an ellipse: across the radius from the image centre its
    // semi-axis is f R / z (z the depth), along it 1 / cos(theta) longer (theta off the axis);
    // then the distortion warps it. Its area-equivalent radius is then R / range times the
    // camera model's pixelsPerRadian(), whatever the distortion or where it lies.
    Scene scene = *makeScene("slow_cube", 1);
    for (const bool distorted : {false, true}) {
        if (!distorted)
            scene.rig.k1 = scene.rig.k2 = 0.0;
        const World world(scene, 1);
        const CameraModel& camera = world.rig().camera(0);
        Observation obs;
        std::size_t seen = 0;
        for (std::uint64_t frame = 0; frame < 400; frame += 20) {
            world.observe(frame, obs);
            for (const MarkerView& m : obs.markers) {
                if (!m.visible[0])
                    continue;
                ++seen;
                const Vec3 p = camera.toCamera(m.position_rig_mm);
                const Vec3 toMarker = m.position_rig_mm - camera.centre_rig_mm();
                EXPECT_NEAR(m.radius_px[0],
                            3.0 * camera.pixelsPerRadian(toMarker) / toMarker.norm(),
                            2e-3 * m.radius_px[0]);
                if (distorted)
                    continue;
                const Eigen::JacobiSVD<Eigen::Matrix2d> axes(m.shape_px[0]);
                const double cosTheta = p.z() / p.norm();
                EXPECT_NEAR(axes.singularValues()(1), 910.0 * 3.0 / p.z(), 2e-3 * m.radius_px[0]);
                EXPECT_NEAR(axes.singularValues()(0) * cosTheta, 910.0 * 3.0 / p.z(),
                            2e-3 * m.radius_px[0]);
            }
        }
        EXPECT_GT(seen, 100u);
    }
}

TEST(SimRender, FrameExposedWithTheLedOffIsDark) {
    Rendered r("two_cubes", 2);
    r.render(10, 0, 0.0);
    const PixelStats dark = measurePixels(r.image, 100);
    EXPECT_EQ(dark.brightCount, 0u);
    EXPECT_LT(dark.maximum, 40);

    r.render(10, 0, 1.0);
    const PixelStats lit = measurePixels(r.image, 100);
    EXPECT_GT(lit.brightCount, 500u);
    EXPECT_EQ(lit.maximum, 255); // near markers saturate
}

TEST(SimRender, LedOffStillShowsAmbientGlints) {
    Rendered r("stress", 2);
    r.render(10, 0, 0.0);
    EXPECT_GT(measurePixels(r.image, 100).brightCount, 0u);
    // ...but no marker: every marker centre is dark.
    for (const MarkerView& m : r.observation.markers) {
        if (!m.visible[0])
            continue;
        {
            const Vec2 p = m.pixel[0];
            const std::size_t at =
                static_cast<std::size_t>(std::lround(p.y())) * static_cast<std::size_t>(r.width()) +
                static_cast<std::size_t>(std::lround(p.x()));
            bool nearGlint = false;
            for (const Glint& g : r.observation.glints[0])
                nearGlint = nearGlint || (g.centre_px - p).norm() < g.radiusMajor_px + 3.0;
            if (!nearGlint) {
                EXPECT_LT(r.image[at], 40);
            }
        }
    }
}

TEST(SimRender, SameSeedSameBytesOtherSeedOtherBytes) {
    Rendered a("crowd", 7), b("crowd", 7), c("crowd", 8);
    a.render(33, 1, 1.0);
    b.render(33, 1, 1.0);
    c.render(33, 1, 1.0);
    EXPECT_EQ(a.image, b.image);
    EXPECT_NE(a.image, c.image);
}

TEST(SimRender, NoiseHasTheConfiguredSigma) {
    Rendered r("slow_cube", 3);
    r.render(0, 0, 0.0);
    double sum = 0.0, squares = 0.0;
    for (std::uint8_t p : r.image) {
        sum += p;
        squares += static_cast<double>(p) * p;
    }
    const double n = static_cast<double>(r.image.size());
    const double mean = sum / n;
    EXPECT_NEAR(mean, r.world.scene().background_dn, 0.2);
    EXPECT_NEAR(std::sqrt(squares / n - mean * mean), r.world.scene().noiseSigma_dn, 0.2);
}

TEST(SimLevels, OverlappingMarkersMergeIntoOneBlob) {
    Observation obs;
    MarkerView a, b, far;
    a.visible = {true, true};
    a.setDisc(0, Vec2(100, 100), 4.0);
    a.setDisc(1, Vec2(90, 100), 4.0);
    a.peak_dn = {1000, 1000};
    b = a;
    b.setDisc(0, Vec2(105, 100), 4.0); // touches a in camera 0 only
    b.setDisc(1, Vec2(140, 100), 4.0);
    MarkerView faint = a;
    faint.setDisc(0, Vec2(600, 500), 4.0);
    faint.setDisc(1, Vec2(600, 500), 4.0);
    faint.peak_dn = {50, 50}; // below the detection level: no blob
    far = a;
    far.setDisc(0, Vec2(400, 300), 4.0);
    far.setDisc(1, Vec2(380, 300), 4.0);
    obs.markers = {a, b, far, faint};
    LevelNoise exact;
    exact.blobCentreSigma_px = 0.0;
    exact.pointSigma_mm = 0.0;
    Random random(1);
    std::vector<SimBlob> blobs;
    blobsFromObservation(obs, 0, exact, random, blobs);
    ASSERT_EQ(blobs.size(), 2u);
    EXPECT_NEAR(blobs[0].centre_px.x(), 102.5, 1e-9);
    blobsFromObservation(obs, 1, exact, random, blobs);
    EXPECT_EQ(blobs.size(), 3u);

    std::vector<Vec3> points;
    pointsFromObservation(obs, exact, random, points);
    EXPECT_EQ(points.size(), 1u); // only the marker merged in neither camera
}

TEST(SimLevels, StreaksAreNotReportedAsBlobs) {
    Observation obs;
    Glint round, streak;
    round.centre_px = {50, 50};
    streak.centre_px = {300, 300};
    streak.radiusMajor_px = 12.0;
    streak.radiusMinor_px = 1.5;
    obs.glints[0] = {round, streak};
    Random random(1);
    std::vector<SimBlob> blobs;
    blobsFromObservation(obs, 0, LevelNoise{}, random, blobs);
    ASSERT_EQ(blobs.size(), 1u);
    EXPECT_NEAR(blobs[0].centre_px.x(), 50.0, 0.5);
}

TEST(SimRender, AMarkerAtTheEdgeOfANearerHandIsCutByIt) {
    // One marker whose centre a hand leaves in view, its disc reaching 4 px under the hand's
    // edge: what lies under the hand is dark, the rest of the disc lit. The same hand behind the
    // marker hides nothing of it.
    FrameRenderer renderer(320, 240, 10.0, 0.0, 1);
    std::vector<std::uint8_t> image(320 * 240);
    Observation observation;
    MarkerView marker;
    marker.visible = {true, true};
    marker.setDisc(0, {100.0, 100.0}, 8.0);
    marker.peak_dn[0] = 1000.0;
    marker.depth_mm[0] = 500.0;
    observation.markers.push_back(marker);
    const auto at = [&](int x, int y) { return image[static_cast<std::size_t>(y * 320 + x)]; };
    // The hand's edge passes 4 px right of the marker's centre.
    observation.occluders[0].push_back({Vec2(100.0 + 4.0 + 30.0, 100.0), 30.0, 300.0});
    renderer.render(image, 320, 0, observation, 1.0, 0);
    EXPECT_EQ(at(100, 100), 255);
    EXPECT_EQ(at(96, 100), 255);
    EXPECT_LT(at(106, 100), 30) << "under the hand";
    EXPECT_LT(at(107, 97), 30) << "under the hand";
    observation.occluders[0].back().depth_mm = 600.0;
    renderer.render(image, 320, 0, observation, 1.0, 0);
    EXPECT_EQ(at(106, 100), 255) << "the hand is behind the marker";
}
