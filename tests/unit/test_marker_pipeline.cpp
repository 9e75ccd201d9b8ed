// Tests of the marker front end: images or blobs in, the rig's 3D markers out, without allocating.
#include <algorithm>
#include <numbers>
#include <numeric>
#include <optional>
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

TEST(MarkerPipeline, SplitsABlobOfTwoMarkersTheOtherCameraSeesApart) {
    // Marker b lies 70 mm behind marker a, on the ray of camera 1 that passes 4 px beside a's
    // image, and looks smaller: camera 1 sees one blob, a's disc with b's peeking out 1.5 px at
    // its side, camera 0 two blobs 15 px apart. Stereo alone pairs at most one of them; going
    // back to camera 1's image it splits the blob on the epipolar lines of camera 0's two blobs
    // and finds both. b's centre, from 10 outline points pushed out by a's light, is 0.2 px off
    // in camera 1, 0.8 mm in depth at 670 mm.
    const StereoRig rig = test::desktopRig();
    const int width = rig.camera(0).intrinsics().width_px;
    const int height = rig.camera(0).intrinsics().height_px;
    const Vec3 a_rig_mm(30.0, -20.0, 600.0);
    const std::optional<Vec2> a1 = rig.camera(1).project(a_rig_mm);
    ASSERT_TRUE(a1);
    const std::optional<Ray> ray = rig.camera(1).ray(*a1 + Vec2(4.0, 0.5));
    ASSERT_TRUE(ray);
    const double range_mm = (670.0 - ray->origin_rig_mm.z()) / ray->direction_rig.z();
    const Vec3 b_rig_mm = ray->origin_rig_mm + range_mm * ray->direction_rig;

    sim::Observation observation;
    std::vector<std::uint8_t> images[2];
    const sim::FrameRenderer renderer(width, height, 10.0, 0.0, 1);
    for (int c = 0; c < 2; ++c) {
        const auto camera = static_cast<std::size_t>(c);
        for (const Vec3& marker : {a_rig_mm, b_rig_mm}) {
            sim::Glint glint;
            glint.centre_px = *rig.camera(c).project(marker);
            glint.radiusMajor_px = glint.radiusMinor_px = marker == a_rig_mm ? 7.0 : 4.5;
            glint.peak_dn = 900.0;
            observation.glints[camera].push_back(glint);
        }
        images[camera].assign(static_cast<std::size_t>(width * height), 0);
        renderer.render(images[camera], width, c, observation, 1.0, 0);
    }
    MarkerPipeline pipeline(rig, MarkerPipelineConfig{});
    ASSERT_TRUE(pipeline.isValid()) << pipeline.error();
    for (int c = 0; c < 2; ++c)
        pipeline.detectBlobs(c, images[static_cast<std::size_t>(c)].data(), width);
    ASSERT_EQ(pipeline.blobs(0).size(), 2u);
    ASSERT_EQ(pipeline.blobs(1).size(), 1u) << "one blob in camera 1 to detection alone";
    const auto found = [&](const Vec3& marker) {
        return std::any_of(pipeline.points_rig_mm().begin(), pipeline.points_rig_mm().end(),
                           [&](const Vec3& p) { return (p - marker).norm() < 1.0; });
    };
    pipeline.matchStereo();
    EXPECT_FALSE(found(a_rig_mm) && found(b_rig_mm)) << "stereo alone";

    pipeline.matchStereo(StereoMethod::Svd,
                         {{{images[0].data(), width}, {images[1].data(), width}}});
    EXPECT_TRUE(found(a_rig_mm));
    EXPECT_TRUE(found(b_rig_mm));
    EXPECT_EQ(pipeline.points_rig_mm().size(), 2u);
    EXPECT_EQ(pipeline.blobs(1).size(), 2u);
    EXPECT_EQ(pipeline.counters().splitOnLines, 1u);
    for (const Blob& blob : pipeline.blobs(1))
        EXPECT_TRUE(blob.split);

    // Again and again, without allocating.
    const std::uint64_t allocations = test::countAllocations([&] {
        for (int i = 0; i < 20; ++i) {
            for (int c = 0; c < 2; ++c)
                pipeline.detectBlobs(c, images[static_cast<std::size_t>(c)].data(), width);
            pipeline.matchStereo(StereoMethod::Svd,
                                 {{{images[0].data(), width}, {images[1].data(), width}}});
        }
    });
    EXPECT_EQ(allocations, 0u);
    EXPECT_EQ(pipeline.counters().splitOnLines, 21u);
}

