// `edgetrack reconstruct`: blob detection, stereo correspondence and triangulation of a recording.
#include "firmware_app/tools/reconstruct_command.hpp"

#include <cstdint>
#include <map>
#include <vector>

#include "firmware_app/tools/frame_source.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;

namespace {

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
    Result<PixelRecording> input = openPixelRecording(options.input, options.from, "reconstruct");
    if (!input)
        return input.error();
    const StereoRig& rig = input->rig;
    Result<std::vector<recording::FrameRow>> frames =
        recording::readFrames(options.input / "frames.csv");
    if (!frames)
        return frames.error();
    if (Status s = prepareOutputDirectory(options.out); !s)
        return s;

    std::vector<recording::BlobRow> blobRows;
    std::vector<recording::PointRow> pointRows;
    Result<FrameSourceSummary> read = forEachMarkerFrame(
        options.input, input->level, options.settings.config.markers,
        [&](const MarkerFrame& frame) -> Status {
            for (int c = 0; c < 2; ++c)
                for (const Blob& b : frame.blobs[c])
                    blobRows.push_back({frame.frame, c, b.centre_px.x(), b.centre_px.y(),
                                        static_cast<double>(b.area_px)});
            for (const Vec3& p : frame.points_rig_mm)
                pointRows.push_back({frame.frame, frame.time_s, p});
            return Ok{};
        });
    if (!read)
        return read.error();

    if (Status s = recording::writeRig(options.out / "rig.toml", rig); !s)
        return s;
    if (Status s = recording::writeFrames(options.out / "frames.csv", *frames); !s)
        return s;
    if (Status s = recording::writeBlobs(options.out / "blobs.csv", blobRows, true); !s)
        return s;
    if (Status s = recording::writePoints(options.out / "points.csv", pointRows); !s)
        return s;
    if (Status s = copyTruth(options.input, options.out); !s)
        return s;

    summary << "edgetrack reconstruct: " << read->frames << " frames from " << read->level << ", "
            << blobRows.size() << " blobs, " << pointRows.size() << " markers; rejected blobs "
            << read->rejectedNotRound << " not round (" << read->splitBlobs
            << " of them split into their discs); " << read->splitOnLines
            << " blobs split on the other camera's epipolar lines; blob overflow "
            << read->blobOverflow << ", marker overflow " << read->markerOverflow << "\n"
            << "  settings: " << options.settings.source << "\n";
    return Ok{};
}

} // namespace edgetrack::app
