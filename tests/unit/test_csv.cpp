// Tests of the strict CSV parser: every malformed input gets a one-line error with file and line.
#include <array>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <sys/stat.h>
#include <thread>

#include <gtest/gtest.h>

#include "firmware_app/formats/csv.hpp"
#include "tests/support/temp_dir.hpp"

using namespace edgetrack;
using namespace edgetrack::recording;

namespace {

constexpr std::array<CsvColumn, 5> kBlobColumns{{{"frame", ColumnType::Integer},
                                                 {"camera", ColumnType::Integer},
                                                 {"u", ColumnType::Real},
                                                 {"v", ColumnType::Real},
                                                 {"area", ColumnType::Real, true}}};

std::string errorOf(std::string_view text) {
    const Result<CsvTable> r = parseCsv(text, "rec/blobs.csv", kBlobColumns);
    EXPECT_FALSE(r.isValid()) << "accepted: " << text;
    if (r.isValid())
        return {};
    EXPECT_EQ(r.error().message.find('\n'), std::string::npos) << "error is not one line";
    return r.error().message;
}

} // namespace

TEST(Csv, ParsesWithAndWithoutOptionalColumn) {
    const auto with = parseCsv("frame,camera,u,v,area\n0,1,10.5,20.25,7\n", "x", kBlobColumns);
    ASSERT_TRUE(with);
    EXPECT_EQ(with->columnCount, 5u);
    ASSERT_EQ(with->rows.size(), 1u);
    EXPECT_EQ(with->rows[0].integer(1), 1);
    EXPECT_DOUBLE_EQ(with->rows[0][4], 7.0);

    const auto without = parseCsv("frame,camera,u,v\r\n3,0,1e2,-2.5\r\n", "x", kBlobColumns);
    ASSERT_TRUE(without);
    EXPECT_EQ(without->columnCount, 4u);
    EXPECT_DOUBLE_EQ(without->rows[0][2], 100.0);
    EXPECT_EQ(without->rows[0].line, 2u);
}

TEST(Csv, AByteOrderMarkBeforeTheHeaderIsTakenAsJsonReadersTakeIt) {
    const auto table = parseCsv("\xEF\xBB\xBF"
                                "frame,camera,u,v\n3,0,1.5,2\n",
                                "x", kBlobColumns);
    ASSERT_TRUE(table) << table.error().message;
    ASSERT_EQ(table->rows.size(), 1u);
    EXPECT_EQ(table->rows[0].integer(0), 3);
    EXPECT_FALSE(parseCsv("frame,\xEF\xBB\xBF"
                          "camera,u,v\n",
                          "x", kBlobColumns))
        << "only before the header";
}

TEST(Csv, HeaderOnlyIsAnEmptyTable) {
    const auto r = parseCsv("frame,camera,u,v\n", "x", kBlobColumns);
    ASSERT_TRUE(r);
    EXPECT_TRUE(r->rows.empty());
}

TEST(Csv, MissingHeader) {
    EXPECT_EQ(errorOf(""), "rec/blobs.csv:1: missing header, expected \"frame,camera,u,v[,area]\"");
}

TEST(Csv, BadHeader) {
    EXPECT_EQ(
        errorOf("frame,cam,u,v\n0,0,1,2\n"),
        "rec/blobs.csv:1: bad header \"frame,cam,u,v\", expected \"frame,camera,u,v[,area]\"");
    // Data where the header should be is a bad header too.
    EXPECT_NE(errorOf("0,0,1,2\n").find("rec/blobs.csv:1: bad header"), std::string::npos);
}

TEST(Csv, MissingColumn) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1,2\n1,0,3\n"),
              "rec/blobs.csv:3: expected 4 fields, found 3");
}

TEST(Csv, ExtraColumn) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1,2,9\n"),
              "rec/blobs.csv:2: expected 4 fields, found 5");
}

TEST(Csv, AnErrorQuotingBinaryBytesIsOnePrintableLine) {
    // A binary file given as CSV: its bytes were echoed to the terminal, escape sequences and all.
    const std::string error = errorOf("frame,camera,u,v\n0,0,\x1b[2J\x01\xff"
                                      "\xc3\xa9,2\n");
    EXPECT_NE(error.find("\\x1b[2J\\x01\\xff\xc3\xa9"), std::string::npos) << error;
    for (const char c : error)
        EXPECT_FALSE(static_cast<unsigned char>(c) < 0x20 || c == 0x7f) << error;
    EXPECT_EQ(Error{"a\nb"}.message, "a\\x0ab") << "one line";
}

TEST(Csv, TextInANumberField) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,abc,2\n"),
              "rec/blobs.csv:2: field 'u' is not a number: \"abc\"");
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,,2\n"),
              "rec/blobs.csv:2: field 'u' is not a number: \"\"");
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1.5x,2\n"),
              "rec/blobs.csv:2: field 'u' is not a number: \"1.5x\"");
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1;5,2\n"),
              "rec/blobs.csv:2: field 'u' is not a number: \"1;5\"");
}

