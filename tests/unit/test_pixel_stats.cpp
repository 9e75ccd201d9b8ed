// Tests of the NEON pixel-statistics kernel against a scalar reference, native or through SIMDe.
#include <algorithm>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/pixel_stats.hpp"
#include "core/simd/neon.hpp"

using namespace edgetrack;

namespace {
PixelStats reference(const std::vector<std::uint8_t>& pixels, std::uint8_t threshold) {
    PixelStats s;
    for (std::uint8_t p : pixels) {
        s.brightCount += p >= threshold ? 1u : 0u;
        s.maximum = std::max(s.maximum, p);
    }
    return s;
}
} // namespace

TEST(PixelStats, MatchesScalarReferenceOnOddLengths) {
    std::mt19937 random(5);
    std::uniform_int_distribution<int> byte(0, 255);
    RecordProperty("neon_backend", simd::neonBackendName());
    for (std::size_t length : {0u, 1u, 15u, 16u, 17u, 255u * 16u, 255u * 16u + 5u, 70001u}) {
        std::vector<std::uint8_t> pixels(length);
        for (auto& p : pixels)
            p = static_cast<std::uint8_t>(byte(random));
        for (int threshold : {0, 1, 128, 200, 255}) {
            const auto t = static_cast<std::uint8_t>(threshold);
            const PixelStats fast = measurePixels(pixels, t);
            const PixelStats slow = reference(pixels, t);
            EXPECT_EQ(fast.brightCount, slow.brightCount) << length << " " << threshold;
            EXPECT_EQ(fast.maximum, slow.maximum) << length << " " << threshold;
        }
    }
}

TEST(PixelStats, CountsAFullBrightFrameWithoutLaneOverflow) {
    // Every lane hits 255 counts many times over: the widening must not lose any.
    const std::vector<std::uint8_t> frame(1280u * 800u, 250);
    const PixelStats s = measurePixels(frame, 200);
    EXPECT_EQ(s.brightCount, 1280u * 800u);
    EXPECT_EQ(s.maximum, 250);
}

TEST(PixelStats, DarkFrameHasNoBrightPixels) {
    std::vector<std::uint8_t> frame(1280u * 800u, 12);
    frame[640u * 400u + 3u] = 40;
    const PixelStats s = measurePixels(frame, 128);
    EXPECT_EQ(s.brightCount, 0u);
    EXPECT_EQ(s.maximum, 40);
}

TEST(PixelStats, BackendMatchesTheBuild) {
#if defined(__aarch64__)
    EXPECT_STREQ(simd::neonBackendName(), "native");
#else
    EXPECT_STREQ(simd::neonBackendName(), "SIMDe");
#endif
}