/// The blob of a 10 mm sphere at \a point_rig_mm in \a camera of \a rig, moved \a down_px rows.
Blob sphereBlob(const StereoRig& rig, int camera, const Vec3& point_rig_mm, double down_px = 0.0) {
    const CameraModel& model = rig.camera(camera);
    const Vec3 across = (point_rig_mm - model.centre_rig_mm()).cross(Vec3::UnitY()).normalized();
    const Vec2 pixel = *model.project(point_rig_mm);
    const double radius_px = (*model.project(point_rig_mm + 5.0 * across) - pixel).norm();
    Blob blob;
    blob.centre_px = pixel + Vec2(0.0, down_px);
    blob.area_px = static_cast<float>(std::numbers::pi * radius_px * radius_px);
    return blob;
}

/// What runAlongALine() saw: points more than 1 mm from every true marker (before and after the
/// second marker appears), and stereo pairs changed for continuity.
struct ContinuityRun {
    int ghostsBefore = 0;
    int ghostsAfter = 0;
    std::uint64_t changed = 0;
};

/// 50 frames of the desktop rig in which marker A moves along x at 480 mm; from frame 30 a
/// second marker appears. \a fill(pipeline, a, frame) puts the frame's blobs into the pipeline
/// (cleared before) and returns the true markers (rig frame, mm).
template <typename Fill>
ContinuityRun runAlongALine(double continuity_mm, Fill fill) {
    MarkerPipelineConfig config;
    // Sizes are left out: the second marker's blob has A's size, so its size tells nothing.
    config.stereo.sizeSigma = 0.0;
    config.stereo.continuity_mm = continuity_mm;
    MarkerPipeline pipeline(test::desktopRig(), config);
    ContinuityRun run;
    for (int frame = 0; frame < 50; ++frame) {
        const Vec3 a(40.0 + 0.5 * frame, 10.0, 480.0);
        pipeline.blobs(0).clear();
        pipeline.blobs(1).clear();
        const std::vector<Vec3> truth = fill(pipeline, a, frame);
        pipeline.matchStereo();
        for (const Vec3& point : pipeline.points_rig_mm()) {
            double nearest_mm = 1e9;
            for (const Vec3& marker : truth)
                nearest_mm = std::min(nearest_mm, (point - marker).norm());
            (frame < 30 ? run.ghostsBefore : run.ghostsAfter) += nearest_mm > 1.0 ? 1 : 0;
        }
    }
    run.changed = pipeline.counters().pairsForContinuity;
    return run;
}

TEST(MarkerPipeline, KeepsAMarkersPartnerWhenAnotherMarkerComesIntoViewOnItsLine) {
    // Marker A moves along, seen by both cameras; camera 1 sees it 1.2 px off its epipolar line
    // (a rig calibration a little off). From frame 30, marker B, hidden from camera 0, comes into
    // camera 1's view exactly on A's epipolar line: alone, the correspondence prefers B's blob for
    // A's (the nearer the line, the higher the proximity) and makes a ghost at neither marker.
    const StereoRig rig = test::desktopRig();
    const Vec3 c0 = rig.camera(0).centre_rig_mm();
    const Vec3 c1 = rig.camera(1).centre_rig_mm();
    auto fill = [&](MarkerPipeline& pipeline, const Vec3& a, int frame) {
        pipeline.blobs(0).push_back(sphereBlob(rig, 0, a));
        pipeline.blobs(1).push_back(sphereBlob(rig, 1, a, 1.2));
        const Vec3 b = a + 30.0 * (c1 - c0).normalized() + 120.0 * (a - c0).normalized();
        if (frame >= 30) {
            Blob ofB = sphereBlob(rig, 1, b);
            ofB.area_px = pipeline.blobs(1)[0].area_px;
            pipeline.blobs(1).push_back(ofB);
        }
        return std::vector<Vec3>{a, b};
    };
    const ContinuityRun without = runAlongALine(0.0, fill);
    EXPECT_EQ(without.ghostsBefore, 0);
    EXPECT_EQ(without.ghostsAfter, 20); // the scene does make the ghost
    const ContinuityRun with = runAlongALine(3.0, fill);
    EXPECT_EQ(with.ghostsBefore + with.ghostsAfter, 0);
    EXPECT_EQ(with.changed, 20U);
}

