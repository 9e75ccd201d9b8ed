// Tests of the marker front end: images or blobs in, the rig's 3D markers out, without allocating.
#include <algorithm>
#include <vector>

#include <gtest/gtest.h>

#include "core/marker_pipeline.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/world.hpp"
#include "tests/support/alloc_guard.hpp"
#include "tests/unit/rig_fixtures.hpp"

namespace edgetrack {
namespace {

/// The two cubes' rendered images, frame after frame.
class RenderedFrames {
public:
    RenderedFrames()
        : world_(*sim::makeScene("two_cubes", 4), 4)
        , renderer_(width(), height(), world_.scene().background_dn, world_.scene().noiseSigma_dn,
                    4)
        , images_{std::vector<std::uint8_t>(pixels()), std::vector<std::uint8_t>(pixels())} {}

    void render(std::uint64_t frame) {
        world_.observe(frame, observation_);
        for (int c = 0; c < 2; ++c)
            renderer_.render(images_[static_cast<std::size_t>(c)], width(), c, observation_, 1.0,
                             frame);
    }
    const std::uint8_t* image(int camera) const {
        return images_[static_cast<std::size_t>(camera)].data();
    }
    int width() const { return world_.scene().rig.width_px; }
    int height() const { return world_.scene().rig.height_px; }
    const sim::World& world() const { return world_; }
    const sim::Observation& observation() const { return observation_; }

private:
    std::size_t pixels() const { return static_cast<std::size_t>(width() * height()); }

    sim::World world_;
    sim::FrameRenderer renderer_;
    sim::Observation observation_;
    std::vector<std::uint8_t> images_[2];
};

TEST(MarkerPipeline, FindsTheMarkersBothCamerasSeeApart) {
    RenderedFrames frames;
    MarkerPipeline pipeline(frames.world().rig(), MarkerPipelineConfig{});
    ASSERT_TRUE(pipeline.isValid()) << pipeline.error();
    std::size_t seen = 0, found = 0;
    std::vector<int> visible;
    for (std::uint64_t f = 0; f < 20; ++f) {
        frames.render(f * 7);
        const std::span<const Vec3> points =
            pipeline.process(frames.image(0), frames.width(), frames.image(1), frames.width());
        ASSERT_EQ(points.size(), pipeline.markers().size());
        sim::separatelyVisible(frames.observation(), visible);
        for (const int index : visible) {
            if (static_cast<std::size_t>(index) >= frames.observation().markers.size())
                continue; // a spurious reflection
            const sim::MarkerView& m =
                frames.observation().markers[static_cast<std::size_t>(index)];
            ++seen;
            found += std::any_of(points.begin(), points.end(), [&](const Vec3& p) {
                return (p - m.position_rig_mm).norm() < 1.0;
            });
        }
    }
    ASSERT_GT(seen, 100u);
    EXPECT_GE(static_cast<double>(found), 0.99 * static_cast<double>(seen));
}

TEST(MarkerPipeline, BlobsGivenFromOutsideGiveTheSameMarkers) {
    RenderedFrames frames;
    MarkerPipeline fromImages(frames.world().rig(), MarkerPipelineConfig{});
    MarkerPipeline fromBlobs(frames.world().rig(), MarkerPipelineConfig{});
    frames.render(11);
    fromImages.process(frames.image(0), frames.width(), frames.image(1), frames.width());
    for (int c = 0; c < 2; ++c) {
        fromBlobs.blobs(c).clear();
        for (const Blob& b : fromImages.blobs(c))
            fromBlobs.blobs(c).push_back(b);
    }
    fromBlobs.matchStereo();
    ASSERT_GT(fromImages.points_rig_mm().size(), 6u);
    EXPECT_TRUE(std::equal(fromImages.points_rig_mm().begin(), fromImages.points_rig_mm().end(),
                           fromBlobs.points_rig_mm().begin(), fromBlobs.points_rig_mm().end()));
}

TEST(MarkerPipeline, CountsWhatDoesNotFitItsCapacities) {
    RenderedFrames frames;
    MarkerPipelineConfig config;
    config.blobs.maxBlobs = 4;
    config.stereo.maxMarkers = 3;
    MarkerPipeline pipeline(frames.world().rig(), config);
    ASSERT_TRUE(pipeline.isValid()) << pipeline.error();
    frames.render(3);
    pipeline.process(frames.image(0), frames.width(), frames.image(1), frames.width());
    EXPECT_EQ(pipeline.blobs(0).size(), 4u);
    EXPECT_LE(pipeline.points_rig_mm().size(), 3u);
    const MarkerPipelineCounters counters = pipeline.counters();
    EXPECT_GT(counters.blobOverflow, 0u);
    EXPECT_EQ(counters.blobOverflow, pipeline.detector(0).counters().blobOverflow +
                                         pipeline.detector(1).counters().blobOverflow);
}

TEST(MarkerPipeline, RefusesCamerasOfDifferentSizes) {
    StereoRig rig = test::desktopRig();
    CameraIntrinsics small = rig.camera(1).intrinsics();
    small.width_px = 640;
    const StereoRig mixed(rig.camera(0), CameraModel(small, rig.camera(1).extrinsics()));
    const MarkerPipeline pipeline(mixed, MarkerPipelineConfig{});
    EXPECT_FALSE(pipeline.isValid());
    EXPECT_NE(std::string(pipeline.error()).find("same image size"), std::string::npos);
}

TEST(MarkerPipeline, AFrameAllocatesNothing) {
    RenderedFrames frames;
    MarkerPipeline pipeline(frames.world().rig(), MarkerPipelineConfig{});
    frames.render(0);
    pipeline.process(frames.image(0), frames.width(), frames.image(1), frames.width());
    const std::uint64_t allocations = test::countAllocations([&] {
        for (int i = 0; i < 50; ++i)
            pipeline.process(frames.image(0), frames.width(), frames.image(1), frames.width());
    });
    EXPECT_EQ(allocations, 0u);
}

} // namespace
} // namespace edgetrack
