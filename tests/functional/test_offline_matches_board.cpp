// The offline commands with the board's edgetrack.toml process frames exactly as the board does.
#include <chrono>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>
#include <thread>

#include <gtest/gtest.h>

#include "firmware_app/firmware/firmware.hpp"
#include "firmware_app/formats/model_file.hpp"
#include "firmware_app/formats/recording.hpp"
#include "firmware_app/tools/calibrate_command.hpp"
#include "firmware_app/tools/reconstruct_command.hpp"
#include "tests/functional/firmware_on_sim_board.hpp"
#include "tests/support/temp_dir.hpp"

namespace edgetrack::app {
namespace {

namespace fs = std::filesystem;
const fs::path kDeployed = fs::path(EDGETRACK_SOURCE_DIR) / "deploy" / "edgetrack.toml";

std::string readText(const fs::path& path) {
    std::ifstream in(path);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

/// A camera pair that hands the simulated board's frames on and keeps a copy of the next few
/// as PGM images of a recording, as `edgetrack sim` would write them.
class RecordingCameraPair : public hal::CameraPair {
public:
    RecordingCameraPair(hal::CameraPair& cameras, fs::path recording)
        : cameras_(cameras)
        , recording_(std::move(recording)) {}

    /// \brief Keep the next \a count frames.
    void keep(int count) { keep_ = count; }
    const std::vector<recording::FrameRow>& kept() const { return kept_; }

    Status start() override { return cameras_.start(); }
    void stop() override { cameras_.stop(); }
    hal::AcquireStatus acquire(hal::StereoFrame& frame, hal::Nanoseconds timeout) override {
        const hal::AcquireStatus status = cameras_.acquire(frame, timeout);
        if (status == hal::AcquireStatus::Frame && keep_ > 0) {
            --keep_;
            const auto number = static_cast<std::int64_t>(frame.number);
            for (int c = 0; c < 2; ++c) {
                const hal::CameraFrame& image = frame.camera[static_cast<std::size_t>(c)];
                recording::Image8 copy{image.width_px, image.height_px, {}};
                for (int y = 0; y < image.height_px; ++y) {
                    const std::uint8_t* row = image.pixels + y * image.stride_bytes;
                    copy.pixels.insert(copy.pixels.end(), row, row + image.width_px);
                }
                EXPECT_TRUE(recording::writePgm(recording::imagePath(recording_, number, c), copy));
            }
            kept_.push_back({number, hal::toSeconds(frame.midExposure())});
        }
        return status;
    }
    void release(const hal::StereoFrame& frame) override { cameras_.release(frame); }
    hal::CameraPairCounters counters() const override { return cameras_.counters(); }
    hal::Nanoseconds framePeriod() const override { return cameras_.framePeriod(); }

private:
    hal::CameraPair& cameras_;
    fs::path recording_;
    int keep_ = 0;
    std::vector<recording::FrameRow> kept_;
};

TEST(OfflineMatchesBoard, ReconstructWithTheBoardsConfigFindsTheBoardsMarkers) {
    test::TempDir dir;
    // Settings other than the defaults, so that the file is seen to reach blob detection.
    std::string text = readText(kDeployed);
    const std::string threshold = "threshold = 60";
    ASSERT_NE(text.find(threshold), std::string::npos) << "deploy/edgetrack.toml changed";
    text.replace(text.find(threshold), threshold.size(), "threshold = 110");
    const fs::path configPath = dir.write("edgetrack.toml", text);
    Result<FirmwareConfig> config = loadFirmwareConfig(configPath);
    ASSERT_TRUE(config) << config.error().message;

    auto sim = makeBoard("two_cubes", 3);
    const fs::path rec = dir.path() / "rec";
    fs::create_directories(rec / "images");
    RecordingCameraPair cameras(sim->cameras, rec);
    hal::Board board{sim->clock, cameras,       sim->ledRing, sim->button, sim->statusLed,
                     sim->flash, sim->rigFlash, sim->can,     sim->udp};
    Firmware firmware(*config, board, sim->world.rig());
    ASSERT_TRUE(firmware.isValid()) << firmware.error();
    firmware.start();
    // Past the LED's start-up; then the board's markers of a few frames.
    while (firmware.counters().framesProcessed < 30)
        firmware.step();
    constexpr int kFrames = 6;
    cameras.keep(kFrames);
    std::map<std::int64_t, std::vector<Vec3>> boardPoints;
    while (boardPoints.size() < kFrames) {
        const std::uint64_t processed = firmware.counters().framesProcessed;
        firmware.step();
        if (firmware.counters().framesProcessed > processed) {
            const std::span<const Vec3> points = firmware.markerPipeline().points_rig_mm();
            boardPoints[static_cast<std::int64_t>(firmware.lastFrame())].assign(points.begin(),
                                                                                points.end());
        }
    }
    ASSERT_EQ(cameras.kept().size(), static_cast<std::size_t>(kFrames));
    ASSERT_TRUE(recording::writeRig(rec / "rig.toml", sim->world.rig()));
    ASSERT_TRUE(recording::writeFrames(rec / "frames.csv", cameras.kept()));

    std::size_t markers = 0;
    for (const bool withTheBoardsConfig : {true, false}) {
        ReconstructOptions options;
        options.input = rec;
        options.out = dir.path() / (withTheBoardsConfig ? "board" : "defaults");
        if (withTheBoardsConfig) {
            Result<CommandSettings> settings = loadCommandSettings(configPath);
            ASSERT_TRUE(settings) << settings.error().message;
            options.settings = std::move(*settings);
        }
        std::ostringstream summary;
        const Status s = runReconstruct(options, summary);
        ASSERT_TRUE(s) << s.error().message;
        if (withTheBoardsConfig) {
            EXPECT_NE(summary.str().find("settings: " + configPath.string()), std::string::npos)
                << summary.str();
        }
        Result<std::vector<recording::PointRow>> rows =
            recording::readPoints(options.out / "points.csv");
        ASSERT_TRUE(rows) << rows.error().message;
        std::map<std::int64_t, std::vector<Vec3>> offline;
        for (const recording::PointRow& row : *rows)
            offline[row.frame].push_back(row.position_rig_mm);
        bool same = true;
        for (const auto& [frame, points] : boardPoints) {
            markers += withTheBoardsConfig ? points.size() : 0;
            same = same && offline[frame] == points;
        }
        // Bit for bit with the board's file; other blob settings move the blob centres.
        EXPECT_EQ(same, withTheBoardsConfig)
            << (withTheBoardsConfig ? "board's" : "default") << " settings";
    }
    EXPECT_GE(markers, 6u * kFrames) << "the cubes in view";
}

/// deploy/edgetrack.toml with \a key's value replaced, so that the file is seen to be used.
fs::path deployedWith(const test::TempDir& dir, const std::string& key, const std::string& value) {
    std::string text = readText(kDeployed);
    const std::size_t at = text.find("\n" + key + " = ");
    EXPECT_NE(at, std::string::npos) << key << " not in deploy/edgetrack.toml";
    if (at == std::string::npos)
        return kDeployed;
    const std::size_t end = text.find('\n', at + 1);
    text.replace(at + 1, end - at - 1, key + " = " + value);
    return dir.write(key + ".toml", text);
}

/// The board's field calibration and `calibrate --config FILE` over the same frames.
void expectOfflineCalibrationAsOnTheBoard(const fs::path& configPath) {
    Result<CommandSettings> settings = loadCommandSettings(configPath);
    ASSERT_TRUE(settings) << settings.error().message;
    auto sim = makeBoard("two_cubes", 7);
    Firmware firmware(settings->config, sim->board, sim->world.rig());
    ASSERT_TRUE(firmware.isValid()) << firmware.error();
    firmware.start();
    while (firmware.counters().framesProcessed < 20)
        firmware.step();

    // Every frame the calibration session is given, at blobs level as the board detected them.
    std::vector<recording::FrameRow> frames;
    std::vector<recording::BlobRow> blobs;
    sim->button.press(sim->clock.now(), 150 * kMs, 3);
    const auto start = std::chrono::steady_clock::now();
    while (firmware.state() != FirmwareState::Finishing || frames.empty()) {
        const FirmwareState before = firmware.state();
        const std::uint64_t processed = firmware.counters().framesProcessed;
        firmware.step();
        ASSERT_LT(std::chrono::steady_clock::now() - start, kFinishingTimeout);
        const FirmwareState after = firmware.state();
        const bool calibrated =
            after == FirmwareState::Calibrating ||
            (before == FirmwareState::Calibrating && after == FirmwareState::Finishing);
        if (firmware.counters().framesProcessed == processed || !calibrated)
            continue;
        const auto frame = static_cast<std::int64_t>(firmware.lastFrame());
        frames.push_back({frame, firmware.lastFrameTime_s()});
        for (int c = 0; c < 2; ++c)
            for (const Blob& b : firmware.markerPipeline().blobs(c))
                blobs.push_back(
                    {frame, c, b.centre_px.x(), b.centre_px.y(), static_cast<double>(b.area_px)});
    }
    const auto finishing = std::chrono::steady_clock::now();
    while (firmware.state() == FirmwareState::Finishing) {
        stepBesideTheWorker(firmware);
        ASSERT_LT(std::chrono::steady_clock::now() - finishing, kFinishingTimeout);
    }
    ASSERT_EQ(firmware.models().size(), 2u) << firmware.lastEvent();
    for (const NamedModel& board : firmware.models())
        EXPECT_GE(board.model.sMin, settings->config.calibration.smin.floor);

    test::TempDir dir;
    const fs::path rec = dir.path() / "session";
    fs::create_directories(rec);
    ASSERT_TRUE(recording::writeRig(rec / "rig.toml", sim->world.rig()));
    ASSERT_TRUE(recording::writeFrames(rec / "frames.csv", frames));
    ASSERT_TRUE(recording::writeBlobs(rec / "blobs.csv", blobs, true));
    CalibrateOptions options;
    options.input = rec;
    options.out = dir.path() / "models";
    options.settings = std::move(*settings);
    std::ostringstream summary, progress;
    const Status calibrated = runCalibrate(options, summary, progress);
    ASSERT_TRUE(calibrated) << calibrated.error().message;
    EXPECT_NE(summary.str().find("settings: " + configPath.string()), std::string::npos)
        << summary.str();

    Result<std::vector<NamedModel>> offline = readModelDirectory(options.out, MarkerSet::kCapacity);
    ASSERT_TRUE(offline) << offline.error().message;
    ASSERT_EQ(offline->size(), firmware.models().size()) << summary.str();
    for (const NamedModel& board : firmware.models()) {
        const auto same = std::find_if(offline->begin(), offline->end(), [&](const NamedModel& m) {
            return m.model.id == board.model.id;
        });
        ASSERT_NE(same, offline->end()) << "body " << board.model.id;
        ASSERT_EQ(same->model.markers_model_mm.size(), board.model.markers_model_mm.size());
        // Model files keep 1e-4 mm.
        for (std::size_t m = 0; m < board.model.markers_model_mm.size(); ++m)
            EXPECT_LT((same->model.markers_model_mm[m] - board.model.markers_model_mm[m]).norm(),
                      1e-3)
                << "body " << board.model.id << " marker " << m;
        EXPECT_EQ(same->model.edges.size(), board.model.edges.size());
        EXPECT_EQ(same->model.sMin, board.model.sMin);
    }
}

TEST(OfflineMatchesBoard, CalibrateWithTheDeployedConfigLearnsTheBoardsModels) {
    expectOfflineCalibrationAsOnTheBoard(kDeployed);
}

TEST(OfflineMatchesBoard, CalibrateWithAnotherConfigLearnsTheBoardsModels) {
    test::TempDir dir;
    // S_min of at least 9 markers: the cubes' models learnt with the defaults say 7.
    expectOfflineCalibrationAsOnTheBoard(deployedWith(dir, "smin_floor", "9"));
}

} // namespace
} // namespace edgetrack::app