TEST(MarkerPipeline, PairsTwoMarkersOnOneLineByTheMarkerThatWasThere) {
    // Marker A moves along, seen by both cameras. From frame 30, marker C comes into view beside
    // it, on the same epipolar plane, 3 mm across and 40 mm deeper: in both images C's blob lies
    // on A's line near A's, and the correspondence pairs the four blobs crosswise (the
    // neighbourhood term finds each blob's neighbour where the crossed pair puts it), two ghosts
    // at neither marker. The frame before has A where its own pair puts it.
    const StereoRig rig = test::desktopRig();
    const Vec3 c0 = rig.camera(0).centre_rig_mm();
    const Vec3 c1 = rig.camera(1).centre_rig_mm();
    auto fill = [&](MarkerPipeline& pipeline, const Vec3& a, int frame) {
        const Vec3 c = a - 3.0 * (c1 - c0).normalized() + 40.0 * (a - c0).normalized();
        for (int camera = 0; camera < 2; ++camera) {
            pipeline.blobs(camera).push_back(sphereBlob(rig, camera, a));
            if (frame >= 30)
                pipeline.blobs(camera).push_back(sphereBlob(rig, camera, c));
        }
        return std::vector<Vec3>{a, c};
    };
    const ContinuityRun without = runAlongALine(0.0, fill);
    EXPECT_EQ(without.ghostsBefore, 0);
    EXPECT_GT(without.ghostsAfter, 20); // the scene does make ghosts
    const ContinuityRun with = runAlongALine(3.0, fill);
    EXPECT_EQ(with.ghostsBefore + with.ghostsAfter, 0);
    // Both pairs changed in each of the 20 frames: the correspondence crosses them anew.
    EXPECT_EQ(with.changed, 40U);
}

TEST(MarkerPipeline, UndoesCrosswisePairsWhoseGhostWentOnFromAFrameBefore) {
    // Markers A and C move along together, C 20 mm aside of A until frame 15 and then sliding,
    // by frame 25, onto A's epipolar plane, 3 mm across and 40 mm deeper (as above). In frame 30
    // camera 0 sees only A and camera 1 only C (a hand in each view): their one pair is a ghost
    // at neither marker. From frame 31 both cameras see both, and the correspondence pairs them
    // crosswise: one ghost goes on from the ghost of frame 30, the other from nothing, while the
    // two markers' own pairs go on from A and C, missing for a frame, within half a millimetre.
    const StereoRig rig = test::desktopRig();
    const Vec3 c0 = rig.camera(0).centre_rig_mm();
    const Vec3 c1 = rig.camera(1).centre_rig_mm();
    auto fill = [&](MarkerPipeline& pipeline, const Vec3& a, int frame) {
        const double sliding = std::clamp((25.0 - frame) / 10.0, 0.0, 1.0);
        const Vec3 c = a - 3.0 * (c1 - c0).normalized() + 40.0 * (a - c0).normalized() +
                       Vec3(0.0, 20.0 * sliding, 0.0);
        const bool handsIn = frame == 30;
        pipeline.blobs(0).push_back(sphereBlob(rig, 0, a));
        pipeline.blobs(1).push_back(sphereBlob(rig, 1, c));
        if (!handsIn) {
            pipeline.blobs(0).push_back(sphereBlob(rig, 0, c));
            pipeline.blobs(1).push_back(sphereBlob(rig, 1, a));
        }
        return handsIn ? std::vector<Vec3>{} : std::vector<Vec3>{a, c};
    };
    const ContinuityRun run = runAlongALine(3.0, fill);
    EXPECT_EQ(run.ghostsBefore, 0);
    // Only frame 30's ghost, the one pair its images allow. Exchanged only for a marker that
    // continued nothing, the crossed pairs stayed: 39 ghosts, both in every frame from 31 on.
    EXPECT_EQ(run.ghostsAfter, 1);
}

/// What runHiddenInCamera0() saw in the ten frames marker A hides: frames in which a point lay
/// within 0.5 mm of A, points more than 1 mm from both markers, and markers carried.
struct HiddenRun {
    int foundA = 0;
    int ghosts = 0;
    std::uint64_t carried = 0;
};

