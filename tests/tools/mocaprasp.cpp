// Turns MoCapRasp's blob logs into blobs-level recordings (see mocaprasp.hpp).
#include "tests/tools/mocaprasp.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "core/stereo_rig.hpp"
#include "firmware_app/formats/recording.hpp"

namespace edgetrack::test {

namespace fs = std::filesystem;

namespace {

/// The 3 x 3 matrix named \a name in MoCapRasp's constants file: name =np.array([[..],[..],[..]]).
/// (Plain string search: GCC 12 warns inside std::regex under the sanitizers.)
Result<CameraIntrinsics> readCameraMatrix(const std::string& text, const std::string& name,
                                          const fs::path& file) {
    std::size_t at = text.find(name);
    while (at != std::string::npos && text.compare(at + name.size(), 1, " ") != 0 &&
           text.compare(at + name.size(), 1, "=") != 0)
        at = text.find(name, at + 1);
    const std::size_t open = at == std::string::npos ? at : text.find("[[", at);
    const std::size_t close = open == std::string::npos ? open : text.find("]]", open);
    if (close == std::string::npos)
        return Error{file.string() + ": no " + name};
    std::vector<double> values;
    std::string item;
    for (char ch : text.substr(open, close - open)) {
        if ((ch >= '0' && ch <= '9') || ch == '.' || ch == '-' || ch == 'e' || ch == '+') {
            item += ch;
        } else if (!item.empty()) {
            values.push_back(std::strtod(item.c_str(), nullptr));
            item.clear();
        }
    }
    if (!item.empty())
        values.push_back(std::strtod(item.c_str(), nullptr));
    if (values.size() != 9)
        return Error{file.string() + ": " + name + " is not a 3 x 3 matrix"};
    CameraIntrinsics in;
    in.width_px = 960;
    in.height_px = 720;
    in.fx_px = values[0];
    in.cx_px = values[2];
    in.fy_px = values[4];
    in.cy_px = values[5];
    return in;
}

} // namespace

Result<MoCapRaspSummary> convertMoCapRasp(const fs::path& csv, const fs::path& constants,
                                          const fs::path& out) {
    std::ifstream constantsFile(constants);
    if (!constantsFile)
        return Error{constants.string() + ": cannot open"};
    const std::string text((std::istreambuf_iterator<char>(constantsFile)),
                           std::istreambuf_iterator<char>());
    Result<CameraIntrinsics> k0 = readCameraMatrix(text, "cameraMatrix_cam1", constants);
    if (!k0)
        return k0.error();
    Result<CameraIntrinsics> k1 = readCameraMatrix(text, "cameraMatrix_cam2", constants);
    if (!k1)
        return k1.error();

    std::ifstream log(csv);
    if (!log)
        return Error{csv.string() + ": cannot open"};
    struct Image {
        double time_s = 0.0;
        double number = 0.0;
        int camera = 0;
        std::vector<Vec2> centres_px;
    };
    std::vector<Image> images;
    MoCapRaspSummary summary;
    std::string line;
    std::size_t lineNumber = 0;
    while (std::getline(log, line)) {
        ++lineNumber;
        std::vector<double> v;
        std::stringstream items(line);
        std::string item;
        while (std::getline(items, item, ','))
            v.push_back(std::strtod(item.c_str(), nullptr));
        if (v.size() < 5 || (v.size() - 3) % 2 != 0)
            return Error{csv.string() + ":" + std::to_string(lineNumber) +
                         ": expected u,v pairs then time, image number, camera"};
        Image image;
        image.time_s = v[v.size() - 3] * 1e-6;
        image.number = v[v.size() - 2];
        image.camera = static_cast<int>(std::lround(v.back()));
        if (image.camera != 0 && image.camera != 1)
            return Error{csv.string() + ":" + std::to_string(lineNumber) + ": camera not 0 or 1"};
        summary.blobsPerCamera = (v.size() - 3) / 2;
        for (std::size_t k = 0; k < summary.blobsPerCamera; ++k)
            image.centres_px.emplace_back(v[2 * k], v[2 * k + 1]);
        images.push_back(std::move(image));
    }
    if (images.empty())
        return Error{csv.string() + ": no rows"};

    // The cameras share the trigger's clock, but not always their image numbers: camera 1 of
    // 7Jun_camCalib.csv skips numbers after its image 3125, pairing images 1 to 4 s apart by
    // number. So a frame is the trigger period the image was taken in: its time over the period,
    // the period being the median time per image number of camera 0's consecutive images.
    std::vector<double> periods;
    const Image* previous = nullptr;
    for (const Image& image : images) {
        if (image.camera != 0)
            continue;
        if (previous && image.number > previous->number)
            periods.push_back((image.time_s - previous->time_s) /
                              (image.number - previous->number));
        previous = &image;
    }
    if (periods.empty())
        return Error{csv.string() + ": camera 0 has fewer than two images"};
    std::nth_element(periods.begin(), periods.begin() + static_cast<long>(periods.size() / 2),
                     periods.end());
    const double period_s = periods[periods.size() / 2];

    std::map<std::int64_t, std::array<const Image*, 2>> frames; // in time order
    for (const Image& image : images) {
        const auto frame = static_cast<std::int64_t>(std::llround(image.time_s / period_s));
        auto [at, inserted] = frames.try_emplace(frame, std::array<const Image*, 2>{});
        (void)inserted;
        const Image*& slot = at->second[static_cast<std::size_t>(image.camera)];
        if (slot)
            return Error{csv.string() + ": two images of camera " + std::to_string(image.camera) +
                         " in one trigger period"};
        slot = &image;
    }
    std::vector<recording::FrameRow> frameRows;
    std::vector<recording::BlobRow> blobs;
    for (const auto& [frame, pair] : frames) {
        frameRows.push_back({frame, static_cast<double>(frame) * period_s});
        summary.framesBothCameras += pair[0] && pair[1] ? 1u : 0u;
        for (const Image* image : pair)
            if (image)
                for (const Vec2& c : image->centres_px)
                    blobs.push_back({frame, image->camera, c.x(), c.y(), std::nullopt});
    }
    summary.frames = frameRows.size();

    CameraExtrinsics ex1;
    ex1.translation_cam_from_rig_mm = Vec3(-1000.0, 0.0, 0.0);
    const StereoRig rig(CameraModel(*k0, CameraExtrinsics{}), CameraModel(*k1, ex1));
    std::error_code ec;
    fs::create_directories(out, ec);
    if (ec)
        return Error{out.string() + ": cannot create: " + ec.message()};
    if (Status s = recording::writeRig(out / "rig.toml", rig); !s)
        return s.error();
    if (Status s = recording::writeFrames(out / "frames.csv", frameRows); !s)
        return s.error();
    if (Status s = recording::writeBlobs(out / "blobs.csv", blobs, false); !s)
        return s.error();
    return summary;
}

} // namespace edgetrack::test
