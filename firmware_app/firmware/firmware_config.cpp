// Reads deploy/edgetrack.toml: known keys only, each type- and range-checked, errors naming the
// key.
#include "firmware_app/firmware/firmware_config.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <sstream>

#include <toml++/toml.h>

#include "core/marker_set.hpp"
#include "core/wand_finder.hpp"
#include "firmware_app/formats/csv.hpp"
#include "firmware_app/formats/toml_document.hpp"
#include "firmware_app/formats/toml_table.hpp"

namespace edgetrack::app {

namespace {

using Section = recording::TomlTableReader;

/// \brief "HOST:PORT" strings, each a destination.
void readEndpoints(Section& s, const char* key, std::vector<hal::UdpEndpoint>& value) {
    const toml::node* node = s.find(key);
    if (node == nullptr)
        return;
    const toml::array* array = node->as_array();
    if (array == nullptr)
        return s.fail(*node, key, "expected an array of \"HOST:PORT\" strings");
    std::vector<hal::UdpEndpoint> read;
    for (const toml::node& entry : *array) {
        if (!entry.is_string())
            return s.fail(entry, key, "expected \"HOST:PORT\" strings");
        Result<hal::UdpEndpoint> endpoint = parseEndpoint(*entry.value<std::string>());
        if (!endpoint)
            return s.fail(entry, key, endpoint.error().message);
        read.push_back(*endpoint);
    }
    value = std::move(read);
}

constexpr std::int64_t kMaxCount = 1 << 20;

void readCameras(Section& s, CameraSettings& c) {
    s.text("camera0_id", c.ids[0]);
    s.text("camera1_id", c.ids[1]);
    s.integer("width_px", c.width_px, 16, 8192);
    s.integer("height_px", c.height_px, 16, 8192);
    s.real("frame_rate_hz", c.frameRate_hz, 1.0, 1000.0);
    s.real("exposure_us", c.exposure_us, 10.0, 100000.0);
    s.real("pair_tolerance_us", c.pairTolerance_us, 0.0, 100000.0);
    s.integer("buffers", c.buffers, 2, 32);
    s.integer("queue_depth", c.queueDepth, 1, 16);
    s.real("timeout_s", c.timeout_s, 0.01, 60.0);
    s.real("retry_s", c.retry_s, 0.01, 600.0);
    s.path("rig", c.rigFile);
    s.numbers("sim_rig_knock", c.simRigKnock);
    s.require(c.exposure_us * 1e-6 < 1.0 / c.frameRate_hz, "exposure_us",
              "must be shorter than the frame period");
    s.require(c.queueDepth < static_cast<std::size_t>(c.buffers), "queue_depth",
              "must be less than buffers (capture needs a free buffer)");
}

void readGpio(Section& s, GpioSettings& g) {
    s.text("chip", g.chip);
    s.text("led_line", g.ledLine);
    s.text("button_line", g.buttonLine);
    s.text("status_line", g.statusLine);
    s.flag("button_active_low", g.buttonActiveLow);
    s.real("strobe_lead_us", g.strobeLead_us, 0.0, 10000.0);
    s.real("strobe_tail_us", g.strobeTail_us, 0.0, 10000.0);
    s.real("debounce_ms", g.debounce_ms, 0.0, 500.0);
    s.real("long_press_s", g.longPress_s, 0.5, 30.0);
    s.real("double_press_s", g.doublePress_s, 0.0, 2.0);
}

void readBlobs(Section& s, BlobDetectorConfig& b) {
    s.integer("threshold", b.threshold, 1, 255);
    s.integer("min_area_px", b.minArea_px, 1, 1 << 20);
    s.integer("max_area_px", b.maxArea_px, 1, 1 << 20);
    s.real("max_elongation", b.maxElongation, 1.0);
    s.real("min_fill", b.minFill, 0.0, 1.0);
    s.real("max_marker_elongation", b.maxMarkerElongation, 1.0);
    s.integer("max_blobs", b.maxBlobs, 1, 65535);
    s.real("keep_near_px", b.keepNear_px, 0.0);
    s.integer("max_labels", b.maxLabels, 16, kMaxCount);
    s.require(b.maxArea_px >= b.minArea_px, "max_area_px", "must be >= min_area_px");
}

void readStereo(Section& s, StereoConfig& c) {
    s.real("sigma_epipolar_px", c.sigmaEpipolar_px, 0.0, Section::kNoLimit, true);
    s.real("epipolar_band_sigmas", c.epipolarBand_sigmas, 0.0, Section::kNoLimit, true);
    s.real("sigma_similarity_px", c.sigmaSimilarity_px, 0.0, Section::kNoLimit, true);
    s.real("neighbourhood_px", c.neighbourhood_px, 0.0, Section::kNoLimit, true);
    s.real("min_depth_mm", c.minDepth_mm, 0.0, Section::kNoLimit, true);
    s.real("max_depth_mm", c.maxDepth_mm, 0.0, Section::kNoLimit, true);
    s.real("min_proximity", c.minProximity, 0.0, 1.0);
    s.real("max_ray_gap_mm", c.maxRayGap_mm, 0.0, Section::kNoLimit, true);
    s.real("max_reprojection_px", c.maxReprojection_px, 0.0, Section::kNoLimit, true);
    s.real("size_sigma", c.sizeSigma, 0.0, Section::kNoLimit);
    s.real("size_rim_px", c.sizeRimSigma_px, 0.0, Section::kNoLimit);
    s.real("continuity_mm", c.continuity_mm, 0.0, Section::kNoLimit);
    s.integer("max_carried_frames", c.maxCarriedFrames, 0, 1000);
    s.flag("seek_expected_markers", c.seekExpectedMarkers);
    s.integer("max_markers", c.maxMarkers, 1, 65535);
    s.require(c.maxDepth_mm > c.minDepth_mm, "max_depth_mm", "must be > min_depth_mm");
}

void readMarkers(Section& s, FrameToFrameConfig& c) {
    s.real("sigma_mm", c.sigma_mm, 0.0, Section::kNoLimit, true);
    s.real("gate_mm", c.gate_mm, 0.0, Section::kNoLimit, true);
    s.real("min_proximity", c.minProximity, 0.0, 1.0);
    s.real("max_prediction_gap_s", c.maxPredictionGap_s, 0.0, Section::kNoLimit, true);
    s.integer("max_markers", c.maxMarkers, 1, 65535);
}

void readCalibration(Section& s, CalibrationConfig& c, CalibrationSessionSettings& session,
                     CompletionConfig& completion) {
    s.integer("max_objects", c.maxObjects, 1, 1024);
    s.integer("max_markers_per_object", c.maxMarkersPerObject, 4,
              static_cast<std::int64_t>(MarkerSet::kCapacity));
    s.integer("max_markers", c.maxMarkers, 4, 65535);
    s.real("edge_window_frames", c.edgeWindow_frames, 1.0);
    s.real("edge_break_mm", c.edgeBreak_mm, 0.0, Section::kNoLimit, true);
    s.integer("min_lifetime_frames", c.minLifetime_frames, 0, kMaxCount);
    s.real("reappear_radius_mm", c.reappearRadius_mm, 0.0, Section::kNoLimit, true);
    s.real("pose_inlier_mm", c.poseInlier_mm, 0.0, Section::kNoLimit, true);
    s.integer("model_average_frames", c.modelAverage_frames, 1, kMaxCount);
    s.integer("min_model_frames", c.minModelFrames, 1, kMaxCount);
    s.integer("untracked_hidden_frames", c.untrackedHidden_frames, 0, kMaxCount);
    s.integer("min_model_markers", c.minModelMarkers, 4, 128);
    s.integer("max_cliques", c.maxCliques, 1, kMaxCount);
    s.integer("clique_step_budget", c.cliqueStepBudget, 1, 1LL << 40);
    s.real("smin_tolerance_mm", c.smin.tolerance_mm, 0.0, Section::kNoLimit, true);
    s.real("same_shape_share", c.smin.sameShapeShare, 0.0, 1.0, true);
    s.integer("smin_floor", c.smin.floor, 3, 128);
    s.real("min_duration_s", session.minDuration_s, 0.0, 3600.0);
    s.real("settle_s", session.settle_s, 0.1, 3600.0);
    s.real("max_duration_s", session.maxDuration_s, 1.0, 3600.0);
    s.real("preview_rate_hz", session.previewRate_hz, 0.0, 1000.0);
    s.integer("buffer_points_per_frame", session.bufferPointsPerFrame, 1, 4096);
    s.real("place_radius_mm", completion.siteRadius_mm, 0.0, Section::kNoLimit, true);
    s.real("min_seen_s", completion.minSeen_s, 0.0, 3600.0);
    s.real("min_seen_share", completion.minSeenShare, 0.0, 1.0);
    s.real("min_model_seen_s", completion.minModelSeen_s, 0.0, 3600.0);
    s.real("same_body_tolerance_mm", completion.sameBodyTolerance_mm, 0.0, Section::kNoLimit, true);
    s.real("triangle_tolerance_mm", completion.triangleTolerance_mm, 0.0, Section::kNoLimit, true);
    s.real("max_marker_residual_ratio", completion.maxResidualRatio, 1.0, Section::kNoLimit);
    s.require(session.maxDuration_s >= session.minDuration_s, "max_duration_s",
              "must be >= min_duration_s");
}

void readTracking(Section& s, ModelTrackingConfig& t, std::size_t& maxModels) {
    s.integer("max_models", maxModels, 1, 1024);
    s.real("distance_tolerance_mm", t.distanceTolerance_mm, 0.0, Section::kNoLimit, true);
    s.real("match_radius_mm", t.matchRadius_mm, 0.0, Section::kNoLimit, true);
    s.real("outlier_factor", t.outlierFactor, 1.0);
    s.real("outlier_floor_mm", t.outlierFloor_mm, 0.0);
    s.real("max_rms_mm", t.maxRms_mm, 0.0, Section::kNoLimit, true);
    s.real("rms_gate_factor", t.rmsGateFactor, 1.0);
    s.real("rms_gate_floor_mm", t.rmsGateFloor_mm, 0.0);
    s.real("prediction_radius_mm", t.predictionRadius_mm, 0.0, Section::kNoLimit, true);
    s.real("prediction_horizon_s", t.predictionHorizon_s, 0.0);
    s.integer("min_tracked_markers", t.minTrackedMarkers, 3, 128);
    s.real("min_pose_spread_mm", t.minPoseSpread_mm, 0.0);
    s.real("identity_memory_s", t.identityMemory_s, 0.0);
    s.integer("max_points", t.maxPoints, 4, 65535);
    s.integer("max_candidates_per_marker", t.maxCandidatesPerMarker, 4, 64);
    s.integer("search_budget", t.searchBudget, 1, 1LL << 40);
}

void readFilter(Section& s, PoseFilterConfig& f) {
    s.flag("enabled", f.enabled);
    s.real("pose_gain", f.poseGain, 0.0, 1.0, true);
    s.real("rate_gain", f.rateGain, 0.0, 1.0);
    s.real("predict_ahead_s", f.predictAhead_s, 0.0, 1.0);
    s.real("reset_after_s", f.resetAfter_s, 0.0, Section::kNoLimit, true);
}

void readFlash(Section& s, FlashSettings& f) {
    s.path("device", f.device);
    s.integer("size_bytes", f.size_bytes, 8192, 1LL << 32);
    s.integer("erase_block_bytes", f.eraseBlock_bytes, 256, 1LL << 24);
    s.require(f.eraseBlock_bytes > 0 && f.size_bytes % f.eraseBlock_bytes == 0, "size_bytes",
              "must be a whole number of erase blocks");
    s.require(f.size_bytes >= 2 * f.eraseBlock_bytes, "size_bytes",
              "must hold two slots of at least one erase block each");
    s.path("rig_device", f.rigDevice);
    s.integer("rig_size_bytes", f.rigSize_bytes, 512, 1LL << 32);
    s.require(f.eraseBlock_bytes > 0 && f.rigSize_bytes % f.eraseBlock_bytes == 0, "rig_size_bytes",
              "must be a whole number of erase blocks");
    s.require(f.rigSize_bytes >= 2 * f.eraseBlock_bytes, "rig_size_bytes",
              "must hold two slots of at least one erase block each");
}

void readRigCalibration(Section& s, RigCalibrationSettings& r) {
    if (const toml::node* node = s.find("wand")) {
        const toml::array* array = node->as_array();
        if (array == nullptr || array->empty() || array->size() + 1 > kMaxWandMarkers)
            return s.fail(*node, "wand",
                          "expected 1 to 7 marker spacings in mm, e.g. [55.0, 102.0]");
        std::vector<double> spacings;
        for (const toml::node& entry : *array) {
            const std::optional<double> value = entry.value<double>();
            if (!value || !(*value > 0.0) || !std::isfinite(*value))
                return s.fail(entry, "wand", "spacings must be positive numbers (mm)");
            spacings.push_back(*value);
        }
        r.wand_mm = std::move(spacings);
    }
    s.real("duration_s", r.duration_s, 1.0, 600.0);
    s.integer("max_frames", r.maxFrames, 50, kMaxCount);
    s.flag("refine_intrinsics", r.refineIntrinsics);
    s.real("drift_warning_px", r.driftWarning_px, 0.0, 100.0, true);
}

void readUdp(Section& s, UdpSettings& u) {
    s.flag("enabled", u.enabled);
    readEndpoints(s, "destinations", u.destinations);
    s.flag("latency_line", u.latencyLine);
    s.require(!u.enabled || !u.destinations.empty(), "destinations",
              "must name at least one destination while enabled");
}

void readCan(Section& s, CanSettings& c) {
    s.flag("enabled", c.enabled);
    s.text("interface", c.interface);
    s.flag("fd", c.fd);
    s.integer("bitrate", c.bitrate, 10000, 1000000);
    s.integer("data_bitrate", c.dataBitrate, 10000, 12000000);
    s.integer("classic_base_id", c.layout.classicBaseId, 0, 0x7FF);
    s.integer("fd_base_id", c.layout.fdBaseId, 0, 0x7FF);
    s.integer("max_bodies", c.layout.maxBodies, 1, 256);
    s.require(c.layout.classicBaseId + 3 * c.layout.maxBodies - 1 <= 0x7FF, "classic_base_id",
              "with max_bodies, the classic identifiers pass 0x7FF");
    s.require(c.layout.fdBaseId + c.layout.maxBodies - 1 <= 0x7FF, "fd_base_id",
              "with max_bodies, the FD identifiers pass 0x7FF");
    s.require(!c.fd || c.dataBitrate >= c.bitrate, "data_bitrate", "must be >= bitrate");
}

void readHealth(Section& s, HealthSettings& h) {
    s.real("status_interval_s", h.statusInterval_s, 0.0, 3600.0);
    s.real("frame_budget_ms", h.frameBudget_ms, 0.0, 10000.0);
}

} // namespace

CompletionConfig completionFor(const FirmwareConfig& config, const StereoRig* rig) {
    CompletionConfig c = config.completion;
    c.maxModels = config.calibration.maxObjects;
    c.maxMarkersPerModel = config.calibration.maxMarkersPerObject;
    c.minModelMarkers = config.calibration.minModelMarkers;
    c.smin = config.calibration.smin;
    if (rig != nullptr)
        c.viewpoint_rig_mm =
            0.5 * (rig->camera(0).centre_rig_mm() + rig->camera(1).centre_rig_mm());
    // Points without a stereo rig (a C3D file) come from cameras all around a room.
    c.noiseGrowsWithDistance = rig != nullptr;
    return c;
}

Result<hal::UdpEndpoint> parseEndpoint(std::string_view text) {
    const std::size_t colon = text.rfind(':');
    if (colon == std::string_view::npos)
        return Error{"'" + std::string(text) + "': expected HOST:PORT"};
    hal::UdpEndpoint endpoint;
    std::string_view host = text.substr(0, colon);
    if (host == "localhost")
        host = "127.0.0.1";
    std::size_t octet = 0;
    while (true) {
        const std::size_t dot = host.find('.');
        const std::string_view part = host.substr(0, dot);
        unsigned value = 0;
        const auto [end, ec] = std::from_chars(part.data(), part.data() + part.size(), value);
        if (part.empty() || ec != std::errc{} || end != part.data() + part.size() || value > 255 ||
            octet >= 4)
            return Error{"'" + std::string(text) + "': host must be an IPv4 address"};
        endpoint.address[octet++] = static_cast<std::uint8_t>(value);
        if (dot == std::string_view::npos)
            break;
        host.remove_prefix(dot + 1);
    }
    if (octet != 4)
        return Error{"'" + std::string(text) + "': host must be an IPv4 address"};
    const std::string_view port = text.substr(colon + 1);
    unsigned value = 0;
    const auto [end, ec] = std::from_chars(port.data(), port.data() + port.size(), value);
    if (port.empty() || ec != std::errc{} || end != port.data() + port.size() || value == 0 ||
        value > 65535)
        return Error{"'" + std::string(text) + "': port must be 1 to 65535"};
    endpoint.port = static_cast<std::uint16_t>(value);
    return endpoint;
}

Result<FirmwareConfig> parseFirmwareConfig(std::string_view text, std::string_view name) {
    const Result<toml::table> parsed = recording::parseTomlDocument(text, name);
    if (!parsed)
        return parsed.error();
    const toml::table& root = *parsed;
    FirmwareConfig config;
    std::optional<Error> error;

    auto table = [&](const toml::table& parent, std::string_view key) -> const toml::table* {
        const toml::node* node = parent.get(key);
        if (node == nullptr || error)
            return nullptr;
        if (!node->is_table())
            error = Error{std::string(name) + ":" + std::to_string(node->source().begin.line) +
                          ": [" + std::string(key) + "] must be a table"};
        return node->as_table();
    };
    auto read = [&](const toml::table& parent, std::string_view key, std::string label,
                    auto&& reader) {
        Section section(name, "[" + label + "] ", table(parent, key), error);
        reader(section);
        section.refuseUnknownKeys();
    };

    read(root, "cameras", "cameras", [&](Section& s) { readCameras(s, config.cameras); });
    read(root, "gpio", "gpio", [&](Section& s) { readGpio(s, config.gpio); });
    read(root, "blobs", "blobs", [&](Section& s) { readBlobs(s, config.markers.blobs); });
    read(root, "stereo", "stereo", [&](Section& s) { readStereo(s, config.markers.stereo); });
    read(root, "markers", "markers",
         [&](Section& s) { readMarkers(s, config.calibration.tracking); });
    read(root, "calibration", "calibration", [&](Section& s) {
        readCalibration(s, config.calibration, config.session, config.completion);
    });
    read(root, "tracking", "tracking",
         [&](Section& s) { readTracking(s, config.tracking, config.maxModels); });
    read(root, "filter", "filter", [&](Section& s) { readFilter(s, config.filter); });
    read(root, "flash", "flash", [&](Section& s) { readFlash(s, config.flash); });
    read(root, "rig_calibration", "rig_calibration",
         [&](Section& s) { readRigCalibration(s, config.rig); });
    read(root, "health", "health", [&](Section& s) { readHealth(s, config.health); });
    if (const toml::table* output = table(root, "output")) {
        read(*output, "udp", "output.udp", [&](Section& s) { readUdp(s, config.udp); });
        read(*output, "can", "output.can", [&](Section& s) { readCan(s, config.can); });
        Section outputSection(name, "[output] ", output, error);
        outputSection.allowTable("udp");
        outputSection.allowTable("can");
        outputSection.refuseUnknownKeys();
    }
    if (!error) {
        static constexpr std::string_view kSections[] = {
            "cameras",  "gpio",   "blobs", "stereo",          "markers", "calibration",
            "tracking", "filter", "flash", "rig_calibration", "health",  "output"};
        for (const auto& [key, node] : root) {
            bool known = false;
            for (std::string_view section : kSections)
                known = known || key.str() == section;
            if (!known) {
                error = Error{std::string(name) + ":" + std::to_string(node.source().begin.line) +
                              ": unknown section or key '" + std::string(key.str()) + "'"};
                break;
            }
        }
    }
    if (error)
        return *error;
    // Every capacity is within its range, but together they may ask for more memory than a board
    // has: refused here, with what takes it, rather than a failed allocation at start-up.
    if (const MemoryNeed need = memoryNeed(config); need.total() > kMaxMemoryNeed_bytes) {
        constexpr double kMb = 1024.0 * 1024.0;
        char why[320];
        std::snprintf(
            why, sizeof why,
            "the settings need %.0f MB of memory (camera images %.0f, blob detection "
            "%.0f, calibration session buffer %.0f, flash %.0f), more than the %.0f MB "
            "a board keeps for edgetrack: lower [cameras] width_px, height_px or "
            "buffers, [calibration] max_duration_s or buffer_points_per_frame, or "
            "[flash] size_bytes",
            static_cast<double>(need.total()) / kMb, static_cast<double>(need.images) / kMb,
            static_cast<double>(need.detection) / kMb, static_cast<double>(need.session) / kMb,
            static_cast<double>(need.flash) / kMb, static_cast<double>(kMaxMemoryNeed_bytes) / kMb);
        return Error{std::string(name) + ": " + why};
    }
    return config;
}

std::size_t sessionFrames(const FirmwareConfig& config) {
    return static_cast<std::size_t>(
               std::ceil(config.session.maxDuration_s * config.cameras.frameRate_hz * 1.05)) +
           16;
}

MemoryNeed memoryNeed(const FirmwareConfig& config) {
    MemoryNeed need;
    const auto pixels = static_cast<std::uint64_t>(config.cameras.width_px) *
                        static_cast<std::uint64_t>(config.cameras.height_px);
    need.images = 2 * 3 * static_cast<std::uint64_t>(config.cameras.buffers) * pixels;
    // Labels (32-bit) and a byte mask per pixel, per camera.
    need.detection = 2 * 5 * pixels;
    // Each point 24 bytes; each frame its time and where its points start.
    need.session = static_cast<std::uint64_t>(sessionFrames(config)) *
                   (24 * static_cast<std::uint64_t>(config.session.bufferPointsPerFrame) + 16);
    need.flash = static_cast<std::uint64_t>(config.flash.size_bytes) +
                 static_cast<std::uint64_t>(config.flash.rigSize_bytes);
    return need;
}

Result<FirmwareConfig> loadFirmwareConfig(const std::filesystem::path& path) {
    Result<std::string> text = recording::readTextFile(path);
    if (!text)
        return text.error();
    return parseFirmwareConfig(*text, path.string());
}

} // namespace edgetrack::app