/// 50 frames of the desktop rig in which markers A and B (12 mm apart) move along x at 480 mm.
/// In frames 30 to 39 camera 0 sees A inside B's disc: one blob for both, given as B's part of a
/// blob split into discs (\a merged) or as B's own round blob (not merged), bounds and all.
/// Before that, A is in neither image for the \a goneFrames frames up to frame 28.
HiddenRun runHiddenInCamera0(std::uint32_t maxCarriedFrames, bool merged, int goneFrames = 0) {
    const StereoRig rig = test::desktopRig();
    MarkerPipelineConfig config;
    config.stereo.maxCarriedFrames = maxCarriedFrames;
    MarkerPipeline pipeline(rig, config);
    HiddenRun run;
    for (int frame = 0; frame < 50; ++frame) {
        const Vec3 a(40.0 + 0.5 * frame, 10.0, 480.0);
        const Vec3 b = a + Vec3(0.0, 12.0, 0.0);
        const bool hidden = frame >= 30 && frame < 40;
        const bool gone = frame >= 29 - goneFrames && frame < 29;
        pipeline.blobs(0).clear();
        pipeline.blobs(1).clear();
        for (int camera = 0; camera < 2; ++camera) {
            Blob ofB = sphereBlob(rig, camera, b);
            if (gone) {
                // A's blob is missing from both images.
            } else if (camera == 0 && hidden) {
                // The bounds of both discs together.
                const Blob ofA = sphereBlob(rig, 0, a);
                const double r = ofA.discRadius_px() + 1.0;
                const auto bound = [](double v) { return static_cast<std::uint16_t>(v); };
                ofB.left = bound(std::min(ofA.centre_px.x(), ofB.centre_px.x()) - r);
                ofB.right = bound(std::max(ofA.centre_px.x(), ofB.centre_px.x()) + r);
                ofB.top = bound(std::min(ofA.centre_px.y(), ofB.centre_px.y()) - r);
                ofB.bottom = bound(std::max(ofA.centre_px.y(), ofB.centre_px.y()) + r);
                ofB.split = merged;
            } else {
                pipeline.blobs(camera).push_back(sphereBlob(rig, camera, a));
            }
            pipeline.blobs(camera).push_back(ofB);
        }
        pipeline.matchStereo();
        if (!hidden)
            continue;
        bool foundA = false;
        for (const Vec3& point : pipeline.points_rig_mm()) {
            foundA = foundA || (point - a).norm() < 0.5;
            run.ghosts += (point - a).norm() > 1.0 && (point - b).norm() > 1.0 ? 1 : 0;
        }
        run.foundA += foundA ? 1 : 0;
    }
    run.carried = pipeline.counters().carriedMarkers;
    return run;
}

TEST(MarkerPipeline, CarriesAMarkerHiddenInAnothersBlobInOneImage) {
    const HiddenRun off = runHiddenInCamera0(0, true);
    EXPECT_EQ(off.foundA, 0); // the scene does hide A from stereo
    const HiddenRun on = runHiddenInCamera0(20, true);
    EXPECT_EQ(on.foundA, 10);
    EXPECT_EQ(on.carried, 10U);
    EXPECT_EQ(on.ghosts, 0);
    // Carried for at most maxCarriedFrames in a row.
    const HiddenRun short_ = runHiddenInCamera0(4, true);
    EXPECT_EQ(short_.foundA, 4);
    EXPECT_EQ(short_.carried, 4U);
}

TEST(MarkerPipeline, AMarkerGoneFromBothImagesForAFewFramesKeepsItsHistory) {
    // A is in neither image in frames 26-28: found again in frame 29, one frame before it hides
    // in camera 0, it goes on with the age it had and is carried.
    const HiddenRun run = runHiddenInCamera0(20, true, 3);
    EXPECT_EQ(run.foundA, 10);
    EXPECT_EQ(run.carried, 10U);
    EXPECT_EQ(run.ghosts, 0);
    // Gone for longer than the pipeline remembers (5 frames): found again with no history, and
    // not carried.
    const HiddenRun longer = runHiddenInCamera0(20, true, 9);
    EXPECT_EQ(longer.foundA, 0);
    EXPECT_EQ(longer.carried, 0U);
}

TEST(MarkerPipeline, DoesNotCarryAMarkerWhereTheOtherImageShowsOneDisc) {
    // Where A should hide, camera 0 has B's round blob only: nothing says A is in it.
    const HiddenRun run = runHiddenInCamera0(20, false);
    EXPECT_EQ(run.foundA, 0);
    EXPECT_EQ(run.carried, 0U);
}

