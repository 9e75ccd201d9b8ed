// Tests of the recording files (frames, blobs, points, truth, truth/) and the choice of level.
#include <gtest/gtest.h>

#include "firmware_app/formats/recording.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/unit/rig_fixtures.hpp"

using namespace edgetrack;
using namespace edgetrack::recording;

namespace {

template <typename Reader>
std::string errorOf(const test::TempDir& dir, const std::string& file, const std::string& text,
                    Reader reader) {
    const auto path = dir.write(file, text);
    const auto r = reader(path);
    EXPECT_FALSE(r.isValid()) << text;
    if (r.isValid())
        return {};
    EXPECT_EQ(r.error().message.rfind(path.string() + ":", 0), 0u) << r.error().message;
    return r.error().message.substr(path.string().size());
}

} // namespace

TEST(Recording, FramesOutOfOrder) {
    test::TempDir dir;
    EXPECT_EQ(errorOf(dir, "frames.csv", "frame,time_s\n0,0\n2,0.02\n1,0.01\n", readFrames),
              ":4: frames out of order: frame 1 after frame 2");
    EXPECT_EQ(errorOf(dir, "frames.csv", "frame,time_s\n0,0\n0,0.01\n", readFrames),
              ":3: frames out of order: frame 0 after frame 0");
    EXPECT_EQ(errorOf(dir, "frames.csv", "frame,time_s\n0,0.5\n1,0.25\n", readFrames),
              ":3: time_s goes backwards");
    EXPECT_EQ(errorOf(dir, "frames.csv", "frame,time_s\n-1,0\n", readFrames),
              ":2: frame -1 is negative");
}

TEST(Recording, BlobsCameraIndex) {
    test::TempDir dir;
    EXPECT_EQ(errorOf(dir, "blobs.csv", "frame,camera,u,v\n0,2,1,1\n", readBlobs),
              ":2: camera must be 0 or 1, found 2");
    EXPECT_EQ(errorOf(dir, "blobs.csv", "frame,camera,u,v\n0,-1,1,1\n", readBlobs),
              ":2: camera must be 0 or 1, found -1");
}

TEST(Recording, BlobsOrderAndArea) {
    test::TempDir dir;
    EXPECT_EQ(errorOf(dir, "blobs.csv", "frame,camera,u,v\n3,0,1,1\n2,0,1,1\n", readBlobs),
              ":3: frames out of order: frame 2 after frame 3");
    EXPECT_EQ(errorOf(dir, "blobs.csv", "frame,camera,u,v,area\n3,0,1,1,-4\n", readBlobs),
              ":2: area is negative");
}

TEST(Recording, PointsTimeMustAgreeWithinAFrame) {
    test::TempDir dir;
    EXPECT_EQ(
        errorOf(dir, "points.csv", "frame,time_s,x,y,z\n0,0,1,2,3\n0,0.1,1,2,3\n", readPoints),
        ":3: time_s differs from the frame's earlier rows");
    EXPECT_EQ(errorOf(dir, "points.csv", "frame,time_s,x,y,z\n0,0,1,2,nan\n", readPoints),
              ":2: field 'z' is \"nan\": NaN and infinity are not allowed");
}

TEST(Recording, TruthQuaternionMustBeUnit) {
    test::TempDir dir;
    EXPECT_EQ(errorOf(dir, "truth.csv",
                      "frame,time_s,object,x,y,z,qw,qx,qy,qz\n0,0,0,1,2,3,1,1,0,0\n", readTruth),
              ":2: quaternion is not unit (norm 1.414214)");
    EXPECT_EQ(errorOf(dir, "truth.csv", "frame,time_s,object,x,y,z,qw,qx,qy\n", readTruth),
              ":1: bad header \"frame,time_s,object,x,y,z,qw,qx,qy\", expected "
              "\"frame,time_s,object,x,y,z,qw,qx,qy,qz\"");
}

TEST(Recording, ObjectMarkersAreUnique) {
    test::TempDir dir;
    EXPECT_EQ(
        errorOf(dir, "truth/object_0.csv", "marker,x,y,z\n0,1,2,3\n0,4,5,6\n", readObjectMarkers),
        ":3: marker 0 appears twice");
}

TEST(Recording, MissingFile) {
    const auto r = readFrames("/nonexistent/frames.csv");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "/nonexistent/frames.csv: cannot open for reading");
}

