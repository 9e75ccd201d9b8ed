// Frame-by-frame reading of recordings and C3D files, with blob detection and stereo on demand.
#include "firmware_app/tools/frame_source.hpp"

#include <array>
#include <filesystem>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "core/marker_pipeline.hpp"
#include "firmware_app/formats/c3d.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;
using recording::Level;

bool isC3dFile(const fs::path& input) {
    std::string extension = input.extension().string();
    for (char& c : extension)
        if (c >= 'A' && c <= 'Z')
            c = static_cast<char>(c - 'A' + 'a');
    return extension == ".c3d";
}

Result<PixelRecording> openPixelRecording(const std::filesystem::path& input,
                                          std::optional<recording::Level> from,
                                          const std::string& what) {
    if (isC3dFile(input))
        return Error{input.string() + ": a C3D file holds only points; " + what +
                     " needs images or blobs"};
    Result<recording::Inventory> inventory = recording::inspect(input);
    if (!inventory)
        return inventory.error();
    Result<recording::Level> level = recording::chooseLevel(input, *inventory, from);
    if (!level)
        return level.error();
    if (*level == recording::Level::Points)
        return Error{input.string() + ": holds only points; " + what + " needs images or blobs"};
    Result<StereoRig> rig = recording::readRig(input / "rig.toml");
    if (!rig)
        return rig.error();
    return PixelRecording{*level, std::move(*rig)};
}

Status prepareOutputDirectory(const fs::path& out) {
    std::error_code ec;
    if (fs::exists(out, ec) && !fs::is_empty(out, ec))
        return Error{out.string() + ": exists and is not empty; choose a new directory"};
    fs::create_directories(out, ec);
    if (ec)
        return Error{out.string() + ": cannot create: " + ec.message()};
    return Ok{};
}

Result<CommandSettings> loadCommandSettings(const fs::path& path) {
    CommandSettings settings;
    if (path.empty())
        return settings;
    Result<FirmwareConfig> config = loadFirmwareConfig(path);
    if (!config)
        return config.error();
    settings.config = std::move(*config);
    settings.source = path.string();
    return settings;
}

