// Tests of the DTrack ASCII output: the layout DTrack clients expect, and a round trip.
#include <array>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "firmware_app/firmware/dtrack.hpp"
#include "tests/support/alloc_guard.hpp"

namespace edgetrack::app {
namespace {

constexpr std::int64_t kSecond_ns = 1'000'000'000;
/// 2026-11-25 00:00:00 UTC (ns since 1970).
constexpr std::int64_t kMidnight_ns = 1'795'564'800LL * kSecond_ns;

TEST(Dtrack, WritesTheLinesDtrackClientsRead) {
    std::array<DtrackBody, 1> bodies{};
    bodies[0].id = 3;
    // A quarter turn about z: the first column of R is (0, 1, 0).
    bodies[0].T_rig_from_model.rotation = Quat(Eigen::AngleAxisd(M_PI / 2.0, Vec3::UnitZ()));
    bodies[0].T_rig_from_model.translation_mm = Vec3(10.5, -20.25, 600.0);
    std::array<char, 512> buffer{};
    const std::size_t length = formatDtrack(
        DtrackFrame{42, kMidnight_ns + 3600 * kSecond_ns + kSecond_ns / 2, 2, bodies, {}, {}},
        buffer);
    ASSERT_GT(length, 0u);
    EXPECT_EQ(std::string(buffer.data(), length),
              "fr 42\r\nts 3600.500000\r\n6dcal 2\r\n6d 1 [3 1.000][10.500 -20.250 600.000]"
              "[0.000000 1.000000 0.000000 -1.000000 0.000000 0.000000 0.000000 0.000000 "
              "1.000000]\r\n3d 0\r\n");
}

TEST(Dtrack, SaysSixDZeroWhenNothingIsTracked) {
    std::array<char, 128> buffer{};
    const std::size_t length =
        formatDtrack(DtrackFrame{7, kMidnight_ns + kSecond_ns, 2, {}, {}, {}}, buffer);
    EXPECT_NE(std::string(buffer.data(), length).find("\r\n6d 0\r\n"), std::string::npos);
}

TEST(Dtrack, ReadsBackWhatItWrites) {
    std::array<DtrackBody, 2> bodies{};
    for (std::size_t i = 0; i < bodies.size(); ++i) {
        bodies[i].id = static_cast<std::uint32_t>(i);
        bodies[i].quality = 0.5 + 0.25 * static_cast<double>(i);
        bodies[i].T_rig_from_model.rotation =
            quaternionFromWxyz(0.3, -0.5 + static_cast<double>(i), 0.7, 0.1);
        bodies[i].T_rig_from_model.translation_mm = Vec3(-100.0 * static_cast<double>(i), 5, 700);
    }
    std::array<char, 1024> buffer{};
    const std::size_t length = formatDtrack(
        DtrackFrame{
            123456, kMidnight_ns + 86399 * kSecond_ns + kSecond_ns / 4, 2, bodies, {}, 0.0123456},
        buffer);
    const Result<ParsedDtrack> parsed = parseDtrack(std::string_view(buffer.data(), length));
    ASSERT_TRUE(parsed) << parsed.error().message;
    EXPECT_EQ(parsed->frame, 123456u);
    EXPECT_DOUBLE_EQ(parsed->timestamp_s, 86399.25);
    ASSERT_TRUE(parsed->ts2.has_value());
    EXPECT_EQ(parsed->ts2->seconds, static_cast<std::uint64_t>(kMidnight_ns / kSecond_ns) + 86399u);
    EXPECT_EQ(parsed->ts2->microseconds, 250'000u);
    EXPECT_EQ(parsed->ts2->latency_us, 12'346u);
    EXPECT_TRUE(parsed->hasMarkerLine);
    EXPECT_TRUE(parsed->markers.empty());
    EXPECT_EQ(parsed->calibrated, 2u);
    ASSERT_EQ(parsed->bodies.size(), 2u);
    for (std::size_t i = 0; i < bodies.size(); ++i) {
        EXPECT_EQ(parsed->bodies[i].id, bodies[i].id);
        EXPECT_NEAR(parsed->bodies[i].quality, bodies[i].quality, 1e-3);
        EXPECT_LT((parsed->bodies[i].T_rig_from_model.translation_mm -
                   bodies[i].T_rig_from_model.translation_mm)
                      .norm(),
                  1e-3);
        EXPECT_LT(rotationAngleBetween_rad(parsed->bodies[i].T_rig_from_model.rotation,
                                           bodies[i].T_rig_from_model.rotation),
                  1e-5);
    }
}

TEST(Dtrack, SendsNothingPartialWhenTheBufferIsShort) {
    std::array<DtrackBody, 4> bodies{};
    std::array<char, 200> buffer{};
    EXPECT_EQ(formatDtrack(DtrackFrame{1, kMidnight_ns, 4, bodies, {}, {}}, buffer), 0u);
}

TEST(Dtrack, FormatsWithoutAllocating) {
    std::array<DtrackBody, 6> bodies{};
    std::array<char, 2048> buffer{};
    std::size_t total = 0;
    const std::uint64_t allocations = test::countAllocations([&] {
        for (std::uint64_t f = 0; f < 1000; ++f)
            total +=
                formatDtrack(DtrackFrame{f,
                                         kMidnight_ns + static_cast<std::int64_t>(f) * 10'000'000,
                                         6,
                                         bodies,
                                         {},
                                         0.003},
                             buffer);
    });
    EXPECT_EQ(allocations, 0u);
    EXPECT_GT(total, 1000u * 6u * 80u);
}

TEST(Dtrack, RefusesMalformedDatagrams) {
    EXPECT_FALSE(parseDtrack("fr 1\n6d 0\n"));
    EXPECT_FALSE(parseDtrack("ts 1.0\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\n6d 1 [0 1.0][1 2 3][1 0 0]\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\n6d 1 [0 1.0][1 2 3][2 0 0 0 1 0 0 0 1]\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\nts2 1 2\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\nts2 1 1000000 5\r\n"));
    // Counts and ids that no integer holds (found by tests/fuzz: casting them was undefined).
    EXPECT_FALSE(parseDtrack("fr 1\r\n3d 1.7e61\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\n6d -1\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\n3d 1 [-5 1.0][1 2 3]\r\n"));
    EXPECT_FALSE(parseDtrack("fr 1\r\n3d 1 [1e20 1.0][1 2 3]\r\n"));
}

TEST(Dtrack, SendsTheMarkerLineInEveryFrameAndTheLatencyInTs2) {
    std::array<DtrackMarker, 2> markers{};
    markers[0] = {1001, 1.0, Vec3(1.0, 2.0, 3.0)};
    markers[1] = {2003, 1.0, Vec3(-4.0, 5.5, 600.25)};
    std::array<char, 512> buffer{};
    const std::int64_t utc_ns = kMidnight_ns + 45 * kSecond_ns + 123'456'789;
    std::size_t length = formatDtrack(DtrackFrame{9, utc_ns, 0, {}, markers, 0.0027}, buffer);
    std::string text(buffer.data(), length);
    // ts and ts2 name the same whole microsecond (123'456'789 ns is 123456 us, not 123457).
    EXPECT_NE(text.find("\r\nts 45.123456\r\nts2 1795564845 123456 2700\r\n"), std::string::npos)
        << text;
    EXPECT_NE(text.find("\r\n3d 2 [1001 1.000][1.000 2.000 3.000] [2003 1.000][-4.000 5.500 "
                        "600.250]\r\n"),
              std::string::npos)
        << text;
    // No markers: `3d 0`, which makes a DTrack client drop the markers it showed.
    length = formatDtrack(DtrackFrame{10, utc_ns, 0, {}, {}, {}}, buffer);
    text.assign(buffer.data(), length);
    EXPECT_NE(text.find("\r\n3d 0\r\n"), std::string::npos) << text;
    EXPECT_EQ(text.find("ts2"), std::string::npos) << "no latency, no ts2 line";
}

TEST(Dtrack, TsAndTs2AgreeToTheMicrosecondInEveryFrame) {
    // ts was rounded and ts2 truncated: about half the frames differed by 1 us.
    std::array<char, 512> buffer{};
    for (std::int64_t k = 0; k < 2000; ++k) {
        const std::int64_t utc_ns = kMidnight_ns + 3 * kSecond_ns + k * 499'999 + (k % 7) * 113;
        const std::size_t length = formatDtrack(
            DtrackFrame{static_cast<std::uint64_t>(k), utc_ns, 0, {}, {}, 0.001}, buffer);
        const std::string text(buffer.data(), length);
        const std::size_t ts = text.find("\r\nts ") + 6, ts2 = text.find("ts2 ");
        const std::string fraction = text.substr(text.find('.', ts) + 1, 6);
        std::istringstream fields(text.substr(ts2 + 4));
        long long seconds = 0, micros = 0;
        fields >> seconds >> micros;
        EXPECT_EQ(std::stoll(fraction), micros) << text;
    }
}

TEST(Dtrack, SixDCalIsTheHighestIdPlusOne) {
    // DTrackSDK and VRPN keep only bodies whose id is below 6dcal: with models 2 and 3 on the
    // board, 6dcal 2 (their number) hid both.
    const std::vector<NamedModel> models = [] {
        std::vector<NamedModel> m(2);
        m[0].model.id = 2;
        m[1].model.id = 3;
        return m;
    }();
    EXPECT_EQ(dtrackCalibratedCount(models), 4u);
    EXPECT_EQ(dtrackCalibratedCount({}), 0u);
}

} // namespace
} // namespace edgetrack::app
