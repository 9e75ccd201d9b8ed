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

namespace edgetrack::recording {

namespace fs = std::filesystem;

namespace {

class RigParser {
public:
    RigParser(std::string_view name)
        : name_(name) {}

    Error at(const toml::node& node, const std::string& key, const std::string& what) const {
        return Error{name_ + ":" + std::to_string(node.source().begin.line) + ": " + key + ": " +
                     what};
    }
    Error atFile(const std::string& what) const { return Error{name_ + ": " + what}; }

    Result<double> number(const toml::table& table, const toml::node& where,
                          const std::string& prefix, const char* key) const {
        const toml::node* node = table.get(key);
        if (node == nullptr)
            return at(where, prefix + key, "missing");
        std::optional<double> value;
        if (node->is_floating_point())
            value = node->value<double>();
        else if (node->is_integer())
            value = static_cast<double>(*node->value<std::int64_t>());
        if (!value)
            return at(*node, prefix + key, "expected a number");
        if (!std::isfinite(*value))
            return at(*node, prefix + key, "NaN and infinity are not allowed");
        return *value;
    }

    Result<int> positiveInteger(const toml::table& table, const toml::node& where,
                                const std::string& prefix, const char* key) const {
        const toml::node* node = table.get(key);
        if (node == nullptr)
            return at(where, prefix + key, "missing");
        if (!node->is_integer())
            return at(*node, prefix + key, "expected an integer");
        const std::int64_t value = *node->value<std::int64_t>();
        if (value <= 0 || value > 65535)
            return at(*node, prefix + key, "must be between 1 and 65535");
        return static_cast<int>(value);
    }

    template <std::size_t N>
    Status numbers(const toml::table& table, const toml::node& where, const std::string& prefix,
                   const char* key, std::array<double, N>& out) const {
        const toml::node* node = table.get(key);
        if (node == nullptr)
            return at(where, prefix + key, "missing");
        const toml::array* array = node->as_array();
        if (array == nullptr || array->size() != N)
            return at(*node, prefix + key,
                      "expected an array of " + std::to_string(N) + " numbers");
        for (std::size_t i = 0; i < N; ++i) {
            const toml::node* entry = array->get(i);
            if (entry == nullptr)
                return at(*node, prefix + key, "element " + std::to_string(i) + " is missing");
            const toml::node& element = *entry;
            std::optional<double> value;
            if (element.is_floating_point())
                value = element.value<double>();
            else if (element.is_integer())
                value = static_cast<double>(*element.value<std::int64_t>());
            if (!value)
                return at(element, prefix + key,
                          "element " + std::to_string(i) + " is not a number");
            if (!std::isfinite(*value))
                return at(element, prefix + key, "NaN and infinity are not allowed");
            out[i] = *value;
        }
        return Ok{};
    }

    Result<CameraModel> camera(const toml::table& table, std::size_t index) const {
        const std::string prefix = "camera[" + std::to_string(index) + "].";
        CameraIntrinsics in;
        CameraExtrinsics ex;

        Result<int> width = positiveInteger(table, table, prefix, "width");
        if (!width)
            return width.error();
        Result<int> height = positiveInteger(table, table, prefix, "height");
        if (!height)
            return height.error();
        in.width_px = *width;
        in.height_px = *height;

        std::array<double*, 4> targets{&in.fx_px, &in.fy_px, &in.cx_px, &in.cy_px};
        std::array<const char*, 4> keys{"fx", "fy", "cx", "cy"};
        for (std::size_t i = 0; i < keys.size(); ++i) {
            Result<double> v = number(table, table, prefix, keys[i]);
            if (!v)
                return v.error();
            *targets[i] = *v;
        }
        if (in.fx_px <= 0.0)
            return at(*table.get("fx"), prefix + "fx", "must be positive");
        if (in.fy_px <= 0.0)
            return at(*table.get("fy"), prefix + "fy", "must be positive");

        if (Status s = numbers(table, table, prefix, "distortion", in.distortion); !s)
            return s.error();
        std::array<double, 9> r{};
        if (Status s = numbers(table, table, prefix, "rotation", r); !s)
            return s.error();
        std::array<double, 3> t{};
        if (Status s = numbers(table, table, prefix, "translation", t); !s)
            return s.error();
        ex.rotation_cam_from_rig << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
        ex.translation_cam_from_rig_mm = {t[0], t[1], t[2]};

        CameraModel model(in, ex);
        if (!model.isValid())
            return at(*table.get("rotation"), prefix + "rotation",
                      "not a proper rotation matrix (row-major, orthonormal, det +1)");
        return model;
    }

private:
    std::string name_;
};

} // namespace

Result<StereoRig> parseRig(std::string_view text, std::string_view name) {
    const RigParser parser(name);
    const Result<toml::table> parsed = parseTomlDocument(text, name);
    if (!parsed)
        return parsed.error();
    const toml::table& root = *parsed;
    const toml::array* cameras = root["camera"].as_array();
    if (cameras == nullptr)
        return parser.atFile("missing [[camera]] tables");
    if (cameras->size() != 2)
        return parser.atFile("expected 2 [[camera]] tables, found " +
                             std::to_string(cameras->size()));
    std::array<CameraModel, 2> models;
    for (std::size_t i = 0; i < 2; ++i) {
        const toml::node* entry = cameras->get(i);
        const toml::table* table = entry != nullptr ? entry->as_table() : nullptr;
        if (table == nullptr)
            return parser.atFile("camera[" + std::to_string(i) + "] is not a table");
        Result<CameraModel> model = parser.camera(*table, i);
        if (!model)
            return model.error();
        models[i] = *model;
    }
    StereoRig rig(models[0], models[1]);
    if (!rig.isValid())
        return parser.atFile("the two cameras share one optical centre or look along the baseline");
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
