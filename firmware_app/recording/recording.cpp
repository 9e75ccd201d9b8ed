// Reading and writing recording directories (INTERFACES §1-2): rig, frames, images, blobs, points,
// truth.
#include "firmware_app/recording/recording.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>

#include <toml++/toml.h>

#include "firmware_app/recording/csv.hpp"
#include "firmware_app/recording/toml_document.hpp"

namespace edgetrack::recording {

namespace fs = std::filesystem;

const char* levelName(Level level) {
    switch (level) {
    case Level::Images:
        return "images";
    case Level::Blobs:
        return "blobs";
    case Level::Points:
        return "points";
    }
    return "?";
}

std::optional<Level> parseLevel(std::string_view name) {
    for (Level level : {Level::Images, Level::Blobs, Level::Points})
        if (name == levelName(level))
            return level;
    return std::nullopt;
}

namespace {

Error rowError(std::string_view name, const CsvRow& row, const std::string& what) {
    return Error{std::string(name) + ":" + std::to_string(row.line) + ": " + what};
}

// Rows of blobs, points and truth come grouped by frame in increasing order; frames.csv is strict.
Status checkFrameOrder(std::string_view name, const CsvRow& row, std::int64_t previous,
                       bool strictlyIncreasing) {
    const std::int64_t frame = row.integer(0);
    if (frame < 0)
        return rowError(name, row, "frame " + std::to_string(frame) + " is negative");
    if (frame < previous || (strictlyIncreasing && frame == previous))
        return rowError(name, row,
                        "frames out of order: frame " + std::to_string(frame) + " after frame " +
                            std::to_string(previous));
    return Ok{};
}

constexpr std::int64_t kNoFrameYet = -1;

/// The file at \a path read whole and given to \a parse with its path as the name in errors.
template <typename Parse>
auto readWith(const fs::path& path, Parse parse) -> decltype(parse(std::string_view{}, "")) {
    Result<std::string> text = readTextFile(path);
    if (!text)
        return text.error();
    return parse(*text, path.string());
}

} // namespace

// ---------------------------------------------------------------------------------------------
// CSV files

Result<std::vector<FrameRow>> parseFrames(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 2> kColumns{
        {{"frame", ColumnType::Integer}, {"time_s", ColumnType::Real}}};
    Result<CsvTable> table = parseCsv(text, name, kColumns);
    if (!table)
        return table.error();
    std::vector<FrameRow> rows;
    rows.reserve(table->rows.size());
    std::int64_t previous = kNoFrameYet;
    double previousTime = -std::numeric_limits<double>::infinity();
    for (const CsvRow& row : table->rows) {
        if (Status s = checkFrameOrder(name, row, previous, true); !s)
            return s.error();
        if (row[1] < previousTime)
            return rowError(name, row, "time_s goes backwards");
        previous = row.integer(0);
        previousTime = row[1];
        rows.push_back({row.integer(0), row[1]});
    }
    return rows;
}

Result<std::vector<FrameRow>> readFrames(const fs::path& path) {
    return readWith(path, parseFrames);
}

Result<std::vector<BlobRow>> parseBlobs(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 5> kColumns{{{"frame", ColumnType::Integer},
                                                        {"camera", ColumnType::Integer},
                                                        {"u", ColumnType::Real},
                                                        {"v", ColumnType::Real},
                                                        {"area", ColumnType::Real, true}}};
    Result<CsvTable> table = parseCsv(text, name, kColumns);
    if (!table)
        return table.error();
    std::vector<BlobRow> rows;
    rows.reserve(table->rows.size());
    std::int64_t previous = kNoFrameYet;
    for (const CsvRow& row : table->rows) {
        if (Status s = checkFrameOrder(name, row, previous, false); !s)
            return s.error();
        previous = row.integer(0);
        const std::int64_t camera = row.integer(1);
        if (camera != 0 && camera != 1)
            return rowError(name, row, "camera must be 0 or 1, found " + std::to_string(camera));
        BlobRow blob;
        blob.frame = row.integer(0);
        blob.camera = static_cast<int>(camera);
        blob.u_px = row[2];
        blob.v_px = row[3];
        if (row.fieldCount == 5) {
            if (row[4] < 0.0)
                return rowError(name, row, "area is negative");
            blob.area_px = row[4];
        }
        rows.push_back(blob);
    }
    return rows;
}

Result<std::vector<BlobRow>> readBlobs(const fs::path& path) {
    return readWith(path, parseBlobs);
}

Result<std::vector<PointRow>> parsePoints(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 5> kColumns{{{"frame", ColumnType::Integer},
                                                        {"time_s", ColumnType::Real},
                                                        {"x", ColumnType::Real},
                                                        {"y", ColumnType::Real},
                                                        {"z", ColumnType::Real}}};
    Result<CsvTable> table = parseCsv(text, name, kColumns);
    if (!table)
        return table.error();
    std::vector<PointRow> rows;
    rows.reserve(table->rows.size());
    std::int64_t previous = kNoFrameYet;
    double previousTime = 0.0;
    for (const CsvRow& row : table->rows) {
        if (Status s = checkFrameOrder(name, row, previous, false); !s)
            return s.error();
        if (row.integer(0) == previous && row[1] != previousTime)
            return rowError(name, row, "time_s differs from the frame's earlier rows");
        if (row.integer(0) != previous && previous != kNoFrameYet && row[1] < previousTime)
            return rowError(name, row, "time_s goes backwards");
        previous = row.integer(0);
        previousTime = row[1];
        rows.push_back({row.integer(0), row[1], Vec3{row[2], row[3], row[4]}});
    }
    return rows;
}

Result<std::vector<PointRow>> readPoints(const fs::path& path) {
    return readWith(path, parsePoints);
}

Result<std::vector<TruthRow>> parseTruth(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 10> kColumns{{{"frame", ColumnType::Integer},
                                                         {"time_s", ColumnType::Real},
                                                         {"object", ColumnType::Integer},
                                                         {"x", ColumnType::Real},
                                                         {"y", ColumnType::Real},
                                                         {"z", ColumnType::Real},
                                                         {"qw", ColumnType::Real},
                                                         {"qx", ColumnType::Real},
                                                         {"qy", ColumnType::Real},
                                                         {"qz", ColumnType::Real}}};
    Result<CsvTable> table = parseCsv(text, name, kColumns);
    if (!table)
        return table.error();
    std::vector<TruthRow> rows;
    rows.reserve(table->rows.size());
    std::int64_t previous = kNoFrameYet;
    for (const CsvRow& row : table->rows) {
        if (Status s = checkFrameOrder(name, row, previous, false); !s)
            return s.error();
        previous = row.integer(0);
        if (row.integer(2) < 0)
            return rowError(name, row, "object id is negative");
        const double norm =
            std::sqrt(row[6] * row[6] + row[7] * row[7] + row[8] * row[8] + row[9] * row[9]);
        // Six printed digits per component keep the norm within 1e-5 of one; allow for that.
        if (std::abs(norm - 1.0) > 1e-4)
            return rowError(name, row,
                            "quaternion is not unit (norm " + std::to_string(norm) + ")");
        TruthRow truth;
        truth.frame = row.integer(0);
        truth.time_s = row[1];
        truth.object = static_cast<int>(row.integer(2));
        truth.T_rig_from_object.translation_mm = {row[3], row[4], row[5]};
        truth.T_rig_from_object.rotation = quaternionFromWxyz(row[6], row[7], row[8], row[9]);
        rows.push_back(truth);
    }
    return rows;
}

Result<std::vector<TruthRow>> readTruth(const fs::path& path) {
    return readWith(path, parseTruth);
}

Result<std::vector<TruthMarker>> parseObjectMarkers(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 4> kColumns{{{"marker", ColumnType::Integer},
                                                        {"x", ColumnType::Real},
                                                        {"y", ColumnType::Real},
                                                        {"z", ColumnType::Real}}};
    Result<CsvTable> table = parseCsv(text, name, kColumns);
    if (!table)
        return table.error();
    std::vector<TruthMarker> markers;
    markers.reserve(table->rows.size());
    for (const CsvRow& row : table->rows) {
        if (row.integer(0) < 0)
            return rowError(name, row, "marker id is negative");
        for (const TruthMarker& m : markers)
            if (m.marker == row.integer(0))
                return rowError(name, row, "marker " + std::to_string(m.marker) + " appears twice");
        markers.push_back({static_cast<int>(row.integer(0)), Vec3{row[1], row[2], row[3]}});
    }
    return markers;
}

Result<std::vector<TruthMarker>> readObjectMarkers(const fs::path& path) {
    return readWith(path, parseObjectMarkers);
}

Status writeFrames(const fs::path& path, const std::vector<FrameRow>& rows) {
    std::string out = "frame,time_s\n";
    for (const FrameRow& r : rows)
        appendCsvLine(out, r.frame, r.time_s);
    return writeTextFileAtomically(path, out);
}

Status writeBlobs(const fs::path& path, const std::vector<BlobRow>& rows, bool withArea) {
    std::string out = withArea ? "frame,camera,u,v,area\n" : "frame,camera,u,v\n";
    for (const BlobRow& r : rows) {
        if (withArea)
            appendCsvLine(out, r.frame, std::int64_t{r.camera}, r.u_px, r.v_px,
                          r.area_px.value_or(0.0));
        else
            appendCsvLine(out, r.frame, std::int64_t{r.camera}, r.u_px, r.v_px);
    }
    return writeTextFileAtomically(path, out);
}

Status writePoints(const fs::path& path, const std::vector<PointRow>& rows) {
    std::string out = "frame,time_s,x,y,z\n";
    for (const PointRow& r : rows)
        appendCsvLine(out, r.frame, r.time_s, r.position_rig_mm.x(), r.position_rig_mm.y(),
                      r.position_rig_mm.z());
    return writeTextFileAtomically(path, out);
}

Status writeTruth(const fs::path& path, const std::vector<TruthRow>& rows) {
    std::string out = "frame,time_s,object,x,y,z,qw,qx,qy,qz\n";
    for (const TruthRow& r : rows) {
        const Vec3& t = r.T_rig_from_object.translation_mm;
        const std::array<double, 4> q = wxyzFromQuaternion(r.T_rig_from_object.rotation);
        appendCsvLine(out, r.frame, r.time_s, std::int64_t{r.object}, t.x(), t.y(), t.z(), q[0],
                      q[1], q[2], q[3]);
    }
    return writeTextFileAtomically(path, out);
}

Status writeObjectMarkers(const fs::path& path, const std::vector<TruthMarker>& markers) {
    std::string out = "marker,x,y,z\n";
    for (const TruthMarker& m : markers)
        appendCsvLine(out, std::int64_t{m.marker}, m.position_object_mm.x(),
                      m.position_object_mm.y(), m.position_object_mm.z());
    return writeTextFileAtomically(path, out);
}

// ---------------------------------------------------------------------------------------------
// rig.toml

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

// ---------------------------------------------------------------------------------------------
// PGM images

namespace {

// Reads one header token of a PGM, skipping whitespace and '#' comments.
std::string_view pgmToken(std::string_view bytes, std::size_t& position) {
    while (position < bytes.size()) {
        const char c = bytes[position];
        if (c == '#') {
            while (position < bytes.size() && bytes[position] != '\n')
                ++position;
        } else if (c == ' ' || c == '\t' || c == '\n' || c == '\r') {
            ++position;
        } else {
            break;
        }
    }
    const std::size_t start = position;
    while (position < bytes.size() && bytes[position] != ' ' && bytes[position] != '\t' &&
           bytes[position] != '\n' && bytes[position] != '\r' && bytes[position] != '#')
        ++position;
    return bytes.substr(start, position - start);
}

std::optional<int> pgmNumber(std::string_view token) {
    int value = 0;
    const auto [end, ec] = std::from_chars(token.data(), token.data() + token.size(), value);
    if (token.empty() || ec != std::errc{} || end != token.data() + token.size() || value < 0)
        return std::nullopt;
    return value;
}

} // namespace

Result<Image8> parsePgm(std::string_view bytes, std::string_view name, int expectedWidth,
                        int expectedHeight) {
    const std::string file(name);
    std::size_t position = 0;
    const std::string_view magic = pgmToken(bytes, position);
    if (magic != "P5")
        return Error{file + ": not a binary 8-bit PGM (P5): magic is \"" +
                     std::string(magic.substr(0, 8)) + "\""};
    const std::optional<int> width = pgmNumber(pgmToken(bytes, position));
    const std::optional<int> height = pgmNumber(pgmToken(bytes, position));
    const std::optional<int> maxval = pgmNumber(pgmToken(bytes, position));
    if (!width || !height || !maxval || *width == 0 || *height == 0)
        return Error{file + ": malformed PGM header"};
    if (*maxval != 255)
        return Error{file + ": PGM maxval is " + std::to_string(*maxval) +
                     ", expected 255 (8-bit)"};
    if ((expectedWidth > 0 && *width != expectedWidth) ||
        (expectedHeight > 0 && *height != expectedHeight))
        return Error{file + ": image is " + std::to_string(*width) + "x" + std::to_string(*height) +
                     ", rig.toml says " + std::to_string(expectedWidth) + "x" +
                     std::to_string(expectedHeight)};
    // Exactly one whitespace byte separates the header from the raster.
    if (position >= bytes.size())
        return Error{file + ": truncated image: no pixel data"};
    ++position;

    const std::size_t expected =
        static_cast<std::size_t>(*width) * static_cast<std::size_t>(*height);
    const std::size_t present = bytes.size() - position;
    if (present < expected)
        return Error{file + ": truncated image: " + std::to_string(present) + " of " +
                     std::to_string(expected) + " pixel bytes"};
    if (present > expected)
        return Error{file + ": " + std::to_string(present - expected) +
                     " bytes after the pixel data"};
    Image8 image;
    image.width = *width;
    image.height = *height;
    image.pixels.assign(bytes.begin() + static_cast<std::ptrdiff_t>(position), bytes.end());
    return image;
}

Result<Image8> readPgm(const fs::path& path, int expectedWidth, int expectedHeight) {
    Result<std::string> bytes = readTextFile(path);
    if (!bytes)
        return bytes.error();
    return parsePgm(*bytes, path.string(), expectedWidth, expectedHeight);
}

Status writePgm(const fs::path& path, const Image8& image) {
    const std::size_t size =
        static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height);
    if (image.width <= 0 || image.height <= 0 || image.pixels.size() != size)
        return Error{path.string() + ": image size does not match its pixel buffer"};
    std::string out =
        "P5\n" + std::to_string(image.width) + " " + std::to_string(image.height) + "\n255\n";
    out.append(reinterpret_cast<const char*>(image.pixels.data()), image.pixels.size());
    return writeTextFileAtomically(path, out);
}