TEST(Csv, FractionInAnIntegerField) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n0.5,0,1,2\n"),
              "rec/blobs.csv:2: field 'frame' is not an integer: \"0.5\"");
}

// A row holds doubles: an integer it would not give back exactly is refused, not rounded (the
// fuzzer's 9223372036854775807 came back as 2^63, outside every int64).
TEST(Csv, IntegerBeyondWhatADoubleHoldsExactly) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n9223372036854775807,0,1,2\n"),
              "rec/blobs.csv:2: field 'frame' is out of range (at most 2^53): "
              "\"9223372036854775807\"");
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,-9007199254740993,1,2\n"),
              "rec/blobs.csv:2: field 'camera' is out of range (at most 2^53): "
              "\"-9007199254740993\"");
    const Result<CsvTable> atLimit =
        parseCsv("frame,camera,u,v\n9007199254740992,0,1,2\n", "rec/blobs.csv", kBlobColumns);
    ASSERT_TRUE(atLimit.isValid());
    EXPECT_EQ(atLimit.value().rows[0].integer(0), std::int64_t{1} << 53);
}

TEST(Csv, NanAndInfinity) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,nan,2\n"),
              "rec/blobs.csv:2: field 'u' is \"nan\": NaN and infinity are not allowed");
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1,-inf\n"),
              "rec/blobs.csv:2: field 'v' is \"-inf\": NaN and infinity are not allowed");
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1,1e999\n"),
              "rec/blobs.csv:2: field 'v' is not a number: \"1e999\"");
}

TEST(Csv, EmptyLineInTheMiddle) {
    EXPECT_EQ(errorOf("frame,camera,u,v\n0,0,1,2\n\n1,0,1,2\n"), "rec/blobs.csv:3: empty line");
}

TEST(Csv, LongGarbageIsShortenedInTheMessage) {
    const std::string garbage(500, 'x');
    const std::string message = errorOf("frame,camera,u,v\n0,0," + garbage + ",2\n");
    EXPECT_LT(message.size(), 120u);
    EXPECT_NE(message.find("..."), std::string::npos);
}

TEST(Csv, NumbersRoundTripExactly) {
    std::string line;
    appendCsvLine(line, std::int64_t{42}, 0.1, -1234.56789012345, 1e-300, 3.0);
    EXPECT_EQ(line, "42,0.1,-1234.56789012345,1e-300,3\n");
}

namespace {

std::string contentOf(const std::filesystem::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    return text.str();
}

} // namespace

TEST(TextFile, WritingThroughALinkReplacesItsTargetAndKeepsTheLink) {
    test::TempDir dir;
    const std::filesystem::path target = dir.path() / "target.csv";
    const std::filesystem::path link = dir.path() / "link.csv";
    std::ofstream(target) << "old\n";
    std::filesystem::create_symlink(target, link);
    ASSERT_TRUE(writeTextFileAtomically(link, "new\n"));
    EXPECT_TRUE(std::filesystem::is_symlink(link));
    EXPECT_EQ(contentOf(target), "new\n");
    EXPECT_FALSE(std::filesystem::exists(dir.path() / "target.csv.tmp"));
    EXPECT_FALSE(std::filesystem::exists(dir.path() / "link.csv.tmp"));
}

TEST(TextFile, AFifoIsWrittenToNotReplaced) {
    // --out FIFO: the program reading the pipe gets the data, and the pipe stays a pipe.
    test::TempDir dir;
    const std::filesystem::path fifo = dir.path() / "poses.csv";
    ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
    std::string received;
    std::thread reader([&] { received = contentOf(fifo); });
    const Status written = writeTextFileAtomically(fifo, "frame,time_s\n");
    reader.join();
    ASSERT_TRUE(written) << written.error().message;
    EXPECT_EQ(received, "frame,time_s\n");
    EXPECT_EQ(std::filesystem::status(fifo).type(), std::filesystem::file_type::fifo);
}

TEST(TextFile, ADirectoryIsNeitherReadNorReplaced) {
    test::TempDir dir;
    const std::filesystem::path directory = dir.path() / "out.csv";
    std::filesystem::create_directories(directory / "inside");
    const Status written = writeTextFileAtomically(directory, "x\n");
    ASSERT_FALSE(written);
    EXPECT_NE(written.error().message.find("is a directory"), std::string::npos);
    EXPECT_TRUE(std::filesystem::is_directory(directory / "inside"));
    const Result<std::string> read = readTextFile(directory);
    ASSERT_FALSE(read);
    EXPECT_NE(read.error().message.find("is a directory"), std::string::npos);
}
