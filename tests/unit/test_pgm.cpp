// Tests of the PGM reader: 8-bit P5 only, size checked against the rig, truncation detected.
#include <gtest/gtest.h>

#include "firmware_app/formats/recording.hpp"
#include "tests/support/temp_dir.hpp"

using namespace edgetrack;
using namespace edgetrack::recording;

namespace {
std::string pgm(const std::string& header, std::size_t pixelBytes) {
    return header + std::string(pixelBytes, '\x7f');
}
} // namespace

TEST(Pgm, ParsesHeaderWithComments) {
    const auto image = parsePgm(pgm("P5\n# camera 0\n4 # width\n2\n255\n", 8), "a.pgm", 4, 2);
    ASSERT_TRUE(image) << image.error().message;
    EXPECT_EQ(image->width, 4);
    EXPECT_EQ(image->height, 2);
    EXPECT_EQ(image->pixels.size(), 8u);
    EXPECT_EQ(image->pixels[7], 0x7f);
}

TEST(Pgm, WrongType) {
    const auto ascii = parsePgm("P2\n2 2\n255\n1 2 3 4\n", "a.pgm");
    ASSERT_FALSE(ascii);
    EXPECT_EQ(ascii.error().message, "a.pgm: not a binary 8-bit PGM (P5): magic is \"P2\"");
    const auto colour = parsePgm(pgm("P6\n1 1\n255\n", 3), "b.ppm");
    ASSERT_FALSE(colour);
    EXPECT_EQ(colour.error().message, "b.ppm: not a binary 8-bit PGM (P5): magic is \"P6\"");
}

TEST(Pgm, SixteenBit) {
    const auto r = parsePgm(pgm("P5\n2 2\n65535\n", 8), "a.pgm");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "a.pgm: PGM maxval is 65535, expected 255 (8-bit)");
}

TEST(Pgm, WrongSizeForTheRig) {
    const auto r =
        parsePgm(pgm("P5\n640 400\n255\n", 640 * 400), "rec/images/000000_0.pgm", 1280, 800);
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message,
              "rec/images/000000_0.pgm: image is 640x400, rig.toml says 1280x800");
}

TEST(Pgm, Truncated) {
    const auto r = parsePgm(pgm("P5\n4 4\n255\n", 10), "a.pgm");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "a.pgm: truncated image: 10 of 16 pixel bytes");
    const auto headerOnly = parsePgm("P5\n4 4\n255", "a.pgm");
    ASSERT_FALSE(headerOnly);
    EXPECT_EQ(headerOnly.error().message, "a.pgm: truncated image: no pixel data");
}

TEST(Pgm, TrailingBytes) {
    const auto r = parsePgm(pgm("P5\n2 2\n255\n", 6), "a.pgm");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "a.pgm: 2 bytes after the pixel data");
}

TEST(Pgm, MalformedHeader) {
    for (const char* header : {"P5\n", "P5\n-2 2\n255\n", "P5\n0 2\n255\n", "P5\nx 2\n255\n"}) {
        const auto r = parsePgm(header, "a.pgm");
        ASSERT_FALSE(r) << header;
        EXPECT_EQ(r.error().message, "a.pgm: malformed PGM header") << header;
    }
}

TEST(Pgm, WriteReadRoundTrip) {
    test::TempDir dir;
    Image8 image;
    image.width = 7;
    image.height = 3;
    for (int i = 0; i < 21; ++i)
        image.pixels.push_back(static_cast<std::uint8_t>(i * 12));
    // Byte values that look like whitespace right after the header must survive.
    image.pixels[0] = '\n';
    image.pixels[1] = ' ';
    const auto path = imagePath(dir.path(), 12, 1);
    EXPECT_EQ(path.filename(), "000012_1.pgm");
    std::filesystem::create_directories(path.parent_path());
    ASSERT_TRUE(writePgm(path, image));
    const auto back = readPgm(path, 7, 3);
    ASSERT_TRUE(back) << back.error().message;
    EXPECT_EQ(back->pixels, image.pixels);
}

TEST(Pgm, MissingFile) {
    const auto r = readPgm("/nonexistent/000000_0.pgm");
    ASSERT_FALSE(r);
    EXPECT_EQ(r.error().message, "/nonexistent/000000_0.pgm: cannot open for reading");
}
