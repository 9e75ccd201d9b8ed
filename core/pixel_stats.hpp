// Whole-frame pixel statistics in one NEON pass: bright-pixel count and maximum.
#pragma once

#include <cstdint>
#include <span>

namespace edgetrack {

/// \brief What one pass over an 8-bit frame learns about its brightness.
struct PixelStats {
    /// Number of pixels >= the threshold.
    std::uint64_t brightCount = 0;
    /// Largest pixel value (0 for an empty span).
    std::uint8_t maximum = 0;
};

/**
 * \brief Count the pixels at or above \a threshold and find the brightest, in NEON.
 *
 * Used to tell a lit frame from a dark one (LED ring off, camera covered) before blob detection.
 */
PixelStats measurePixels(std::span<const std::uint8_t> pixels, std::uint8_t threshold);

} // namespace edgetrack