namespace {

Result<FrameSourceSummary> readC3dFrames(const fs::path& input,
                                         const std::function<Status(const MarkerFrame&)>& visit) {
    Result<recording::C3dPoints> c3d = recording::readC3d(input);
    if (!c3d)
        return c3d.error();
    FrameSourceSummary summary;
    summary.level = "c3d";
    std::vector<Vec3> points;
    points.reserve(c3d->pointCount);
    for (std::size_t f = 0; f < c3d->frameCount; ++f) {
        points.clear();
        for (std::size_t p = 0; p < c3d->pointCount; ++p)
            if (c3d->isValid(f, p))
                points.push_back(c3d->position(f, p));
        MarkerFrame frame;
        frame.frame = c3d->firstFrame + static_cast<std::int64_t>(f);
        frame.time_s = static_cast<double>(f) / c3d->frameRate_hz;
        frame.points_rig_mm = points;
        summary.points += points.size();
        ++summary.frames;
        if (Status s = visit(frame); !s)
            return s.error();
    }
    return summary;
}

Result<FrameSourceSummary> readPointFrames(const fs::path& input,
                                           const recording::Inventory& inventory,
                                           const std::function<Status(const MarkerFrame&)>& visit) {
    Result<std::vector<recording::PointRow>> rows = recording::readPoints(input / "points.csv");
    if (!rows)
        return rows.error();
    // Frames: frames.csv when present (frames with no markers included), else those in points.csv.
    std::vector<recording::FrameRow> frames;
    if (inventory.frames) {
        Result<std::vector<recording::FrameRow>> read = recording::readFrames(input / "frames.csv");
        if (!read)
            return read.error();
        frames = std::move(*read);
    }
    std::map<std::int64_t, std::vector<Vec3>> byFrame;
    std::map<std::int64_t, double> timeOf;
    for (const recording::PointRow& row : *rows) {
        byFrame[row.frame].push_back(row.position_rig_mm);
        timeOf.emplace(row.frame, row.time_s);
    }
    if (!inventory.frames)
        for (const auto& [frame, time_s] : timeOf)
            frames.push_back({frame, time_s});
    std::set<std::int64_t> listed;
    for (const recording::FrameRow& row : frames)
        listed.insert(row.frame);
    for (const auto& entry : timeOf)
        if (!listed.contains(entry.first))
            return Error{(input / "points.csv").string() + ": frame " +
                         std::to_string(entry.first) + " is not in frames.csv"};
    FrameSourceSummary summary;
    summary.level = "points";
    if (inventory.rig) {
        Result<StereoRig> rig = recording::readRig(input / "rig.toml");
        if (!rig)
            return rig.error();
        summary.rig = std::move(*rig);
    }
    const std::vector<Vec3> none;
    for (const recording::FrameRow& row : frames) {
        auto it = byFrame.find(row.frame);
        MarkerFrame frame;
        frame.frame = row.frame;
        frame.time_s = row.time_s;
        frame.points_rig_mm = it == byFrame.end() ? std::span<const Vec3>(none) : it->second;
        summary.points += frame.points_rig_mm.size();
        ++summary.frames;
        if (Status s = visit(frame); !s)
            return s.error();
    }
    return summary;
}

Result<FrameSourceSummary>
reconstructFrames(const fs::path& input, Level level, const MarkerPipelineConfig& config,
                  const std::function<Status(const MarkerFrame&)>& visit) {
    Result<StereoRig> rig = recording::readRig(input / "rig.toml");
    if (!rig)
        return rig.error();
    Result<std::vector<recording::FrameRow>> frames = recording::readFrames(input / "frames.csv");
    if (!frames)
        return frames.error();

    std::map<std::int64_t, std::vector<recording::BlobRow>> inputBlobs;
    if (level == Level::Images) {
        // Images of a frame frames.csv does not list would be skipped in silence, as rows of
        // blobs.csv for such a frame are not (below): both are refused.
        std::set<std::int64_t> known;
        for (const recording::FrameRow& f : *frames)
            known.insert(f.frame);
        std::error_code ec;
        for (const std::filesystem::directory_entry& entry :
             std::filesystem::directory_iterator(input / "images", ec)) {
            // Other files than NNNNNN_C.pgm (INTERFACES §1) are not images of the recording.
            const std::optional<std::int64_t> frame =
                recording::imageFrameOf(entry.path().filename().string());
            if (frame && !known.contains(*frame))
                return Error{entry.path().string() + ": frame " + std::to_string(*frame) +
                             " is not in frames.csv"};
        }
        if (ec)
            return Error{(input / "images").string() + ": " + ec.message()};
    }
    if (level == Level::Blobs) {
        Result<std::vector<recording::BlobRow>> rows = recording::readBlobs(input / "blobs.csv");
        if (!rows)
            return rows.error();
        std::map<std::int64_t, bool> known;
        for (const recording::FrameRow& f : *frames)
            known[f.frame] = true;
        for (const recording::BlobRow& row : *rows) {
            if (!known.contains(row.frame))
                return Error{(input / "blobs.csv").string() + ": frame " +
                             std::to_string(row.frame) + " is not in frames.csv"};
            inputBlobs[row.frame].push_back(row);
        }
    }

    MarkerPipeline pipeline(*rig, config);
    if (!pipeline.isValid())
        return Error{(input / "rig.toml").string() + ": " + pipeline.error()};

    FrameSourceSummary summary;
    summary.level = recording::levelName(level);
    summary.rig = *rig;
    // Stereo goes back to the images to split blobs of several discs.
    std::array<recording::Image8, 2> images;
    std::array<ImageView, 2> views{};
    for (const recording::FrameRow& row : *frames) {
        if (level == Level::Images) {
            for (int c = 0; c < 2; ++c) {
                const CameraIntrinsics& in = rig->camera(c).intrinsics();
                Result<recording::Image8> image = recording::readPgm(
                    recording::imagePath(input, row.frame, c), in.width_px, in.height_px);
                if (!image)
                    return image.error();
                const auto camera = static_cast<std::size_t>(c);
                images[camera] = std::move(*image);
                views[camera] = {images[camera].pixels.data(), images[camera].width};
                pipeline.detectBlobs(c, views[camera].pixels, views[camera].stride_bytes);
            }
        } else {
            pipeline.blobs(0).clear();
            pipeline.blobs(1).clear();
            for (const recording::BlobRow& b : inputBlobs[row.frame]) {
                Blob blob;
                blob.centre_px = {b.u_px, b.v_px};
                blob.area_px = static_cast<float>(b.area_px.value_or(0.0));
                pipeline.blobs(b.camera).push_back(blob);
            }
        }
        pipeline.matchStereo(StereoMethod::Svd, views);
        MarkerFrame frame;
        frame.frame = row.frame;
        frame.time_s = row.time_s;
        frame.blobs[0] = pipeline.blobs(0).span();
        frame.blobs[1] = pipeline.blobs(1).span();
        frame.points_rig_mm = pipeline.points_rig_mm();
        summary.blobs += pipeline.blobs(0).size() + pipeline.blobs(1).size();
        summary.points += frame.points_rig_mm.size();
        ++summary.frames;
        if (Status s = visit(frame); !s)
            return s.error();
    }
    const MarkerPipelineCounters refused = pipeline.counters();
    summary.blobOverflow = refused.blobOverflow;
    summary.rejectedNotRound = refused.rejectedNotRound;
    summary.splitBlobs = refused.splitBlobs;
    summary.splitOnLines = refused.splitOnLines;
    summary.markerOverflow = refused.markerOverflow;
    return summary;
}

} // namespace

Result<FrameSourceSummary>
forEachMarkerFrame(const fs::path& input, std::optional<Level> from,
                   const MarkerPipelineConfig& config,
                   const std::function<Status(const MarkerFrame&)>& visit) {
    if (isC3dFile(input)) {
        if (from && *from != Level::Points)
            return Error{input.string() + ": a C3D file holds points only"};
        return readC3dFrames(input, visit);
    }
    Result<recording::Inventory> inventory = recording::inspect(input);
    if (!inventory)
        return inventory.error();
    Result<Level> level = recording::chooseLevel(input, *inventory, from);
    if (!level)
        return level.error();
    if (*level == Level::Points)
        return readPointFrames(input, *inventory, visit);
    return reconstructFrames(input, *level, config, visit);
}

} // namespace edgetrack::app
