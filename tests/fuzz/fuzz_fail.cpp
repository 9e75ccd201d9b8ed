// The fuzz targets' failure report: the property that broke, then abort() for the fuzzer to catch.
#include <cstdio>
#include <cstdlib>

#include "tests/fuzz/fuzz_input.hpp"

namespace edgetrack::fuzz {

void fail(const char* what) {
    std::fprintf(stderr, "fuzz property failed: %s\n", what);
    std::abort();
}

} // namespace edgetrack::fuzz
