// `edgetrack rig calibrate` as a user runs it: the simulated wand from a far start, and the real
// MoCapRasp wand recording (../shared/realdata/MoCapRasp) through reconstruct and calibrate.
#include <cmath>
#include <map>
#include <sstream>

#include <gtest/gtest.h>

#include "firmware_app/app/cli.hpp"
#include "firmware_app/formats/recording.hpp"
#include "firmware_app/tools/sim_command.hpp"
#include "hal/sim/scene.hpp"
#include "tests/support/rig_knock.hpp"
#include "tests/support/temp_dir.hpp"
#include "tests/tools/mocaprasp.hpp"

using namespace edgetrack;
namespace fs = std::filesystem;

namespace {

struct CliRun {
    int exit = 0;
    std::string out;
    std::string err;
};

CliRun edgetrackCli(std::vector<std::string> args) {
    args.insert(args.begin(), "edgetrack");
    std::vector<const char*> argv;
    for (const std::string& a : args)
        argv.push_back(a.c_str());
    std::ostringstream out, err;
    CliRun run;
    run.exit = app::runCommandLine(static_cast<int>(argv.size()), argv.data(), out, err);
    run.out = out.str();
    run.err = err.str();
    return run;
}

/// The number after \a label in \a text ("reprojection RMS 0.055 px" -> 0.055).
double numberAfter(const std::string& text, const std::string& label, std::size_t from = 0) {
    const std::size_t at = text.find(label, from);
    return at == std::string::npos ? -1.0 : std::strtod(text.c_str() + at + label.size(), nullptr);
}

#ifdef EDGETRACK_SLOW_TARGET
constexpr int kWandFrames = 1500; // 15 s: the emulator runs 20 times slower
#else
constexpr int kWandFrames = 3000; // 30 s, as the figure
#endif

/// A simulated wand session at blobs level in \a dir/wand (its rig.toml is the truth).
app::SimRecordingOptions wandRecording(const test::TempDir& dir) {
    app::SimRecordingOptions sim;
    sim.scene = "wand";
    sim.frames = kWandFrames;
    sim.out = dir.path() / "wand";
    sim.level = recording::Level::Blobs;
    EXPECT_TRUE(app::writeSimRecording(sim));
    return sim;
}

} // namespace

TEST(RigCalibrateCommand, SimulatedWandFromAStartFiftyMillimetresAndFiveDegreesOff) {
    test::TempDir dir;
    const app::SimRecordingOptions sim = wandRecording(dir);
    const Result<StereoRig> truth = recording::readRig(sim.out / "rig.toml");
    ASSERT_TRUE(truth);
    const StereoRig start = test::knockedRig(*truth, 50.0, 5.0);
    ASSERT_TRUE(recording::writeRig(sim.out / "rig.toml", start));

    const fs::path out = dir.path() / "found.toml";
    const CliRun run = edgetrackCli({"rig", "calibrate", "--input", sim.out.string(), "--wand",
                                     "55,102", "--out", out.string()});
    ASSERT_EQ(run.exit, 0) << run.err;
    const Result<StereoRig> found = recording::readRig(out);
    ASSERT_TRUE(found) << found.error().message;
    EXPECT_LT(test::cameraOneTurn_deg(*found, *truth), 0.01) << run.out;
    EXPECT_LT(test::cameraOneShift_mm(*found, *truth), 0.1) << run.out;
    // The simulator's blob noise, 0.05 px per coordinate, leaves 0.054 px after the fit takes
    // five of each pair's twelve numbers (see test_rig_calibration.cpp).
    const double expected = 0.05 * std::sqrt(2.0) * std::sqrt(7.0 / 12.0);
    for (const char* camera : {"camera 0: reprojection RMS ", "camera 1: reprojection RMS "})
        EXPECT_NEAR(numberAfter(run.out, camera), expected, 0.1 * expected) << run.out;
    EXPECT_NE(run.out.find("result: good"), std::string::npos) << run.out;
}

