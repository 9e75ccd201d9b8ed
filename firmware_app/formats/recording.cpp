// Reading and writing recording directories (INTERFACES §1): frames, images, blobs, points, truth
// (rig.toml is rig_file.cpp's).
#include "firmware_app/formats/recording.hpp"

#include <array>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <set>

#include "firmware_app/formats/csv.hpp"

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

/// The rows of a table with \a columns, each made a T by \a convert (which may refuse it with an
/// error, and may keep state from row to row: frame order).
template <typename T, std::size_t N, typename Convert>
Result<std::vector<T>> parseRows(std::string_view text, std::string_view name,
                                 const std::array<CsvColumn, N>& columns, Convert convert) {
    Result<CsvTable> table = parseCsv(text, name, columns);
    if (!table)
        return table.error();
    std::vector<T> rows;
    rows.reserve(table->rows.size());
    for (const CsvRow& row : table->rows) {
        Result<T> converted = convert(row);
        if (!converted)
            return converted.error();
        rows.push_back(std::move(*converted));
    }
    return rows;
}

} // namespace

// ---------------------------------------------------------------------------------------------
// CSV files

Result<std::vector<FrameRow>> parseFrames(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 2> kColumns{
        {{"frame", ColumnType::Integer}, {"time_s", ColumnType::Real}}};
    std::int64_t previous = kNoFrameYet;
    double previousTime = -std::numeric_limits<double>::infinity();
    return parseRows<FrameRow>(text, name, kColumns, [&](const CsvRow& row) -> Result<FrameRow> {
        if (Status s = checkFrameOrder(name, row, previous, true); !s)
            return s.error();
        if (row[1] < previousTime)
            return rowError(name, row, "time_s goes backwards");
        previous = row.integer(0);
        previousTime = row[1];
        return FrameRow{row.integer(0), row[1]};
    });
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
    std::int64_t previous = kNoFrameYet;
    return parseRows<BlobRow>(text, name, kColumns, [&](const CsvRow& row) -> Result<BlobRow> {
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
        return blob;
    });
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
    std::int64_t previous = kNoFrameYet;
    double previousTime = 0.0;
    return parseRows<PointRow>(text, name, kColumns, [&](const CsvRow& row) -> Result<PointRow> {
        if (Status s = checkFrameOrder(name, row, previous, false); !s)
            return s.error();
        if (row.integer(0) == previous && row[1] != previousTime)
            return rowError(name, row, "time_s differs from the frame's earlier rows");
        if (row.integer(0) != previous && previous != kNoFrameYet && row[1] < previousTime)
            return rowError(name, row, "time_s goes backwards");
        previous = row.integer(0);
        previousTime = row[1];
        return PointRow{row.integer(0), row[1], Vec3{row[2], row[3], row[4]}};
    });
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
    std::int64_t previous = kNoFrameYet;
    return parseRows<TruthRow>(text, name, kColumns, [&](const CsvRow& row) -> Result<TruthRow> {
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
        return truth;
    });
}

Result<std::vector<TruthRow>> readTruth(const fs::path& path) {
    return readWith(path, parseTruth);
}

Result<std::vector<TruthMarker>> parseObjectMarkers(std::string_view text, std::string_view name) {
    static constexpr std::array<CsvColumn, 4> kColumns{{{"marker", ColumnType::Integer},
                                                        {"x", ColumnType::Real},
                                                        {"y", ColumnType::Real},
                                                        {"z", ColumnType::Real}}};
    std::set<std::int64_t> seen;
    return parseRows<TruthMarker>(
        text, name, kColumns, [&](const CsvRow& row) -> Result<TruthMarker> {
            if (row.integer(0) < 0)
                return rowError(name, row, "marker id is negative");
            if (!seen.insert(row.integer(0)).second)
                return rowError(name, row,
                                "marker " + std::to_string(row.integer(0)) + " appears twice");
            return TruthMarker{static_cast<int>(row.integer(0)), Vec3{row[1], row[2], row[3]}};
        });
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

std::optional<std::int64_t> imageFrameOf(std::string_view fileName) {
    // As imagePath() writes them: six digits, '_', the camera, ".pgm".
    if (fileName.size() != 12 || fileName[6] != '_' || (fileName[7] != '0' && fileName[7] != '1') ||
        fileName.substr(8) != ".pgm")
        return std::nullopt;
    std::int64_t frame = 0;
    for (const char c : fileName.substr(0, 6)) {
        if (c < '0' || c > '9')
            return std::nullopt;
        frame = frame * 10 + (c - '0');
    }
    return frame;
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
