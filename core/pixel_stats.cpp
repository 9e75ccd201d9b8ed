// Whole-frame pixel statistics in one NEON pass: bright-pixel count and maximum.
#include "core/pixel_stats.hpp"

#include <algorithm>

#include "core/simd/neon.hpp"

namespace edgetrack {

PixelStats measurePixels(std::span<const std::uint8_t> pixels, std::uint8_t threshold) {
    PixelStats stats;
    const std::uint8_t* p = pixels.data();
    std::size_t remaining = pixels.size();

    const uint8x16_t thresholdVector = vdupq_n_u8(threshold);
    uint8x16_t maximumVector = vdupq_n_u8(0);
    uint64x2_t countVector = vdupq_n_u64(0);

    // A byte lane counts up to 255 before it must be widened, hence blocks of 255 vectors.
    constexpr std::size_t kVectorsPerBlock = 255;
    while (remaining >= 16) {
        const std::size_t vectors = std::min(remaining / 16, kVectorsPerBlock);
        uint8x16_t laneCount = vdupq_n_u8(0);
        for (std::size_t i = 0; i < vectors; ++i, p += 16) {
            const uint8x16_t v = vld1q_u8(p);
            // The comparison yields 0xFF (-1) per bright lane; subtracting it adds one.
            laneCount = vsubq_u8(laneCount, vcgeq_u8(v, thresholdVector));
            maximumVector = vmaxq_u8(maximumVector, v);
        }
        countVector = vaddq_u64(countVector, vpaddlq_u32(vpaddlq_u16(vpaddlq_u8(laneCount))));
        remaining -= vectors * 16;
    }
    stats.brightCount = vgetq_lane_u64(countVector, 0) + vgetq_lane_u64(countVector, 1);
    stats.maximum = vmaxvq_u8(maximumVector);

    for (; remaining > 0; --remaining, ++p) {
        stats.brightCount += *p >= threshold ? 1u : 0u;
        stats.maximum = std::max(stats.maximum, *p);
    }
    return stats;
}

} // namespace edgetrack