TEST(Recording, AllFilesRoundTripExactly) {
    test::TempDir dir;
    const std::vector<FrameRow> frames{{0, 0.0}, {1, 1.0 / 120.0}, {5, 0.0416666}};
    std::vector<BlobRow> blobs{{0, 0, 100.125, 200.5, 12.0},
                               {0, 1, 3.0e-3, 799.99, 9.5},
                               {5, 1, 1.0 / 3.0, 2.0 / 3.0, 0.0}};
    const std::vector<PointRow> points{{1, 1.0 / 120.0, {1.5, -2.25, 600.125}},
                                       {1, 1.0 / 120.0, {-0.1, 0.2, 0.3}}};
    TruthRow truth;
    truth.frame = 1;
    truth.time_s = 1.0 / 120.0;
    truth.object = 3;
    truth.T_rig_from_object.rotation = Quat(Eigen::AngleAxisd(0.4, Vec3(1, 2, 3).normalized()));
    truth.T_rig_from_object.translation_mm = {10.0, -20.0, 555.5};
    const std::vector<TruthMarker> markers{{0, {35, 35, 35}}, {7, {-35, 0.5, 12}}};

    ASSERT_TRUE(writeFrames(dir.path() / "frames.csv", frames));
    ASSERT_TRUE(writeBlobs(dir.path() / "blobs.csv", blobs, true));
    ASSERT_TRUE(writePoints(dir.path() / "points.csv", points));
    ASSERT_TRUE(writeTruth(dir.path() / "truth.csv", {truth}));
    std::filesystem::create_directories(dir.path() / "truth");
    ASSERT_TRUE(writeObjectMarkers(dir.path() / "truth" / "object_3.csv", markers));

    const auto framesBack = readFrames(dir.path() / "frames.csv");
    ASSERT_TRUE(framesBack);
    ASSERT_EQ(framesBack->size(), 3u);
    EXPECT_EQ((*framesBack)[1].time_s, 1.0 / 120.0);
    EXPECT_EQ((*framesBack)[2].frame, 5);

    const auto blobsBack = readBlobs(dir.path() / "blobs.csv");
    ASSERT_TRUE(blobsBack);
    ASSERT_EQ(blobsBack->size(), 3u);
    EXPECT_EQ((*blobsBack)[2].u_px, 1.0 / 3.0);
    EXPECT_EQ((*blobsBack)[1].camera, 1);
    EXPECT_EQ((*blobsBack)[0].area_px, 12.0);

    const auto pointsBack = readPoints(dir.path() / "points.csv");
    ASSERT_TRUE(pointsBack);
    EXPECT_EQ((*pointsBack)[0].position_rig_mm, points[0].position_rig_mm);

    const auto truthBack = readTruth(dir.path() / "truth.csv");
    ASSERT_TRUE(truthBack);
    EXPECT_EQ((*truthBack)[0].object, 3);
    EXPECT_EQ((*truthBack)[0].T_rig_from_object.translation_mm,
              truth.T_rig_from_object.translation_mm);
    EXPECT_LT(rotationAngleBetween_rad((*truthBack)[0].T_rig_from_object.rotation,
                                       truth.T_rig_from_object.rotation),
              1e-7);

    const auto markersBack = readObjectMarkers(dir.path() / "truth" / "object_3.csv");
    ASSERT_TRUE(markersBack);
    EXPECT_EQ((*markersBack)[1].marker, 7);
    EXPECT_EQ((*markersBack)[1].position_object_mm, markers[1].position_object_mm);

    // Without the area column the header and the rows have four fields.
    ASSERT_TRUE(writeBlobs(dir.path() / "blobs4.csv", blobs, false));
    const auto noArea = readBlobs(dir.path() / "blobs4.csv");
    ASSERT_TRUE(noArea);
    EXPECT_FALSE((*noArea)[0].area_px.has_value());
}

TEST(Recording, ChoosesTheLowestLevelPresent) {
    test::TempDir dir;
    dir.write("points.csv", "frame,time_s,x,y,z\n");
    auto inventory = inspect(dir.path());
    ASSERT_TRUE(inventory);
    auto level = chooseLevel(dir.path(), *inventory, std::nullopt);
    ASSERT_TRUE(level);
    EXPECT_EQ(*level, Level::Points);

    dir.write("blobs.csv", "frame,camera,u,v\n");
    inventory = inspect(dir.path());
    // Blobs without rig.toml cannot be used.
    level = chooseLevel(dir.path(), *inventory, std::nullopt);
    ASSERT_FALSE(level);
    EXPECT_EQ(level.error().message, dir.path().string() + ": the blobs level needs rig.toml");

    ASSERT_TRUE(writeRig(dir.path() / "rig.toml", test::desktopRig()));
    dir.write("frames.csv", "frame,time_s\n");
    inventory = inspect(dir.path());
    level = chooseLevel(dir.path(), *inventory, std::nullopt);
    ASSERT_TRUE(level);
    EXPECT_EQ(*level, Level::Blobs);

    level = chooseLevel(dir.path(), *inventory, Level::Points);
    ASSERT_TRUE(level);
    EXPECT_EQ(*level, Level::Points);

    level = chooseLevel(dir.path(), *inventory, Level::Images);
    ASSERT_FALSE(level);
    EXPECT_EQ(level.error().message, dir.path().string() + ": has no images level");
}

TEST(Recording, NotADirectory) {
    const auto r = inspect("/nonexistent/rec");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "/nonexistent/rec: not a recording directory");
    test::TempDir dir;
    const auto empty = chooseLevel(dir.path(), *inspect(dir.path()), std::nullopt);
    ASSERT_FALSE(empty);
    EXPECT_EQ(empty.error().message,
              dir.path().string() + ": holds no images/, blobs.csv or points.csv");
}

TEST(Recording, LevelNames) {
    EXPECT_EQ(parseLevel("images"), Level::Images);
    EXPECT_EQ(parseLevel("points"), Level::Points);
    EXPECT_FALSE(parseLevel("pixels"));
}

TEST(Recording, ImageNamesReadBackToTheirFrame) {
    EXPECT_EQ(imageFrameOf(imagePath("rec", 123, 1).filename().string()), 123);
    EXPECT_EQ(imageFrameOf("000000_0.pgm"), 0);
    for (const char* other : {"000123_2.pgm", "00012a_0.pgm", "000123_0.png", "123_0.pgm",
                              "0000123_0.pgm", "thumbs.db"})
        EXPECT_FALSE(imageFrameOf(other)) << other;
}