fs::path imagePath(const fs::path& recording, std::int64_t frame, int camera) {
    std::array<char, 32> name{};
    std::snprintf(name.data(), name.size(), "%06lld_%d.pgm", static_cast<long long>(frame), camera);
    return recording / "images" / name.data();
}

// ---------------------------------------------------------------------------------------------
// Directory level

Result<Inventory> inspect(const fs::path& recording) {
    std::error_code ec;
    if (!fs::is_directory(recording, ec))
        return Error{recording.string() + ": not a recording directory"};
    Inventory inventory;
    inventory.rig = fs::is_regular_file(recording / "rig.toml", ec);
    inventory.frames = fs::is_regular_file(recording / "frames.csv", ec);
    inventory.images = fs::is_directory(recording / "images", ec);
    inventory.blobs = fs::is_regular_file(recording / "blobs.csv", ec);
    inventory.points = fs::is_regular_file(recording / "points.csv", ec);
    inventory.truth = fs::is_regular_file(recording / "truth.csv", ec);
    return inventory;
}

Result<Level> chooseLevel(const fs::path& recording, const Inventory& inventory,
                          std::optional<Level> requested) {
    auto present = [&inventory](Level level) {
        switch (level) {
        case Level::Images:
            return inventory.images;
        case Level::Blobs:
            return inventory.blobs;
        case Level::Points:
            return inventory.points;
        }
        return false;
    };
    std::optional<Level> level = requested;
    if (!level) {
        for (Level candidate : {Level::Images, Level::Blobs, Level::Points})
            if (present(candidate)) {
                level = candidate;
                break;
            }
        if (!level)
            return Error{recording.string() + ": holds no images/, blobs.csv or points.csv"};
    }
    if (!present(*level))
        return Error{recording.string() + ": has no " + levelName(*level) + " level"};
    if (*level != Level::Points && !inventory.rig)
        return Error{recording.string() + ": the " + std::string(levelName(*level)) +
                     " level needs rig.toml"};
    if (*level != Level::Points && !inventory.frames)
        return Error{recording.string() + ": the " + std::string(levelName(*level)) +
                     " level needs frames.csv"};
    return *level;
}

} // namespace edgetrack::recording