/// 40 frames of the desktop rig in which marker A moves along x at 480 mm and marker B, as
/// large and 20 mm nearer camera 0, slides in front of A by frame 30, to \a aside_mm off camera
/// 0's ray through A, and stays there to frame 39. In those ten frames camera 0 has B's round
/// blob alone; camera 1 sees both apart. Returns the frames of those ten in which a point lay
/// within 0.5 mm of A.
int framesFoundBehindARoundBlob(double aside_mm) {
    const StereoRig rig = test::desktopRig();
    MarkerPipeline pipeline(rig, MarkerPipelineConfig{});
    const Vec3 c0 = rig.camera(0).centre_rig_mm();
    int found = 0;
    for (int frame = 0; frame < 40; ++frame) {
        const Vec3 a(40.0 + 0.5 * frame, 10.0, 480.0);
        const Vec3 onRay = a - 20.0 * (a - c0).normalized();
        const double sliding = std::clamp((30.0 - frame) / 10.0, 0.0, 1.0);
        const Vec3 b = onRay + Vec3(0.0, aside_mm + (12.0 - aside_mm) * sliding, 0.0);
        const bool hidden = frame >= 30;
        for (int camera = 0; camera < 2; ++camera) {
            pipeline.blobs(camera).clear();
            if (!(camera == 0 && hidden))
                pipeline.blobs(camera).push_back(sphereBlob(rig, camera, a));
            pipeline.blobs(camera).push_back(sphereBlob(rig, camera, b));
        }
        pipeline.matchStereo();
        if (!hidden)
            continue;
        bool foundA = false;
        for (const Vec3& point : pipeline.points_rig_mm())
            foundA = foundA || (point - a).norm() < 0.5;
        found += foundA ? 1 : 0;
    }
    return found;
}

TEST(MarkerPipeline, CarriesAMarkerHiddenBehindANearerMarkersRoundBlob) {
    // A quarter and half a millimetre aside (0.5 and 0.9 px), A's disc lies inside B's but for
    // half a pixel: one round blob, B's, which nothing marks as merged. B is nearer, so A may be
    // behind it; A is carried on its own disc in camera 1 in all ten frames (in none before the
    // nearer marker's round blob counted as a cover).
    EXPECT_EQ(framesFoundBehindARoundBlob(0.25), 10);
    EXPECT_EQ(framesFoundBehindARoundBlob(0.5), 10);
    // A millimetre and a half aside, A's disc would stick out of B's by 2.4 px, which the image
    // does not show: A has gone, and is not carried.
    EXPECT_EQ(framesFoundBehindARoundBlob(1.5), 0);
}

/// What runClosingCluster() saw in the frames its markers' discs lie far over each other in both
/// images: frames in which each was found within 0.5 mm, and points more than 1 mm from all.
struct ClusterRun {
    int framesMerged = 0;
    std::vector<int> found;
    int ghosts = 0;
    std::uint64_t foundWhereExpected = 0;
    /// Allocations in all the frames' process().
    std::uint64_t allocations = 0;
};

