// `edgetrack reconstruct`: blob detection, stereo correspondence and triangulation of a recording.
#include "firmware_app/reconstruct_command.hpp"

#include <cstdint>
#include <map>
#include <vector>

#include "core/blob_detector.hpp"
#include "core/stereo_matcher.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;
using recording::Level;

namespace {

Status prepareOutput(const fs::path& out) {
    std::error_code ec;
    if (fs::exists(out, ec) && !fs::is_empty(out, ec))
        return Error{out.string() + ": exists and is not empty; choose a new directory"};
    fs::create_directories(out, ec);
    if (ec)
        return Error{out.string() + ": cannot create: " + ec.message()};
    return Ok{};
}

Status copyTruth(const fs::path& input, const fs::path& out) {
    std::error_code ec;
    if (fs::is_regular_file(input / "truth.csv", ec)) {
        fs::copy_file(input / "truth.csv", out / "truth.csv", ec);
        if (ec)
            return Error{(out / "truth.csv").string() + ": cannot copy: " + ec.message()};
    }
    if (fs::is_directory(input / "truth", ec)) {
        fs::copy(input / "truth", out / "truth", fs::copy_options::recursive, ec);
        if (ec)
            return Error{(out / "truth").string() + ": cannot copy: " + ec.message()};
    }
    return Ok{};
}

} // namespace

Status runReconstruct(const ReconstructOptions& options, std::ostream& summary) {
    Result<recording::Inventory> inventory = recording::inspect(options.input);
    if (!inventory)
        return inventory.error();
    Result<Level> level = recording::chooseLevel(options.input, *inventory, options.from);
    if (!level)
        return level.error();
    if (*level == Level::Points)
        return Error{options.input.string() +
                     ": holds only points; reconstruct needs images or blobs"};
    Result<StereoRig> rig = recording::readRig(options.input / "rig.toml");
    if (!rig)
        return rig.error();
    Result<std::vector<recording::FrameRow>> frames =
        recording::readFrames(options.input / "frames.csv");
    if (!frames)
        return frames.error();

    // Blob rows of the input, grouped by frame (blobs level only).
    std::map<std::int64_t, std::vector<recording::BlobRow>> inputBlobs;
    if (*level == Level::Blobs) {
        Result<std::vector<recording::BlobRow>> rows =
            recording::readBlobs(options.input / "blobs.csv");
        if (!rows)
            return rows.error();
        std::map<std::int64_t, bool> known;
        for (const recording::FrameRow& f : *frames)
            known[f.frame] = true;
        for (const recording::BlobRow& row : *rows) {
            if (!known.contains(row.frame))
                return Error{(options.input / "blobs.csv").string() + ": frame " +
                             std::to_string(row.frame) + " is not in frames.csv"};
            inputBlobs[row.frame].push_back(row);
        }
    }
    if (Status s = prepareOutput(options.out); !s)
        return s;

    const BlobDetectorConfig blobConfig;
    const CameraIntrinsics& in0 = rig->camera(0).intrinsics();
    const CameraIntrinsics& in1 = rig->camera(1).intrinsics();
    BlobDetector detector0(blobConfig, in0.width_px, in0.height_px);
    BlobDetector detector1(blobConfig, in1.width_px, in1.height_px);
    const StereoConfig stereoConfig;
    StereoMatcher stereo(*rig, stereoConfig, blobConfig.maxBlobs);
    BoundedVector<Blob> blobs[2] = {BoundedVector<Blob>(blobConfig.maxBlobs),
                                    BoundedVector<Blob>(blobConfig.maxBlobs)};
    BoundedVector<StereoMarker> markers(stereoConfig.maxMarkers);

    std::vector<recording::BlobRow> blobRows;
    std::vector<recording::PointRow> pointRows;
    for (const recording::FrameRow& frame : *frames) {
        if (*level == Level::Images) {
            for (int c = 0; c < 2; ++c) {
                const CameraIntrinsics& in = rig->camera(c).intrinsics();
                Result<recording::Image8> image = recording::readPgm(
                    recording::imagePath(options.input, frame.frame, c), in.width_px, in.height_px);
                if (!image)
                    return image.error();
                (c == 0 ? detector0 : detector1)
                    .detect(image->pixels.data(), image->width, blobs[c]);
            }
        } else {
            blobs[0].clear();
            blobs[1].clear();
            for (const recording::BlobRow& row : inputBlobs[frame.frame]) {
                Blob b;
                b.centre_px = {row.u_px, row.v_px};
                b.area_px = static_cast<float>(row.area_px.value_or(0.0));
                blobs[row.camera].push_back(b);
            }
        }
        for (int c = 0; c < 2; ++c)
            for (const Blob& b : blobs[c])
                blobRows.push_back({frame.frame, c, b.centre_px.x(), b.centre_px.y(),
                                    static_cast<double>(b.area_px)});
        stereo.match(blobs[0].span(), blobs[1].span(), markers);
        for (const StereoMarker& m : markers)
            pointRows.push_back({frame.frame, frame.time_s, m.position_rig_mm});
    }

    if (Status s = recording::writeRig(options.out / "rig.toml", *rig); !s)
        return s;
    if (Status s = recording::writeFrames(options.out / "frames.csv", *frames); !s)
        return s;
    if (Status s = recording::writeBlobs(options.out / "blobs.csv", blobRows, true); !s)
        return s;
    if (Status s = recording::writePoints(options.out / "points.csv", pointRows); !s)
        return s;
    if (Status s = copyTruth(options.input, options.out); !s)
        return s;

    // The blob vectors count every refused blob, from the detector and from blobs.csv alike (the
    // detector's own counter sees the same refusals, so adding it would count them twice).
    const std::uint64_t blobOverflow = blobs[0].overflowCount() + blobs[1].overflowCount();
    summary << "edgetrack reconstruct: " << frames->size() << " frames from "
            << recording::levelName(*level) << ", " << blobRows.size() << " blobs, "
            << pointRows.size() << " markers; rejected blobs "
            << detector0.counters().rejectedNotRound + detector1.counters().rejectedNotRound
            << " not round; blob overflow " << blobOverflow << ", marker overflow "
            << stereo.counters().markerOverflow << "\n";
    return Ok{};
}

} // namespace edgetrack::app
