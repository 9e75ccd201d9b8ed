// Tests of `edgetrack track` and pose files: the sim -> calibrate -> track chain against truth.
#include <sstream>

#include <gtest/gtest.h>

#include "firmware_app/formats/csv.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "firmware_app/formats/pose_file.hpp"
#include "firmware_app/tools/calibrate_command.hpp"
#include "firmware_app/tools/sim_command.hpp"
#include "firmware_app/tools/track_command.hpp"
#include "tests/support/temp_dir.hpp"

namespace edgetrack::app {
namespace {

namespace fs = std::filesystem;

TEST(PoseFile, RowsReadBackToTheirPrecision) {
    test::TempDir dir;
    PoseRow row;
    row.frame = 42;
    row.time_s = 0.42;
    row.body = 3;
    row.T_rig_from_model.translation_mm = Vec3(12.34567, -8.9, 600.00004);
    row.T_rig_from_model.rotation = quaternionFromWxyz(0.5, -0.5, 0.5, 0.5);
    row.markers = 9;
    row.rms_mm = 0.1234;
    std::string csv = kPoseCsvHeader;
    appendPoseRow(csv, row);
    ASSERT_TRUE(recording::writeTextFileAtomically(dir.path() / "poses.csv", csv));

    const Result<std::vector<PoseRow>> read = readPoses(dir.path() / "poses.csv");
    ASSERT_TRUE(read) << read.error().message;
    ASSERT_EQ(read->size(), 1u);
    const PoseRow& back = read->front();
    EXPECT_EQ(back.frame, 42);
    EXPECT_EQ(back.body, 3u);
    EXPECT_EQ(back.markers, 9u);
    EXPECT_NEAR(back.rms_mm, 0.1234, 1e-9);
    EXPECT_LT((back.T_rig_from_model.translation_mm - row.T_rig_from_model.translation_mm).norm(),
              1e-4);
    EXPECT_LT(
        rotationAngleBetween_rad(back.T_rig_from_model.rotation, row.T_rig_from_model.rotation),
        1e-8);
}

TEST(PoseFile, RefusesABadQuaternionWithItsLine) {
    test::TempDir dir;
    std::string text(kPoseCsvHeader);
    text += "0,0,0,1,2,3,1,0,0,0,4,0.1\n1,0.01,0,1,2,3,0.5,0,0,0,4,0.1\n";
    const fs::path path = dir.write("poses.csv", text);
    const Result<std::vector<PoseRow>> read = readPoses(path);
    ASSERT_FALSE(read);
    EXPECT_NE(read.error().message.find("poses.csv:3: quaternion is not unit"), std::string::npos)
        << read.error().message;
}

/// Per body, the pose in the frame of object k: constant over frames when the body is object k.
struct Consistency {
    double spread_mm = 1e9;
    double spread_deg = 1e9;
};

Consistency consistencyWith(const std::vector<PoseRow>& poses, std::uint32_t body,
                            const std::vector<recording::TruthRow>& truth, std::int64_t object) {
    std::vector<RigidTransform> T_object_from_model;
    for (const PoseRow& pose : poses) {
        if (pose.body != body)
            continue;
        for (const recording::TruthRow& t : truth)
            if (t.frame == pose.frame && t.object == static_cast<int>(object))
                T_object_from_model.push_back(t.T_rig_from_object.inverse() *
                                              pose.T_rig_from_model);
    }
    Consistency c;
    if (T_object_from_model.empty())
        return c;
    c = Consistency{0.0, 0.0};
    for (const RigidTransform& t : T_object_from_model) {
        c.spread_mm = std::max(c.spread_mm,
                               (t.translation_mm - T_object_from_model[0].translation_mm).norm());
        c.spread_deg = std::max(
            c.spread_deg, rotationAngleBetween_rad(t.rotation, T_object_from_model[0].rotation) *
                              180.0 / 3.14159265358979);
    }
    return c;
}

TEST(TrackCommand, TracksCalibratedModelsThroughAnotherRecording) {
    test::TempDir dir;
    SimRecordingOptions sim;
    sim.scene = "two_cubes";
    sim.level = recording::Level::Points;
    sim.frames = 1200;
    sim.seed = 2;
    sim.out = dir.path() / "calibration";
    ASSERT_TRUE(writeSimRecording(sim));
    sim.frames = 300;
    sim.seed = 3;
    sim.out = dir.path() / "session";
    ASSERT_TRUE(writeSimRecording(sim));

    std::ostringstream summary, progress;
    CalibrateOptions calibrate;
    calibrate.input = dir.path() / "calibration";
    calibrate.out = dir.path() / "models";
    const Status calibrated = runCalibrate(calibrate, summary, progress);
    ASSERT_TRUE(calibrated) << calibrated.error().message;

    TrackOptions track;
    track.models = dir.path() / "models";
    track.input = dir.path() / "session";
    track.out = dir.path() / "poses.csv";
    const Status tracked = runTrack(track, summary, progress);
    ASSERT_TRUE(tracked) << tracked.error().message;
    EXPECT_NE(summary.str().find("edgetrack track: 300 frames from points, 2 models"),
              std::string::npos)
        << summary.str();

    const Result<std::vector<PoseRow>> poses = readPoses(track.out);
    ASSERT_TRUE(poses) << poses.error().message;
    const Result<std::vector<recording::TruthRow>> truth =
        recording::readTruth(dir.path() / "session" / "truth.csv");
    ASSERT_TRUE(truth) << truth.error().message;
    // Each body is one of the two cubes, at a fixed offset from it, in most frames (the cubes
    // hide each other, so some frames show too few of a cube's markers; eval_tracking measures
    // against what was visible).
    std::vector<std::int64_t> objectOf;
    for (std::uint32_t body = 0; body < 2; ++body) {
        const auto rows = std::count_if(poses->begin(), poses->end(),
                                        [&](const PoseRow& p) { return p.body == body; });
        EXPECT_GE(rows, 255) << "body " << body << " found in " << rows << " of 300 frames";
        std::int64_t best = -1;
        Consistency bestConsistency;
        for (std::int64_t object = 0; object < 2; ++object) {
            const Consistency c = consistencyWith(*poses, body, *truth, object);
            if (c.spread_mm < bestConsistency.spread_mm) {
                bestConsistency = c;
                best = object;
            }
        }
        EXPECT_LT(bestConsistency.spread_mm, 1.0) << "body " << body;
        EXPECT_LT(bestConsistency.spread_deg, 1.0) << "body " << body;
        objectOf.push_back(best);
    }
    EXPECT_NE(objectOf[0], objectOf[1]);
}

TEST(TrackCommand, ReportsBadModelsAndLeavesNoPartialOutput) {
    test::TempDir dir;
    SimRecordingOptions sim;
    sim.scene = "slow_cube";
    sim.level = recording::Level::Points;
    sim.frames = 5;
    sim.out = dir.path() / "session";
    ASSERT_TRUE(writeSimRecording(sim));
    std::ostringstream summary, progress;
    TrackOptions track;
    track.input = sim.out;
    track.out = dir.path() / "poses.csv";

    track.models = dir.path() / "no_models_here";
    Status s = runTrack(track, summary, progress);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("no_models_here"), std::string::npos) << s.error().message;

    dir.write("models/body_0.json", "{ \"id\": 0, \"markers\": [[0, 0, 0]], \"edges\": [] ");
    track.models = dir.path() / "models";
    s = runTrack(track, summary, progress);
    ASSERT_FALSE(s);
    EXPECT_NE(s.error().message.find("body_0.json"), std::string::npos) << s.error().message;
    EXPECT_FALSE(fs::exists(track.out));
}

} // namespace
} // namespace edgetrack::app