TEST(RigCalibrateCommand, RefinedIntrinsicsOfTheSimulatedCameras) {
    test::TempDir dir;
    const app::SimRecordingOptions sim = wandRecording(dir);
    const Result<StereoRig> truth = recording::readRig(sim.out / "rig.toml");
    ASSERT_TRUE(truth);
    const StereoRig moved = test::knockedRig(*truth, 20.0, 2.0);
    std::array<CameraModel, 2> cameras{moved.camera(0), moved.camera(1)};
    for (CameraModel& camera : cameras) {
        CameraIntrinsics in = camera.intrinsics();
        in.fx_px *= 1.01;
        in.fy_px *= 0.99;
        camera = CameraModel(in, camera.extrinsics());
    }
    ASSERT_TRUE(recording::writeRig(sim.out / "rig.toml", StereoRig(cameras[0], cameras[1])));

    const fs::path out = dir.path() / "found.toml";
    const CliRun run = edgetrackCli({"rig", "calibrate", "--input", sim.out.string(), "--wand",
                                     "55,102", "--out", out.string(), "--refine-intrinsics"});
    ASSERT_EQ(run.exit, 0) << run.err;
    const Result<StereoRig> found = recording::readRig(out);
    ASSERT_TRUE(found);
    for (int c = 0; c < 2; ++c) {
        EXPECT_NEAR(found->camera(c).intrinsics().fx_px / truth->camera(c).intrinsics().fx_px, 1.0,
                    0.001);
        EXPECT_NEAR(found->camera(c).intrinsics().fy_px / truth->camera(c).intrinsics().fy_px, 1.0,
                    0.001);
    }
}

TEST(RigCalibrateCommand, NoWandNoRig) {
    test::TempDir dir;
    app::SimRecordingOptions sim;
    sim.scene = "slow_cube";
    sim.frames = 50;
    sim.out = dir.path() / "cube";
    sim.level = recording::Level::Blobs;
    ASSERT_TRUE(app::writeSimRecording(sim));
    const fs::path out = dir.path() / "rig.toml";
    const CliRun run = edgetrackCli({"rig", "calibrate", "--input", sim.out.string(), "--wand",
                                     "55,102", "--out", out.string()});
    EXPECT_EQ(run.exit, 1);
    EXPECT_NE(run.err.find("edgetrack rig calibrate: the wand was found in both images of only"),
              std::string::npos)
        << run.err;
    EXPECT_EQ(std::count(run.err.begin(), run.err.end(), '\n'), 1);
    EXPECT_FALSE(fs::exists(out));

    const CliRun badWand = edgetrackCli({"rig", "calibrate", "--input", sim.out.string(), "--wand",
                                         "55,-3", "--out", out.string()});
    EXPECT_EQ(badWand.exit, 2);
    EXPECT_NE(badWand.err.find("--wand: '-3' is not a positive distance"), std::string::npos);

    sim.out = dir.path() / "points";
    sim.level = recording::Level::Points;
    ASSERT_TRUE(app::writeSimRecording(sim));
    const CliRun points = edgetrackCli({"rig", "calibrate", "--input", sim.out.string(), "--wand",
                                        "55,102", "--out", out.string()});
    EXPECT_EQ(points.exit, 1);
    EXPECT_NE(points.err.find("needs images or blobs"), std::string::npos) << points.err;
}

namespace {

const fs::path kMoCapRasp = fs::path(EDGETRACK_REALDATA_DIR) / "MoCapRasp";

/// Per frame, the points of a points.csv.
std::map<std::int64_t, std::vector<Vec3>> pointsByFrame(const fs::path& points) {
    std::map<std::int64_t, std::vector<Vec3>> frames;
    const auto rows = recording::readPoints(points);
    if (rows)
        for (const recording::PointRow& row : *rows)
            frames[row.frame].push_back(row.position_rig_mm);
    return frames;
}

} // namespace

