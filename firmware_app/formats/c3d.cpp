// C3D reader: header, parameter section (POINT group) and 3D point records in three number formats.
#include "firmware_app/formats/c3d.hpp"

#include <bit>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <map>
#include <optional>

#include "firmware_app/formats/csv.hpp"

namespace edgetrack::recording {

namespace {

constexpr std::size_t kBlock = 512;
constexpr std::uint8_t kIntel = 84, kDec = 85, kMips = 86;

/// Reads numbers in the file's format with bounds checks; every read past the end fails.
class Reader {
public:
    Reader(std::string_view bytes, std::uint8_t processor)
        : bytes_(bytes)
        , processor_(processor) {}

    void setProcessor(std::uint8_t processor) { processor_ = processor; }
    bool has(std::size_t offset, std::size_t size) const {
        return offset <= bytes_.size() && size <= bytes_.size() - offset;
    }
    std::uint8_t u8(std::size_t offset) const { return static_cast<std::uint8_t>(bytes_[offset]); }
    std::int8_t i8(std::size_t offset) const { return static_cast<std::int8_t>(u8(offset)); }
    std::uint16_t u16(std::size_t offset) const {
        const std::uint16_t a = u8(offset), b = u8(offset + 1);
        return processor_ == kMips ? static_cast<std::uint16_t>((a << 8) | b)
                                   : static_cast<std::uint16_t>((b << 8) | a);
    }
    std::int16_t i16(std::size_t offset) const { return static_cast<std::int16_t>(u16(offset)); }
    float f32(std::size_t offset) const {
        std::uint8_t b[4];
        for (std::size_t i = 0; i < 4; ++i)
            b[i] = u8(offset + i);
        std::uint32_t bits = 0;
        if (processor_ == kMips) {
            bits = (std::uint32_t{b[0]} << 24) | (std::uint32_t{b[1]} << 16) |
                   (std::uint32_t{b[2]} << 8) | b[3];
        } else if (processor_ == kDec) {
            // VAX F-float: 16-bit halves swapped against IEEE, exponent bias larger by two.
            bits = (std::uint32_t{b[1]} << 24) | (std::uint32_t{b[0]} << 16) |
                   (std::uint32_t{b[3]} << 8) | b[2];
            if (bits == 0)
                return 0.0f;
            return std::bit_cast<float>(bits) / 4.0f;
        } else {
            bits = (std::uint32_t{b[3]} << 24) | (std::uint32_t{b[2]} << 16) |
                   (std::uint32_t{b[1]} << 8) | b[0];
        }
        return std::bit_cast<float>(bits);
    }
    std::string_view text(std::size_t offset, std::size_t size) const {
        return bytes_.substr(offset, size);
    }
    std::size_t size() const { return bytes_.size(); }

private:
    std::string_view bytes_;
    std::uint8_t processor_;
};

struct Parameter {
    std::int8_t type = 0; // -1 char, 1 byte, 2 int16, 4 float
    std::vector<std::size_t> dimensions;
    std::size_t dataOffset = 0;
    std::size_t dataSize = 0;
};

std::string upper(std::string_view s) {
    std::string out(s);
    for (char& c : out)
        if (c >= 'a' && c <= 'z')
            c = static_cast<char>(c - 'a' + 'A');
    return out;
}

std::string trim(std::string_view s) {
    std::size_t begin = 0, end = s.size();
    while (begin < end && (s[begin] == ' ' || s[begin] == '\0'))
        ++begin;
    while (end > begin && (s[end - 1] == ' ' || s[end - 1] == '\0'))
        --end;
    return std::string(s.substr(begin, end - begin));
}

} // namespace

Result<C3dPoints> parseC3d(std::string_view bytes, std::string_view name) {
    const std::string where(name);
    auto fail = [&](const std::string& message) -> Result<C3dPoints> {
        return Error{where + ": " + message};
    };
    if (bytes.size() < kBlock)
        return fail("not a C3D file (shorter than its 512-byte header)");
    Reader r(bytes, kIntel);
    if (r.u8(1) != 0x50)
        return fail("not a C3D file (byte 2 is not 0x50)");
    const std::size_t parameterBlock = r.u8(0);
    if (parameterBlock < 2)
        return fail("parameter section points into the header");
    const std::size_t parameterStart = (parameterBlock - 1) * kBlock;
    if (!r.has(parameterStart, 4))
        return fail("truncated before its parameter section");
    const std::uint8_t processor = r.u8(parameterStart + 3);
    if (processor != kIntel && processor != kDec && processor != kMips)
        return fail("unknown processor type " + std::to_string(processor) +
                    " (expected 84 Intel, 85 DEC or 86 MIPS)");
    r.setProcessor(processor);

    const std::size_t pointCount = r.u16(2);
    const std::size_t analogPerFrame = r.u16(4);
    const std::int64_t firstFrame = r.u16(6);
    const std::int64_t lastFrame = r.u16(8);
    const float scale = r.f32(12);
    const std::size_t dataBlockHeader = r.u16(16);
    const float rate = r.f32(20);

    // Parameters by "GROUP:NAME".
    std::map<std::string, Parameter> parameters;
    std::map<int, std::string> groups;
    const std::size_t parameterBlocks = r.u8(parameterStart + 2);
    const std::size_t parameterEnd =
        std::min(r.size(), parameterStart + std::max<std::size_t>(parameterBlocks, 1) * kBlock);
    std::size_t at = parameterStart + 4;
    struct Pending {
        int group;
        std::string name;
        Parameter parameter;
    };
    std::vector<Pending> pending;
    while (at + 2 <= parameterEnd) {
        const std::int8_t nameLength = r.i8(at);
        const std::int8_t id = r.i8(at + 1);
        if (nameLength == 0 || id == 0)
            break;
        const std::size_t length = static_cast<std::size_t>(std::abs(nameLength));
        if (!r.has(at + 2, length + 2))
            return fail("truncated parameter section");
        const std::string entryName = upper(r.text(at + 2, length));
        const std::size_t offsetField = at + 2 + length;
        const std::size_t next = r.u16(offsetField);
        if (id < 0) {
            groups[-id] = entryName;
        } else {
            Parameter p;
            std::size_t cursor = offsetField + 2;
            if (!r.has(cursor, 2))
                return fail("truncated parameter " + entryName);
            p.type = r.i8(cursor);
            const std::size_t dims = r.u8(cursor + 1);
            cursor += 2;
            if (!r.has(cursor, dims))
                return fail("truncated parameter " + entryName);
            std::size_t elements = 1;
            for (std::size_t d = 0; d < dims; ++d) {
                p.dimensions.push_back(r.u8(cursor + d));
                elements *= p.dimensions.back();
            }
            cursor += dims;
            const std::size_t elementSize = static_cast<std::size_t>(std::abs(p.type));
            if (elementSize != 1 && elementSize != 2 && elementSize != 4)
                return fail("parameter " + entryName + " has unknown type " +
                            std::to_string(p.type));
            p.dataOffset = cursor;
            p.dataSize = elements * elementSize;
            if (!r.has(p.dataOffset, p.dataSize))
                return fail("truncated parameter " + entryName);
            pending.push_back({id, entryName, p});
        }
        if (next == 0)
            break;
        at = offsetField + next;
    }
    for (const Pending& p : pending)
        if (groups.contains(p.group))
            parameters[groups[p.group] + ":" + p.name] = p.parameter;

    auto integer = [&](const std::string& key) -> std::optional<std::int64_t> {
        auto it = parameters.find(key);
        if (it == parameters.end() || it->second.dataSize == 0)
            return std::nullopt;
        const Parameter& p = it->second;
        if (p.type == 2)
            return r.u16(p.dataOffset); // unsigned: counts above 32767 are common
        if (p.type == 1)
            return r.u8(p.dataOffset);
        if (p.type == 4) {
            // A float beyond what an integer holds is no count (and casting it is undefined).
            const float value = r.f32(p.dataOffset);
            if (!(std::abs(value) < 1.0e15F))
                return std::nullopt;
            return static_cast<std::int64_t>(value);
        }
        return std::nullopt;
    };
    auto real = [&](const std::string& key) -> std::optional<double> {
        auto it = parameters.find(key);
        if (it == parameters.end() || it->second.type != 4 || it->second.dataSize < 4)
            return std::nullopt;
        return static_cast<double>(r.f32(it->second.dataOffset));
    };

    C3dPoints out;
    // POINT:USED is a 16-bit word, signed in the standard, unsigned in files past 32767 points.
    const std::int64_t used = integer("POINT:USED").value_or(static_cast<std::int64_t>(pointCount));
    if (used < 0 || used > 65535)
        return fail("POINT:USED " + std::to_string(used) + " is not a number of points");
    out.pointCount = static_cast<std::size_t>(used);
    out.frameRate_hz = real("POINT:RATE").value_or(static_cast<double>(rate));
    if (!(out.frameRate_hz > 0.0) || !std::isfinite(out.frameRate_hz))
        return fail("frame rate is not a positive number");
    out.firstFrame = firstFrame;
    if (lastFrame < firstFrame)
        return fail("last frame " + std::to_string(lastFrame) + " is before the first " +
                    std::to_string(firstFrame));
    out.frameCount = static_cast<std::size_t>(lastFrame - firstFrame + 1);
    const std::size_t headerFrameCount = out.frameCount;
    if (std::optional<std::int64_t> frames = integer("POINT:FRAMES");
        frames && *frames > static_cast<std::int64_t>(out.frameCount))
        out.frameCount = static_cast<std::size_t>(*frames); // header words overflow at 65535
    const double pointScale = real("POINT:SCALE").value_or(static_cast<double>(scale));
    const bool floats = pointScale < 0.0;
    if (!std::isfinite(pointScale))
        return fail("POINT:SCALE is not a number");

    double toMillimetres = 1.0;
    if (auto it = parameters.find("POINT:UNITS"); it != parameters.end() && it->second.type == -1) {
        const std::string units = trim(r.text(it->second.dataOffset, it->second.dataSize));
        if (units == "m")
            toMillimetres = 1000.0;
        else if (units == "cm")
            toMillimetres = 10.0;
        else if (!units.empty() && units != "mm")
            return fail("POINT:UNITS '" + units + "' is not m, cm or mm");
    }
    if (auto it = parameters.find("POINT:LABELS");
        it != parameters.end() && it->second.type == -1 && it->second.dimensions.size() == 2) {
        const std::size_t width = it->second.dimensions[0];
        for (std::size_t i = 0; i < it->second.dimensions[1]; ++i)
            out.labels.push_back(trim(r.text(it->second.dataOffset + i * width, width)));
    }
    out.labels.resize(out.pointCount);

    const std::int64_t dataBlockValue =
        integer("POINT:DATA_START").value_or(static_cast<std::int64_t>(dataBlockHeader));
    if (dataBlockValue < 2)
        return fail("data section points into the header");
    if (static_cast<std::uint64_t>(dataBlockValue - 1) > r.size() / kBlock)
        return fail("data section starts past the end of the file");
    const auto dataBlock = static_cast<std::size_t>(dataBlockValue);
    const std::size_t dataStart = (dataBlock - 1) * kBlock;
    const std::size_t sampleSize = floats ? 4 : 2;
    const std::size_t frameSize = (out.pointCount * 4 + analogPerFrame) * sampleSize;
    // Frames without data take no room, so the file cannot vouch for more than its header says.
    if (frameSize == 0 && out.frameCount > headerFrameCount)
        return fail("POINT:FRAMES " + std::to_string(out.frameCount) +
                    " frames of no points and no analog data: more than the header's " +
                    std::to_string(headerFrameCount));
    if (frameSize > 0 &&
        (dataStart > r.size() || (r.size() - dataStart) / frameSize < out.frameCount))
        return fail("truncated: " + std::to_string(out.frameCount) + " frames of " +
                    std::to_string(out.pointCount) + " points do not fit in the file");
    const double unitScale = floats ? toMillimetres : std::abs(pointScale) * toMillimetres;

    out.positions_mm.resize(out.frameCount * out.pointCount);
    out.valid.resize(out.frameCount * out.pointCount);
    for (std::size_t f = 0; f < out.frameCount; ++f) {
        const std::size_t frameStart = dataStart + f * frameSize;
        for (std::size_t p = 0; p < out.pointCount; ++p) {
            const std::size_t s = frameStart + p * 4 * sampleSize;
            double v[4];
            for (std::size_t k = 0; k < 4; ++k)
                v[k] = floats ? static_cast<double>(r.f32(s + k * 4))
                              : static_cast<double>(r.i16(s + k * 2));
            const std::size_t index = f * out.pointCount + p;
            out.positions_mm[index] = Vec3(v[0], v[1], v[2]) * unitScale;
            // The fourth word holds cameras and residual; negative marks a missing sample.
            const bool finite = std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
            out.valid[index] = v[3] >= 0.0 && finite;
        }
    }
    return out;
}

Result<C3dPoints> readC3d(const std::filesystem::path& path) {
    Result<std::string> bytes = readTextFile(path);
    if (!bytes)
        return bytes.error();
    return parseC3d(*bytes, path.string());
}

} // namespace edgetrack::recording
