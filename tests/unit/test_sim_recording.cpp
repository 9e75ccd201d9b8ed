// Tests of `edgetrack sim` recordings: exact INTERFACES layout, read back at every level,
// repeatable.
#include <fstream>
#include <iterator>

#include <gtest/gtest.h>

#include "firmware_app/formats/recording.hpp"
#include "firmware_app/tools/sim_command.hpp"
#include "hal/sim/scene.hpp"
#include "tests/support/temp_dir.hpp"

using namespace edgetrack;
using namespace edgetrack::recording;

namespace {

std::string fileBytes(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

app::SimRecordingOptions options(const std::filesystem::path& out, Level level,
                                 const char* scene = "two_cubes", std::int64_t frames = 12) {
    app::SimRecordingOptions o;
    o.scene = scene;
    o.frames = frames;
    o.out = out;
    o.seed = 42;
    o.level = level;
    return o;
}

} // namespace

TEST(SimRecording, ImagesLevelReadsBack) {
    test::TempDir dir;
    const auto rec = dir.path() / "rec";
    ASSERT_TRUE(app::writeSimRecording(options(rec, Level::Images)));
    const auto inventory = inspect(rec);
    ASSERT_TRUE(inventory);
    EXPECT_EQ(*chooseLevel(rec, *inventory, std::nullopt), Level::Images);
    const auto rig = readRig(rec / "rig.toml");
    ASSERT_TRUE(rig) << rig.error().message;
    const auto frames = readFrames(rec / "frames.csv");
    ASSERT_TRUE(frames);
    ASSERT_EQ(frames->size(), 12u);
    EXPECT_DOUBLE_EQ((*frames)[3].time_s, 0.03);
    for (const FrameRow& f : *frames)
        for (int camera = 0; camera < 2; ++camera) {
            const auto image =
                readPgm(imagePath(rec, f.frame, camera), rig->camera(camera).intrinsics().width_px,
                        rig->camera(camera).intrinsics().height_px);
            ASSERT_TRUE(image) << image.error().message;
        }
    const auto truth = readTruth(rec / "truth.csv");
    ASSERT_TRUE(truth) << truth.error().message;
    EXPECT_EQ(truth->size(), 24u); // two objects, every frame
    const auto cube = readObjectMarkers(rec / "truth" / "object_0.csv");
    ASSERT_TRUE(cube);
    EXPECT_EQ(cube->size(), 30u);
    EXPECT_EQ(readObjectMarkers(rec / "truth" / "object_1.csv")->size(), 24u);
    EXPECT_FALSE(std::filesystem::exists(rec / "blobs.csv"));
}

TEST(SimRecording, BlobsLevelReadsBackAndMatchesTruth) {
    test::TempDir dir;
    const auto rec = dir.path() / "rec";
    ASSERT_TRUE(app::writeSimRecording(options(rec, Level::Blobs, "slow_cube", 30)));
    const auto blobs = readBlobs(rec / "blobs.csv");
    ASSERT_TRUE(blobs) << blobs.error().message;
    ASSERT_FALSE(blobs->empty());
    EXPECT_TRUE(blobs->front().area_px.has_value());

    // Every blob lies near the projection of some true marker.
    const auto rig = readRig(rec / "rig.toml");
    const auto truth = readTruth(rec / "truth.csv");
    const auto markers = readObjectMarkers(rec / "truth" / "object_0.csv");
    ASSERT_TRUE(rig && truth && markers);
    for (const BlobRow& blob : *blobs) {
        const RigidTransform& pose =
            (*truth)[static_cast<std::size_t>(blob.frame)].T_rig_from_object;
        double nearest = 1e9;
        for (const TruthMarker& m : *markers)
            if (auto p = rig->camera(blob.camera).project(pose.apply(m.position_object_mm)))
                nearest = std::min(nearest, (*p - Vec2(blob.u_px, blob.v_px)).norm());
        EXPECT_LT(nearest, 6.0) << "frame " << blob.frame; // merged blobs sit between markers
    }
}

TEST(SimRecording, PointsLevelReadsBackAndMatchesTruth) {
    test::TempDir dir;
    const auto rec = dir.path() / "rec";
    ASSERT_TRUE(app::writeSimRecording(options(rec, Level::Points, "slow_cube", 30)));
    EXPECT_EQ(*chooseLevel(rec, *inspect(rec), std::nullopt), Level::Points);
    const auto points = readPoints(rec / "points.csv");
    const auto truth = readTruth(rec / "truth.csv");
    const auto markers = readObjectMarkers(rec / "truth" / "object_0.csv");
    ASSERT_TRUE(points && truth && markers);
    ASSERT_GE(points->size(), 30u * 5u); // at least one whole face of the cube every frame
    for (const PointRow& p : *points) {
        const RigidTransform& pose = (*truth)[static_cast<std::size_t>(p.frame)].T_rig_from_object;
        double nearest = 1e9;
        for (const TruthMarker& m : *markers)
            nearest =
                std::min(nearest, (pose.apply(m.position_object_mm) - p.position_rig_mm).norm());
        EXPECT_LT(nearest, 0.5);
    }
}

TEST(SimRecording, EverySceneIsTheSameBytesForTheSameSeed) {
    test::TempDir dir;
    for (const sim::SceneInfo& scene : sim::sceneCatalogue()) {
        for (Level level : {Level::Images, Level::Blobs, Level::Points}) {
            const std::string tag = std::string(scene.name) + "_" + levelName(level);
            const auto a = dir.path() / ("a_" + tag);
            const auto b = dir.path() / ("b_" + tag);
            ASSERT_TRUE(app::writeSimRecording(options(a, level, scene.name, 3)));
            ASSERT_TRUE(app::writeSimRecording(options(b, level, scene.name, 3)));
            int files = 0;
            for (const auto& entry : std::filesystem::recursive_directory_iterator(a)) {
                if (!entry.is_regular_file())
                    continue;
                const auto relative = std::filesystem::relative(entry.path(), a);
                EXPECT_EQ(fileBytes(entry.path()), fileBytes(b / relative))
                    << tag << " " << relative;
                ++files;
            }
            EXPECT_GE(files, 4) << tag;
            std::filesystem::remove_all(a);
            std::filesystem::remove_all(b);
        }
    }
}

TEST(SimRecording, RefusesToOverwriteAndUnknownScenes) {
    test::TempDir dir;
    dir.write("rec/notes.txt", "keep me");
    const Status busy = app::writeSimRecording(options(dir.path() / "rec", Level::Points));
    ASSERT_FALSE(busy);
    EXPECT_EQ(busy.error().message,
              (dir.path() / "rec").string() + ": exists and is not empty; choose a new directory");
    auto unknown = options(dir.path() / "other", Level::Points);
    unknown.scene = "moon";
    const Status s = app::writeSimRecording(unknown);
    ASSERT_FALSE(s);
    EXPECT_EQ(s.error().message, "unknown scene 'moon' (edgetrack sim --list shows them)");
}
