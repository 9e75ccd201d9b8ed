// One include for NEON intrinsics: native on aarch64, SIMDe's portable translation elsewhere.
#pragma once

// SIMD code in edgetrack is written once, in NEON. On x86 hosts SIMDe maps the same intrinsics to
// SSE/AVX or scalar code, so every test exercises the NEON path on every build.
#if defined(__ARM_NEON) && !defined(EDGETRACK_NEON_VIA_SIMDE)
#include <arm_neon.h>
#define EDGETRACK_NEON_NATIVE 1
#else
#define SIMDE_ENABLE_NATIVE_ALIASES
// Our data holds no NaNs: let SIMDe map vminq/vmaxq straight to SSE instead of emulating ARM's
// NaN rules, which costs several instructions per operation.
#define SIMDE_FAST_NANS
#include <simde/arm/neon.h>
#define EDGETRACK_NEON_NATIVE 0
#endif

namespace edgetrack::simd {

/// \return "native" or "SIMDe", for logs and benchmark labels.
constexpr const char* neonBackendName() {
    return EDGETRACK_NEON_NATIVE ? "native" : "SIMDe";
}

} // namespace edgetrack::simd
