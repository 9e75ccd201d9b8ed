// Tests of the C3D reader on files written here in each number format, on damaged files, and on
// a real Vicon recording when ../shared/realdata is present.
#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "firmware_app/formats/c3d.hpp"

namespace edgetrack::recording {
namespace {

// Writes a minimal C3D file: header, one parameter block with POINT:USED, SCALE, RATE, UNITS,
// LABELS, and the point records.
class C3dWriter {
public:
    enum class Format { IntelFloat, IntelInteger, Mips, Dec };
    explicit C3dWriter(Format format)
        : format_(format) {}

    /// A POINT:FRAMES parameter (a float, as some writers store it) to add; none when empty.
    std::optional<float> pointFrames;

    std::string write(const std::vector<std::vector<Vec3>>& frames,
                      const std::vector<std::vector<bool>>& valid, const std::string& units,
                      double scale, float rate) {
        const std::size_t points = frames.empty() ? 0 : frames[0].size();
        std::string file(2 * 512, '\0');
        file[0] = 2;
        file[1] = 0x50;
        const bool floats = format_ != Format::IntelInteger;
        put16(file, 2, static_cast<std::uint16_t>(points));
        put16(file, 4, 0);
        put16(file, 6, 1);
        put16(file, 8, static_cast<std::uint16_t>(frames.size()));
        putFloat(file, 12, floats ? -static_cast<float>(scale) : static_cast<float>(scale));
        put16(file, 16, 3);
        putFloat(file, 20, rate);
        // Parameter section at block 2.
        std::size_t at = 512;
        file[at + 2] = 1;
        file[at + 3] = static_cast<char>(format_ == Format::Mips  ? 86
                                         : format_ == Format::Dec ? 85
                                                                  : 84);
        at += 4;
        at = group(file, at, 1, "POINT");
        at = parameter(file, at, 1, "USED", 2, {}, int16Bytes(static_cast<std::int16_t>(points)));
        at = parameter(file, at, 1, "RATE", 4, {}, floatBytes(rate));
        at = parameter(file, at, 1, "UNITS", -1, {static_cast<std::uint8_t>(units.size())},
                       std::vector<std::uint8_t>(units.begin(), units.end()));
        if (pointFrames)
            at = parameter(file, at, 1, "FRAMES", 4, {}, floatBytes(*pointFrames));
        std::vector<std::uint8_t> labels;
        for (std::size_t p = 0; p < points; ++p) {
            std::string label = "m" + std::to_string(p);
            label.resize(4, ' ');
            labels.insert(labels.end(), label.begin(), label.end());
        }
        at = parameter(file, at, 1, "LABELS", -1, {4, static_cast<std::uint8_t>(points)}, labels,
                       true);
        // Data at block 3.
        for (std::size_t f = 0; f < frames.size(); ++f)
            for (std::size_t p = 0; p < points; ++p) {
                const double residual = valid[f][p] ? 1.0 : -1.0;
                const double v[4] = {frames[f][p].x(), frames[f][p].y(), frames[f][p].z(),
                                     residual};
                for (double x : v) {
                    if (floats) {
                        std::string bytes(4, '\0');
                        putFloat(bytes, 0, static_cast<float>(x));
                        file += bytes;
                    } else {
                        std::string bytes(2, '\0');
                        put16(bytes, 0,
                              static_cast<std::uint16_t>(static_cast<std::int16_t>(
                                  std::lround(x == residual ? x : x / scale))));
                        file += bytes;
                    }
                }
            }
        return file;
    }

private:
    void put16(std::string& s, std::size_t at, std::uint16_t v) const {
        if (format_ == Format::Mips) {
            s[at] = static_cast<char>(v >> 8);
            s[at + 1] = static_cast<char>(v & 0xff);
        } else {
            s[at] = static_cast<char>(v & 0xff);
            s[at + 1] = static_cast<char>(v >> 8);
        }
    }
    void putFloat(std::string& s, std::size_t at, float value) const {
        std::uint32_t bits = 0;
        if (format_ == Format::Dec) {
            bits = std::bit_cast<std::uint32_t>(value * 4.0f);
            const std::uint8_t ieee[4] = {
                static_cast<std::uint8_t>(bits), static_cast<std::uint8_t>(bits >> 8),
                static_cast<std::uint8_t>(bits >> 16), static_cast<std::uint8_t>(bits >> 24)};
            const std::uint8_t dec[4] = {ieee[2], ieee[3], ieee[0], ieee[1]};
            for (std::size_t i = 0; i < 4; ++i)
                s[at + i] = static_cast<char>(dec[i]);
            return;
        }
        bits = std::bit_cast<std::uint32_t>(value);
        for (std::size_t i = 0; i < 4; ++i) {
            const std::size_t shift = format_ == Format::Mips ? 24 - 8 * i : 8 * i;
            s[at + i] = static_cast<char>((bits >> shift) & 0xff);
        }
    }
    std::vector<std::uint8_t> int16Bytes(std::int16_t v) const {
        std::string s(2, '\0');
        put16(s, 0, static_cast<std::uint16_t>(v));
        return {static_cast<std::uint8_t>(s[0]), static_cast<std::uint8_t>(s[1])};
    }
    std::vector<std::uint8_t> floatBytes(float v) const {
        std::string s(4, '\0');
        putFloat(s, 0, v);
        return {static_cast<std::uint8_t>(s[0]), static_cast<std::uint8_t>(s[1]),
                static_cast<std::uint8_t>(s[2]), static_cast<std::uint8_t>(s[3])};
    }
    std::size_t group(std::string& s, std::size_t at, int id, const std::string& name) const {
        s[at] = static_cast<char>(name.size());
        s[at + 1] = static_cast<char>(-id);
        std::memcpy(&s[at + 2], name.data(), name.size());
        const std::size_t offsetField = at + 2 + name.size();
        put16(s, offsetField, 3); // offset field (2) + empty description (1)
        s[offsetField + 2] = 0;
        return offsetField + 3;
    }
    std::size_t parameter(std::string& s, std::size_t at, int group, const std::string& name,
                          int type, const std::vector<std::uint8_t>& dims,
                          const std::vector<std::uint8_t>& data, bool last = false) const {
        s[at] = static_cast<char>(name.size());
        s[at + 1] = static_cast<char>(group);
        std::memcpy(&s[at + 2], name.data(), name.size());
        const std::size_t offsetField = at + 2 + name.size();
        std::size_t cursor = offsetField + 2;
        s[cursor++] = static_cast<char>(type);
        s[cursor++] = static_cast<char>(dims.size());
        for (std::uint8_t d : dims)
            s[cursor++] = static_cast<char>(d);
        for (std::uint8_t b : data)
            s[cursor++] = static_cast<char>(b);
        s[cursor++] = 0; // description length
        put16(s, offsetField, last ? 0 : static_cast<std::uint16_t>(cursor - offsetField));
        return cursor;
    }

