// Tests of the firmware configuration: the deployed file, and errors that name the key.
#include <fstream>
#include <iterator>
#include <string>

#include <gtest/gtest.h>

#include "firmware_app/firmware/firmware_config.hpp"
#include "tests/support/temp_dir.hpp"

namespace edgetrack::app {
namespace {

const std::filesystem::path kDeployed =
    std::filesystem::path(EDGETRACK_SOURCE_DIR) / "deploy" / "edgetrack.toml";

TEST(FirmwareConfig, TheDeployedFileStatesExactlyTheDefaults) {
    const Result<FirmwareConfig> deployed = loadFirmwareConfig(kDeployed);
    ASSERT_TRUE(deployed) << deployed.error().message;
    EXPECT_TRUE(*deployed == FirmwareConfig{})
        << "deploy/edgetrack.toml documents the defaults; change both together";
}

TEST(FirmwareConfig, EveryKeyOfTheDeployedFileIsRead) {
    // Changing each value in the file must change the configuration: no key is ignored.
    std::ifstream in(kDeployed);
    std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::size_t keys = 0;
    std::size_t lineStart = 0;
    while (lineStart < text.size()) {
        const std::size_t lineEnd = text.find('\n', lineStart);
        const std::string line = text.substr(lineStart, lineEnd - lineStart);
        const std::size_t equals = line.find(" = ");
        if (!line.empty() && line[0] != '#' && line[0] != '[' && equals != std::string::npos) {
            const std::string value = line.substr(equals + 3);
            std::string changed;
            if (value == "true" || value == "false")
                changed = value == "true" ? "false" : "true";
            else if (value.front() == '"')
                changed = "\"/x\"";
            else if (value.front() == '[')
                changed = "[\"10.1.2.3:7000\"]";
            else if (value.find('.') != std::string::npos)
                changed = std::to_string(std::stod(value) * 1.25 + 0.01);
            else
                changed = std::to_string(std::stoll(value, nullptr, 0) + 1);
            std::string edited = text;
            edited.replace(lineStart + equals + 3, value.size(), changed);
            const Result<FirmwareConfig> parsed = parseFirmwareConfig(edited, "edited.toml");
            // Some changes break a cross-check (that is an error naming the key); either way
            // the key was read.
            if (parsed) {
                EXPECT_FALSE(*parsed == FirmwareConfig{}) << "ignored: " << line;
            }
            ++keys;
        }
        lineStart = lineEnd == std::string::npos ? text.size() : lineEnd + 1;
    }
    EXPECT_GE(keys, 90u);
}

TEST(FirmwareConfig, EmptyMeansDefaults) {
    const Result<FirmwareConfig> empty = parseFirmwareConfig("", "empty.toml");
    ASSERT_TRUE(empty) << empty.error().message;
    EXPECT_TRUE(*empty == FirmwareConfig{});
}

TEST(FirmwareConfig, ValuesReachTheStages) {
    const Result<FirmwareConfig> c = parseFirmwareConfig(R"(
[gpio]
button_active_low = false
[blobs]
threshold = 90
[tracking]
distance_tolerance_mm = 0.5
max_models = 4
[output.udp]
destinations = ["239.1.2.3:5001", "localhost:6000"]
[output.can]
enabled = true
fd = true
)",
                                                         "c.toml");
    ASSERT_TRUE(c) << c.error().message;
    EXPECT_EQ(c->markers.blobs.threshold, 90);
    EXPECT_FALSE(c->gpio.buttonActiveLow);
    EXPECT_DOUBLE_EQ(c->tracking.distanceTolerance_mm, 0.5);
    EXPECT_EQ(c->maxModels, 4u);
    ASSERT_EQ(c->udp.destinations.size(), 2u);
    EXPECT_TRUE(c->udp.destinations[0].isMulticast());
    EXPECT_EQ(c->udp.destinations[0].port, 5001);
    EXPECT_EQ(c->udp.destinations[1].address, (std::array<std::uint8_t, 4>{127, 0, 0, 1}));
    EXPECT_TRUE(c->can.enabled);
    EXPECT_TRUE(c->can.fd);
}

struct BadCase {
    const char* toml;
    const char* error;
};

class FirmwareConfigErrors : public ::testing::TestWithParam<BadCase> {};

TEST_P(FirmwareConfigErrors, NameTheFileLineAndKey) {
    const Result<FirmwareConfig> c = parseFirmwareConfig(GetParam().toml, "board.toml");
    ASSERT_FALSE(c) << GetParam().toml;
    EXPECT_EQ(c.error().message, GetParam().error);
}

INSTANTIATE_TEST_SUITE_P(
    Cases, FirmwareConfigErrors,
    ::testing::Values(
        BadCase{"[tracking]\ndistance_tolerance_mm = -1\n",
                "board.toml:2: [tracking] distance_tolerance_mm: must be > 0 (got -1)"},
        BadCase{"[tracking]\ndistance_tolerence_mm = 1\n",
                "board.toml:2: [tracking] distance_tolerence_mm: unknown key"},
        BadCase{"[blobs]\nthreshold = \"high\"\n",
                "board.toml:2: [blobs] threshold: expected an integer"},
        BadCase{"[blobs]\nthreshold = 300\n",
                "board.toml:2: [blobs] threshold: must be between 1 and 255 (got 300)"},
        BadCase{"[stereo]\nmin_depth_mm = 900.0\nmax_depth_mm = 800.0\n",
                "board.toml:3: [stereo] max_depth_mm: must be > min_depth_mm"},
        BadCase{"[cameras]\nexposure_us = 20000\n",
                "board.toml:2: [cameras] exposure_us: must be shorter than the frame period"},
        BadCase{"[cameras]\nbuffers = 2\nqueue_depth = 2\n",
                "board.toml:3: [cameras] queue_depth: must be less than buffers (capture needs "
                "a free buffer)"},
        BadCase{"[output.udp]\ndestinations = [\"10.0.0.300:5000\"]\n",
                "board.toml:2: [output.udp] destinations: '10.0.0.300:5000': host must be an "
                "IPv4 address"},
        BadCase{"[output.udp]\ndestinations = [\"10.0.0.3\"]\n",
                "board.toml:2: [output.udp] destinations: '10.0.0.3': expected HOST:PORT"},
        BadCase{"[output.udp]\ndestinations = []\n",
                "board.toml:2: [output.udp] destinations: must name at least one destination "
                "while enabled"},
        BadCase{"[output.can]\nclassic_base_id = 0x7F0\n",
                "board.toml:2: [output.can] classic_base_id: with max_bodies, the classic "
                "identifiers pass 0x7FF"},
        BadCase{"[output]\nudp = 5\n", "board.toml:2: [udp] must be a table"},
        BadCase{"[output.tcp]\nport = 1\n", "board.toml:1: [output] tcp: unknown key"},
        BadCase{"[camera]\nwidth_px = 640\n", "board.toml:1: unknown section or key 'camera'"},
        BadCase{"[filter]\nenabled = 1\n",
                "board.toml:2: [filter] enabled: expected true or false"},
        BadCase{"[flash]\nsize_bytes = 10000\n",
                "board.toml:2: [flash] size_bytes: must be a whole number of erase blocks"},
        BadCase{"[tracking]\nmax_rms_mm = nan\n",
                "board.toml:2: [tracking] max_rms_mm: NaN and infinity are not allowed"},
        BadCase{"[tracking\nmax_rms_mm = 1\n",
                "board.toml:1: Error while parsing table header: expected ']', saw '\\n'"}));

TEST(FirmwareConfig, AMissingFileSaysSo) {
    const Result<FirmwareConfig> c = loadFirmwareConfig("/nonexistent/edgetrack.toml");
    ASSERT_FALSE(c);
    EXPECT_EQ(c.error().message, "/nonexistent/edgetrack.toml: cannot open for reading");
}

TEST(FirmwareConfig, ADirectoryGivenAsTheFileIsAnErrorNotTheDefaults) {
    // --config DIR ran on the built-in defaults without a word.
    test::TempDir dir;
    const Result<FirmwareConfig> c = loadFirmwareConfig(dir.path());
    ASSERT_FALSE(c);
    EXPECT_NE(c.error().message.find("is a directory"), std::string::npos) << c.error().message;
}

TEST(FirmwareConfig, CapacitiesThatTogetherExceedABoardsMemoryAreRefusedWithWhatTakesIt) {
    // Each within its range, together 1.4 TB of session buffer: the allocation at start-up
    // aborted the program (std::bad_alloc).
    const Result<FirmwareConfig> huge = parseFirmwareConfig(
        "[cameras]\nframe_rate_hz = 1000.0\nexposure_us = 100.0\n"
        "[calibration]\nmax_duration_s = 3600.0\nbuffer_points_per_frame = 4096\n",
        "board.toml");
    ASSERT_FALSE(huge);
    EXPECT_EQ(huge.error().message.rfind("board.toml: the settings need ", 0), 0u)
        << huge.error().message;
    EXPECT_NE(huge.error().message.find("calibration session buffer"), std::string::npos);
    EXPECT_EQ(huge.error().message.find('\n'), std::string::npos);
    // Images: 8192 x 8192 in 32 buffers a camera.
    EXPECT_FALSE(parseFirmwareConfig("[cameras]\nwidth_px = 8192\nheight_px = 8192\nbuffers = 32\n",
                                     "board.toml"));
    // The defaults take a tenth of the bound.
    EXPECT_LT(memoryNeed(FirmwareConfig{}).total(), kMaxMemoryNeed_bytes / 8);
}

} // namespace
} // namespace edgetrack::app