/// 60 frames of the desktop rig, rendered: 10 mm markers at 480 mm placed at \a offsets_mm (in
/// the image plane) from a point that drifts along, ten times as far apart up to frame 10,
/// closing in to those offsets by frame 30, staying so to frame 45 and parting again.
ClusterRun runClosingCluster(bool seek, const std::vector<Vec3>& offsets_mm) {
    const StereoRig rig = test::desktopRig();
    MarkerPipelineConfig config;
    config.stereo.seekExpectedMarkers = seek;
    MarkerPipeline pipeline(rig, config);
    const int width = rig.camera(0).intrinsics().width_px;
    const int height = rig.camera(0).intrinsics().height_px;
    const sim::FrameRenderer renderer(width, height, 10.0, 2.0, 7);
    std::vector<std::uint8_t> images[2] = {
        std::vector<std::uint8_t>(static_cast<std::size_t>(width * height)),
        std::vector<std::uint8_t>(static_cast<std::size_t>(width * height))};
    ClusterRun run;
    run.found.assign(offsets_mm.size(), 0);
    for (int frame = 0; frame < 60; ++frame) {
        const double spread = frame < 10   ? 10.0
                              : frame < 30 ? 10.0 - 9.0 * (frame - 10) / 20.0
                              : frame < 45 ? 1.0
                                           : 1.0 + 0.5 * (frame - 45);
        const Vec3 centre(-20.0 + 0.3 * frame, 15.0 + 0.2 * frame, 480.0);
        sim::Observation observation;
        std::vector<Vec3> truth;
        for (const Vec3& offset : offsets_mm) {
            const Vec3 p = centre + spread * offset;
            truth.push_back(p);
            sim::MarkerView view;
            view.position_rig_mm = p;
            for (int c = 0; c < 2; ++c) {
                const auto camera = static_cast<std::size_t>(c);
                const Vec3 inCamera = rig.camera(c).toCamera(p);
                view.visible[camera] = true;
                view.setDisc(c, *rig.camera(c).project(p),
                             rig.camera(c).intrinsics().fx_px * 5.0 / inCamera.z());
                view.peak_dn[camera] = 900.0;
                view.depth_mm[camera] = inCamera.z();
            }
            observation.markers.push_back(view);
        }
        for (int c = 0; c < 2; ++c) {
            const auto camera = static_cast<std::size_t>(c);
            renderer.render(images[camera], width, c, observation, 1.0,
                            static_cast<std::uint64_t>(frame));
        }
        std::span<const Vec3> points;
        run.allocations += test::countAllocations(
            [&] { points = pipeline.process(images[0].data(), width, images[1].data(), width); });
        if (frame < 32 || frame >= 45)
            continue;
        ++run.framesMerged;
        for (const Vec3& p : points) {
            bool near = false;
            for (std::size_t m = 0; m < truth.size(); ++m) {
                run.found[m] += (p - truth[m]).norm() < 0.5 ? 1 : 0;
                near = near || (p - truth[m]).norm() <= 1.0;
            }
            run.ghosts += near ? 0 : 1;
        }
    }
    run.foundWhereExpected = pipeline.counters().markersSplitWhereExpected;
    return run;
}

TEST(MarkerPipeline, FindsMarkersOfAClusterWhereTheyWereExpected) {
    // Three markers closing in to a triangle of 4.5 mm sides, and four to a square of 3.5 mm
    // sides (0.45 and 0.35 diameters): in both images one round blob, which detection takes as
    // one disc and stereo as one marker in the middle of them all. Sought where each was
    // expected, the discs are found in that blob, and the marker of the middle goes.
    const std::vector<Vec3> triangle{Vec3(0.0, 0.0, 0.0), Vec3(4.5, 0.0, 0.0),
                                     Vec3(2.25, 3.9, 0.0)};
    const std::vector<Vec3> square{Vec3(0.0, 0.0, 0.0), Vec3(3.5, 0.0, 0.0), Vec3(0.0, 3.5, 0.0),
                                   Vec3(3.5, 3.5, 0.0)};
    for (const std::vector<Vec3>* cluster : {&triangle, &square}) {
        const ClusterRun without = runClosingCluster(false, *cluster);
        EXPECT_EQ(without.framesMerged, 13);
        EXPECT_EQ(std::accumulate(without.found.begin(), without.found.end(), 0), 0)
            << "the scene does merge the markers";
        EXPECT_EQ(without.ghosts, 13);
        const ClusterRun with = runClosingCluster(true, *cluster);
        for (std::size_t m = 0; m < cluster->size(); ++m)
            EXPECT_GE(with.found[m], 10) << cluster->size() << " markers, marker " << m;
        EXPECT_EQ(with.ghosts, 0);
        EXPECT_GE(with.foundWhereExpected, 30U);
        EXPECT_EQ(with.allocations, 0U);
    }
}

TEST(MarkerPipeline, CarriesAMarkerOnADiscFoundOnlyWhereItWasExpected) {
    // Three markers closing in to a stack 15 and 30 mm deep, each 4 mm aside: their discs lie
    // far over each other in both images. The nearest marker's disc in camera 0 is found only by
    // the search where it was expected, after stereo ran, and in camera 1 the marker is hidden in
    // the others' blob. Carried on that disc's ray (cast from its centre, as stereo never saw
    // it), the nearest marker is found in every frame; without the ray, in 7 of the 13.
    const std::vector<Vec3> stack{Vec3(0.0, 0.0, 0.0), Vec3(3.0, 3.0, 15.0), Vec3(-3.0, 3.0, 30.0)};
    const ClusterRun run = runClosingCluster(true, stack);
    EXPECT_EQ(run.framesMerged, 13);
    EXPECT_EQ(run.found[0], 13);
    EXPECT_EQ(run.allocations, 0U);
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