    Format format_;
};

struct Sample {
    std::vector<std::vector<Vec3>> frames{{{1.5, -2.25, 500.0}, {100.0, 20.0, -30.5}},
                                          {{2.0, -2.0, 501.0}, {99.0, 21.0, -31.0}},
                                          {{2.5, -1.75, 502.0}, {0.0, 0.0, 0.0}}};
    std::vector<std::vector<bool>> valid{{true, true}, {true, true}, {true, false}};
};

void expectSample(const C3dPoints& c3d, const Sample& s, double unit, double tolerance) {
    ASSERT_EQ(c3d.frameCount, 3u);
    ASSERT_EQ(c3d.pointCount, 2u);
    EXPECT_DOUBLE_EQ(c3d.frameRate_hz, 120.0);
    EXPECT_EQ(c3d.labels[1], "m1");
    for (std::size_t f = 0; f < 3; ++f)
        for (std::size_t p = 0; p < 2; ++p) {
            EXPECT_EQ(c3d.isValid(f, p), s.valid[f][p]);
            if (s.valid[f][p]) {
                EXPECT_LT((c3d.position(f, p) - s.frames[f][p] * unit).norm(), tolerance);
            }
        }
}

TEST(C3d, ReadsIntelFloats) {
    const Sample s;
    const std::string bytes =
        C3dWriter(C3dWriter::Format::IntelFloat).write(s.frames, s.valid, "mm", 1.0, 120.0f);
    const Result<C3dPoints> c3d = parseC3d(bytes, "intel.c3d");
    ASSERT_TRUE(c3d) << c3d.error().message;
    expectSample(*c3d, s, 1.0, 1e-4);
}

TEST(C3d, ReadsScaledIntegers) {
    const Sample s;
    const std::string bytes =
        C3dWriter(C3dWriter::Format::IntelInteger).write(s.frames, s.valid, "mm", 0.25, 120.0f);
    const Result<C3dPoints> c3d = parseC3d(bytes, "integer.c3d");
    ASSERT_TRUE(c3d) << c3d.error().message;
    expectSample(*c3d, s, 1.0, 0.13);
}

TEST(C3d, ReadsBigEndianMipsAndConvertsMetres) {
    const Sample s;
    const std::string bytes =
        C3dWriter(C3dWriter::Format::Mips).write(s.frames, s.valid, "m", 1.0, 120.0f);
    const Result<C3dPoints> c3d = parseC3d(bytes, "mips.c3d");
    ASSERT_TRUE(c3d) << c3d.error().message;
    expectSample(*c3d, s, 1000.0, 1e-2);
}

TEST(C3d, ReadsDecFloats) {
    const Sample s;
    const std::string bytes =
        C3dWriter(C3dWriter::Format::Dec).write(s.frames, s.valid, "mm", 1.0, 120.0f);
    const Result<C3dPoints> c3d = parseC3d(bytes, "dec.c3d");
    ASSERT_TRUE(c3d) << c3d.error().message;
    expectSample(*c3d, s, 1.0, 1e-4);
}

TEST(C3d, DamagedFilesGetOneLineErrors) {
    const Sample s;
    const std::string good =
        C3dWriter(C3dWriter::Format::IntelFloat).write(s.frames, s.valid, "mm", 1.0, 120.0f);
    auto errorOf = [](const std::string& bytes) {
        const Result<C3dPoints> c3d = parseC3d(bytes, "bad.c3d");
        return c3d ? std::string("no error") : c3d.error().message;
    };
    EXPECT_NE(errorOf(good.substr(0, 100)).find("shorter than its 512-byte header"),
              std::string::npos);
    std::string notC3d = good;
    notC3d[1] = 0x42;
    EXPECT_NE(errorOf(notC3d).find("not a C3D file"), std::string::npos);
    std::string processor = good;
    processor[512 + 3] = 99;
    EXPECT_NE(errorOf(processor).find("unknown processor type 99"), std::string::npos);
    EXPECT_NE(errorOf(good.substr(0, good.size() - 10)).find("truncated"), std::string::npos);
    EXPECT_NE(errorOf(good.substr(0, 520)).find("truncated"), std::string::npos);
    const std::string inches =
        C3dWriter(C3dWriter::Format::IntelFloat).write(s.frames, s.valid, "in", 1.0, 120.0f);
    EXPECT_NE(errorOf(inches).find("POINT:UNITS 'in'"), std::string::npos);
    for (const std::string& e : {errorOf(notC3d), errorOf(processor)}) {
        EXPECT_EQ(e.rfind("bad.c3d: ", 0), 0u) << e;
        EXPECT_EQ(e.find('\n'), std::string::npos);
    }
}

TEST(C3d, FramesOfNoDataBeyondTheHeaderAreRefusedNotRead) {
    // No points and POINT:FRAMES = 9.9e14 (a float): no data to check the count against, so it
    // was believed, and reading 1e15 empty frames hung and filled memory.
    C3dWriter writer(C3dWriter::Format::IntelFloat);
    for (const float frames : {9.9e14F, 5.0e7F}) {
        writer.pointFrames = frames;
        const std::string bytes = writer.write({{}, {}}, {{}, {}}, "mm", 1.0, 100.0f);
        const Result<C3dPoints> c3d = parseC3d(bytes, "lying.c3d");
        ASSERT_FALSE(c3d) << frames;
        EXPECT_NE(c3d.error().message.find("POINT:FRAMES"), std::string::npos)
            << c3d.error().message;
    }
    // As many frames as the header says, with no points, is an empty recording, not an error.
    writer.pointFrames = 2.0F;
    const Result<C3dPoints> empty =
        parseC3d(writer.write({{}, {}}, {{}, {}}, "mm", 1.0, 100.0f), "empty.c3d");
    ASSERT_TRUE(empty) << empty.error().message;
    EXPECT_EQ(empty->frameCount, 2u);
}

TEST(C3d, ADirectoryWhereTheFileShouldBeIsAnError) {
    const std::filesystem::path directory =
        std::filesystem::temp_directory_path() / "edgetrack_c3d_directory.c3d";
    std::filesystem::create_directories(directory);
    const Result<C3dPoints> c3d = readC3d(directory);
    ASSERT_FALSE(c3d);
    EXPECT_NE(c3d.error().message.find("is a directory"), std::string::npos);
    std::filesystem::remove(directory);
}

TEST(C3d, EveryTruncationIsAnErrorNotACrash) {
    const Sample s;
    const std::string good =
        C3dWriter(C3dWriter::Format::IntelFloat).write(s.frames, s.valid, "mm", 1.0, 120.0f);
    for (std::size_t size = 0; size < good.size(); size += 7)
        EXPECT_FALSE(parseC3d(good.substr(0, size), "cut.c3d")) << size << " bytes";
}

const std::filesystem::path kVicon =
    std::filesystem::path(EDGETRACK_REALDATA_DIR) / "ezc3d-testFiles" / "Vicon.c3d";

TEST(C3dRealData, ViconRecordingAsItsReadmeDescribesIt) {
    if (!std::filesystem::exists(kVicon))
        GTEST_SKIP() << kVicon << " is absent (the shared real-data folder is not here)";
    const Result<C3dPoints> c3d = readC3d(kVicon);
    ASSERT_TRUE(c3d) << c3d.error().message;
    EXPECT_EQ(c3d->pointCount, 51u);
    EXPECT_EQ(c3d->frameCount, 580u);
    EXPECT_DOUBLE_EQ(c3d->frameRate_hz, 100.0);
    std::vector<std::size_t> box;
    for (std::size_t p = 0; p < c3d->pointCount; ++p)
        if (c3d->labels[p].rfind("boite:", 0) == 0)
            box.push_back(p);
    ASSERT_EQ(box.size(), 8u);
    std::size_t invalid = 0;
    for (std::size_t f = 0; f < c3d->frameCount; ++f)
        for (std::size_t p = 0; p < c3d->pointCount; ++p)
            invalid += c3d->isValid(f, p) ? 0u : 1u;
    const double missing =
        static_cast<double>(invalid) / static_cast<double>(c3d->frameCount * c3d->pointCount);
    EXPECT_GT(missing, 0.001);
    EXPECT_LT(missing, 0.05);
    // The box is rigid: each of its distances stays within a millimetre or so of its mean.
    for (std::size_t a = 0; a < box.size(); ++a)
        for (std::size_t b = a + 1; b < box.size(); ++b) {
            double sum = 0.0, sum2 = 0.0;
            int n = 0;
            for (std::size_t f = 0; f < c3d->frameCount; ++f) {
                if (!c3d->isValid(f, box[a]) || !c3d->isValid(f, box[b]))
                    continue;
                const double d = (c3d->position(f, box[a]) - c3d->position(f, box[b])).norm();
                sum += d;
                sum2 += d * d;
                ++n;
            }
            ASSERT_GT(n, 100);
            const double mean = sum / n;
            EXPECT_LT(std::sqrt(std::max(0.0, sum2 / n - mean * mean)), 1.0)
                << c3d->labels[box[a]] << " - " << c3d->labels[box[b]];
            EXPECT_GT(mean, 30.0);
            EXPECT_LT(mean, 510.0);
        }
}

} // namespace
} // namespace edgetrack::recording
