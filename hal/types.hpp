// Time and counter vocabulary shared by every HAL interface.
#pragma once

#include <cstdint>

namespace edgetrack::hal {

/// \brief Nanoseconds on the board's monotonic clock (CLOCK_MONOTONIC on Linux).
using Nanoseconds = std::int64_t;

inline constexpr Nanoseconds kNanosecondsPerSecond = 1'000'000'000;
inline constexpr Nanoseconds kNanosecondsPerMillisecond = 1'000'000;

constexpr double toSeconds(Nanoseconds t) {
    return static_cast<double>(t) * 1e-9;
}

} // namespace edgetrack::hal
