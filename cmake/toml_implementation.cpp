// toml++'s implementation, compiled once here; every other file includes its declarations only.
//
// Debian 12's toml++ (3.3.0) asserts preconditions that its own parser breaks on malformed input
// (`[[[1]]]`, a `}` inside an array; fixed upstream from marzer/tomlplusplus#301 on): a debug
// build aborts there, and a clang release build is told to assume they hold. Here they are off
// in every build, so that debug, sanitizer and release builds all parse as a GCC release build
// does (a parse error); tests/fuzz runs that parser under AddressSanitizer and UBSan.
#define TOML_IMPLEMENTATION
#include <toml++/impl/preprocessor.h>
#undef TOML_ASSERT
#define TOML_ASSERT(expr) static_assert(true)
#undef TOML_ASSERT_ASSUME
#define TOML_ASSERT_ASSUME(expr) static_assert(true)
#include <toml++/toml.h>
