// Fuzz target: a recording's CSV tables (frames, blobs, points, truth, object markers).
#include <cmath>
#include <cstdint>
#include <set>

#include "firmware_app/formats/recording.hpp"
#include "tests/fuzz/fuzz_input.hpp"

namespace {

using namespace edgetrack;

template <typename Rows>
void expectErrorNamed(const Result<Rows>& result, std::string_view name) {
    if (!result && result.error().message.rfind(name, 0) != 0)
        fuzz::fail("an error does not start with the file's name");
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    fuzz::FuzzInput in(data, size);
    const std::uint8_t table = in.byte() % 5;
    const std::string_view text = in.rest();
    switch (table) {
    case 0: {
        const auto frames = recording::parseFrames(text, "frames.csv");
        expectErrorNamed(frames, "frames.csv");
        if (frames)
            for (std::size_t i = 1; i < frames->size(); ++i)
                if ((*frames)[i].frame <= (*frames)[i - 1].frame ||
                    (*frames)[i].time_s < (*frames)[i - 1].time_s)
                    fuzz::fail("frames accepted out of order");
        break;
    }
    case 1: {
        const auto blobs = recording::parseBlobs(text, "blobs.csv");
        expectErrorNamed(blobs, "blobs.csv");
        if (blobs)
            for (const recording::BlobRow& b : *blobs)
                if (b.camera != 0 && b.camera != 1)
                    fuzz::fail("a blob of a third camera accepted");
        break;
    }
    case 2: {
        const auto points = recording::parsePoints(text, "points.csv");
        expectErrorNamed(points, "points.csv");
        if (points)
            for (std::size_t i = 1; i < points->size(); ++i)
                if ((*points)[i].frame < (*points)[i - 1].frame)
                    fuzz::fail("points accepted out of frame order");
        break;
    }
    case 3: {
        const auto truth = recording::parseTruth(text, "truth.csv");
        expectErrorNamed(truth, "truth.csv");
        if (truth)
            for (const recording::TruthRow& t : *truth)
                if (std::abs(t.T_rig_from_object.rotation.norm() - 1.0) > 1e-3)
                    fuzz::fail("a truth pose whose rotation is not unit");
        break;
    }
    default: {
        const auto markers = recording::parseObjectMarkers(text, "markers.csv");
        expectErrorNamed(markers, "markers.csv");
        if (markers) {
            std::set<int> ids;
            for (const recording::TruthMarker& m : *markers)
                if (!ids.insert(m.marker).second)
                    fuzz::fail("a marker id accepted twice");
        }
        break;
    }
    }
    return 0;
}
