// rig.toml (INTERFACES section 2): the two cameras' intrinsics, distortion and poses, read with
// one-line errors that name the file, the line and the key, and written back.
#include <array>
#include <cmath>
#include <cstdio>
#include <string>

#include <toml++/toml.h>

#include "firmware_app/formats/csv.hpp"
#include "firmware_app/formats/recording.hpp"
#include "firmware_app/formats/toml_document.hpp"
#include "firmware_app/formats/toml_table.hpp"

namespace edgetrack::recording {

namespace fs = std::filesystem;

namespace {

/// \brief Camera \a index of rig.toml: every key required, extra keys ignored (INTERFACES §2).
Result<CameraModel> readCamera(std::string_view name, const toml::table& table, std::size_t index) {
    std::optional<Error> error;
    TomlTableReader keys(name, "camera[" + std::to_string(index) + "].", &table, error,
                         TomlTableReader::Keys::Required);
    CameraIntrinsics in;
    CameraExtrinsics ex;
    keys.integer("width", in.width_px, 1, 65535);
    keys.integer("height", in.height_px, 1, 65535);
    keys.real("fx", in.fx_px);
    keys.real("fy", in.fy_px);
    keys.real("cx", in.cx_px);
    keys.real("cy", in.cy_px);
    keys.require(in.fx_px > 0.0, "fx", "must be positive");
    keys.require(in.fy_px > 0.0, "fy", "must be positive");
    keys.numbers("distortion", in.distortion);
    std::array<double, 9> r{};
    keys.numbers("rotation", r);
    std::array<double, 3> t{};
    keys.numbers("translation", t);
    if (error)
        return *error;
    ex.rotation_cam_from_rig << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
    ex.translation_cam_from_rig_mm = {t[0], t[1], t[2]};
    CameraModel model(in, ex);
    keys.require(model.isValid(), "rotation",
                 "not a proper rotation matrix (row-major, orthonormal, det +1)");
    if (error)
        return *error;
    if (const std::optional<double> fold = model.foldInsideImage_px()) {
        // As text, not through int: a focal length of 1e67 px puts the fold past any int.
        char radius[32];
        std::snprintf(radius, sizeof radius, "%.0f", *fold);
        keys.require(false, "distortion",
                     std::string("folds the image back ") + radius +
                         " px from the principal point, inside the image (the radius stops "
                         "growing there): no lens does that, check k1, k2, k3");
    }
    if (error)
        return *error;
    return model;
}

} // namespace

Result<StereoRig> parseRig(std::string_view text, std::string_view name) {
    auto atFile = [&](const std::string& what) { return Error{std::string(name) + ": " + what}; };
    const Result<toml::table> parsed = parseTomlDocument(text, name);
    if (!parsed)
        return parsed.error();
    const toml::table& root = *parsed;
    const toml::array* cameras = root["camera"].as_array();
    if (cameras == nullptr)
        return atFile("missing [[camera]] tables");
    if (cameras->size() != 2)
        return atFile("expected 2 [[camera]] tables, found " + std::to_string(cameras->size()));
    std::array<CameraModel, 2> models;
    for (std::size_t i = 0; i < 2; ++i) {
        const toml::node* entry = cameras->get(i);
        const toml::table* table = entry != nullptr ? entry->as_table() : nullptr;
        if (table == nullptr)
            return atFile("camera[" + std::to_string(i) + "] is not a table");
        Result<CameraModel> model = readCamera(name, *table, i);
        if (!model)
            return model.error();
        models[i] = *model;
    }
    StereoRig rig(models[0], models[1]);
    if (!rig.isValid())
        return atFile("the two cameras share one optical centre or look along the baseline");
    return rig;
}

Result<StereoRig> readRig(const fs::path& path) {
    Result<std::string> text = readTextFile(path);
    if (!text)
        return text.error();
    return parseRig(*text, path.string());
}

Status writeRig(const fs::path& path, const StereoRig& rig) {
    std::string out =
        "# stereo rig; camera 0 defines the rig frame (x right, y down, z forward, mm)\n";
    auto list = [&out](const double* values, std::size_t count) {
        out += "[";
        for (std::size_t i = 0; i < count; ++i) {
            if (i > 0)
                out += ", ";
            appendNumber(out, values[i]);
        }
        out += "]\n";
    };
    for (const CameraModel& camera : rig.cameras()) {
        const CameraIntrinsics& in = camera.intrinsics();
        const CameraExtrinsics& ex = camera.extrinsics();
        out += "\n[[camera]]\nwidth = " + std::to_string(in.width_px) +
               "\nheight = " + std::to_string(in.height_px) + "\n";
        const std::array<std::pair<const char*, double>, 4> scalars{
            {{"fx", in.fx_px}, {"fy", in.fy_px}, {"cx", in.cx_px}, {"cy", in.cy_px}}};
        for (const auto& [key, value] : scalars) {
            out += key;
            out += " = ";
            // TOML needs a decimal point for a float; to_chars omits it for whole numbers.
            std::string number;
            appendNumber(number, value);
            if (number.find_first_of(".eE") == std::string::npos)
                number += ".0";
            out += number + "\n";
        }
        out += "distortion = ";
        list(in.distortion.data(), 5);
        std::array<double, 9> r{};
        for (int row = 0; row < 3; ++row)
            for (int col = 0; col < 3; ++col)
                r[static_cast<std::size_t>(row * 3 + col)] = ex.rotation_cam_from_rig(row, col);
        out += "rotation = ";
        list(r.data(), 9);
        out += "translation = ";
        list(ex.translation_cam_from_rig_mm.data(), 3);
    }
    return writeTextFileAtomically(path, out);
}

} // namespace edgetrack::recording
