// `edgetrack rig calibrate`: wand sightings of a recording into core's rig calibration.
#include "firmware_app/tools/rig_calibrate_command.hpp"

#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>

namespace edgetrack::app {

namespace fs = std::filesystem;

Result<std::vector<double>> parseWandSpacings(std::string_view text) {
    std::vector<double> spacings;
    std::size_t at = 0;
    while (at <= text.size()) {
        const std::size_t comma = std::min(text.find(',', at), text.size());
        const std::string item(text.substr(at, comma - at));
        char* end = nullptr;
        const double value = std::strtod(item.c_str(), &end);
        if (item.empty() || end != item.c_str() + item.size() || !std::isfinite(value) ||
            value <= 0.0)
            return Error{"--wand: '" + item + "' is not a positive distance in mm (D1[,D2...])"};
        spacings.push_back(value);
        at = comma + 1;
    }
    if (spacings.size() + 1 > kMaxWandMarkers)
        return Error{"--wand: at most " + std::to_string(kMaxWandMarkers - 1) + " spacings"};
    return spacings;
}

namespace {

std::string fixed(double value, int decimals) {
    char text[64];
    std::snprintf(text, sizeof(text), "%.*f", decimals, value);
    return text;
}

} // namespace

void printRigReport(const RigCalibrationReport& r, std::ostream& out) {
    out << "frame pairs with the wand in both images: " << r.framePairs << " (used " << r.framesUsed
        << ", refused " << r.framesRefused << ", left out to bound the time " << r.framesSkipped
        << ")\n";
    for (int c = 0; c < 2; ++c)
        out << "camera " << c << ": reprojection RMS "
            << fixed(r.reprojectionRms_px[static_cast<std::size_t>(c)], 3) << " px, wand seen in "
            << fixed(100.0 * r.coverage[static_cast<std::size_t>(c)], 0) << "% of the image\n";
    out << "wand length error: RMS " << fixed(r.lengthErrorRms_mm, 3) << " mm, 95th percentile "
        << fixed(r.lengthError95_mm, 3) << " mm, max " << fixed(r.lengthErrorMax_mm, 3) << " mm\n";
    out << "camera 1 moved " << fixed(r.positionChange_mm, 2) << " mm and turned "
        << fixed(r.rotationChange_deg, 3) << " degrees from the starting rig\n";
    for (const std::string& warning : r.warnings)
        out << "warning: " << warning << "\n";
    out << (r.good() ? "result: good\n" : "result: poor\n");
}

Status runRigCalibrate(const RigCalibrateOptions& options, std::ostream& report) {
    const WandSpec wand = WandSpec::fromSpacings(options.wandSpacings_mm);
    if (!wand.isValid())
        return Error{"--wand: give one to " + std::to_string(kMaxWandMarkers - 1) +
                     " positive spacings in mm"};
    Result<PixelRecording> input =
        openPixelRecording(options.input, options.from, "rig calibration");
    if (!input)
        return input.error();
    const StereoRig& start = input->rig;
    std::error_code ec;
    if (fs::exists(options.out, ec) && fs::is_directory(options.out, ec))
        return Error{options.out.string() + ": is a directory; --out names the rig.toml to write"};

    std::array<WandFinder, 2> finders{WandFinder(wand, {}), WandFinder(wand, {})};
    std::vector<WandFramePair> pairs;
    Result<FrameSourceSummary> read = forEachMarkerFrame(
        options.input, input->level, options.settings.config.markers,
        [&](const MarkerFrame& frame) -> Status {
            WandFramePair pair;
            pair.frame = frame.frame;
            for (int c = 0; c < 2; ++c) {
                std::optional<WandSighting> s =
                    finders[static_cast<std::size_t>(c)].find(start.camera(c), frame.blobs[c]);
                if (!s)
                    return Ok{};
                pair.sightings[static_cast<std::size_t>(c)] = *s;
            }
            pairs.push_back(pair);
            return Ok{};
        });
    if (!read)
        return read.error();

    const WandFinderCounters& a = finders[0].counters();
    const WandFinderCounters& b = finders[1].counters();
    report << "edgetrack rig calibrate: " << read->frames << " frames (" << read->level
           << " level); wand found in camera 0 " << a.found << ", camera 1 " << b.found
           << " (refused as ambiguous " << a.ambiguous + b.ambiguous << ", too many blobs "
           << a.tooManyBlobs + b.tooManyBlobs << ")\n";

    RigCalibrationConfig config;
    config.refineIntrinsics = options.refineIntrinsics;
    Result<RigCalibrationResult> result = calibrateRig(start, wand, pairs, config);
    if (!result)
        return result.error();
    printRigReport(result->report, report);
    if (Status s = recording::writeRig(options.out, result->rig); !s)
        return s;
    report << "wrote " << options.out.string() << "\n";
    return Ok{};
}

} // namespace edgetrack::app