// The real wand of MoCapRasp (two Raspberry Pi NoIR cameras about 3.5 m apart, turned 100
// degrees to each other, the wand 2.4 to 3.5 m away): a room-sized rig, far from the board's
// desktop one, so reconstruct runs with a working volume to match (README of docs/rig-calibration).
TEST(RigCalibrateCommand, MoCapRaspWandThenItsObject) {
    if (!fs::exists(kMoCapRasp / "7Jun_camCalib.csv"))
        GTEST_SKIP() << kMoCapRasp << " is absent (the shared real-data folder is not here)";
    test::TempDir dir;
    const fs::path constants = kMoCapRasp / "constants_f3641f9.py";
    const auto wandRec =
        test::convertMoCapRasp(kMoCapRasp / "7Jun_camCalib.csv", constants, dir.path() / "wand");
    ASSERT_TRUE(wandRec) << wandRec.error().message;
    EXPECT_EQ(wandRec->framesBothCameras, 2564u);

    const fs::path rig = dir.path() / "rig.toml";
    const CliRun calibrate =
        edgetrackCli({"rig", "calibrate", "--input", (dir.path() / "wand").string(), "--wand",
                      "55,102", "--out", rig.string(), "--refine-intrinsics"});
    ASSERT_EQ(calibrate.exit, 0) << calibrate.err;

    const fs::path room = dir.write("room.toml", "[stereo]\nmax_depth_mm = 8000.0\n"
                                                 "max_ray_gap_mm = 5.0\n"
                                                 "max_reprojection_px = 3.0\n");
    fs::copy_file(rig, dir.path() / "wand" / "rig.toml", fs::copy_options::overwrite_existing);
    const CliRun reconstruct =
        edgetrackCli({"reconstruct", "--config", room.string(), "--input",
                      (dir.path() / "wand").string(), "--out", (dir.path() / "wand3d").string()});
    ASSERT_EQ(reconstruct.exit, 0) << reconstruct.err;
    std::vector<double> errors;
    for (const auto& [frame, points] : pointsByFrame(dir.path() / "wand3d" / "points.csv")) {
        if (points.size() != 3)
            continue;
        double length = 0.0;
        for (const Vec3& a : points)
            for (const Vec3& b : points)
                length = std::max(length, (a - b).norm());
        errors.push_back(std::abs(length - 157.0));
    }
    const double share = static_cast<double>(errors.size()) / 2564.0;
    EXPECT_GE(share, 0.90) << calibrate.out;
    std::sort(errors.begin(), errors.end());
    double sum = 0.0;
    for (double e : errors)
        sum += e * e;
    ASSERT_FALSE(errors.empty());
    EXPECT_LE(std::sqrt(sum / static_cast<double>(errors.size())), 1.0) << calibrate.out;
    EXPECT_LE(errors[static_cast<std::size_t>(0.95 * static_cast<double>(errors.size()))], 1.5)
        << calibrate.out;

    // The 4-marker object the same cameras saw, reconstructed with that rig: one model of 4.
    const auto objectRec =
        test::convertMoCapRasp(kMoCapRasp / "7Jun_camTest.csv", constants, dir.path() / "object");
    ASSERT_TRUE(objectRec) << objectRec.error().message;
    fs::copy_file(rig, dir.path() / "object" / "rig.toml", fs::copy_options::overwrite_existing);
    const CliRun models =
        edgetrackCli({"calibrate", "--config", room.string(), "--input",
                      (dir.path() / "object").string(), "--out", (dir.path() / "models").string()});
    ASSERT_EQ(models.exit, 0) << models.err;
    EXPECT_NE(models.out.find("1 model written"), std::string::npos) << models.out;
    EXPECT_NE(models.out.find("body_0.json: 4 markers"), std::string::npos) << models.out;
}
