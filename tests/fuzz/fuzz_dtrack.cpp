// Fuzz target: the DTrack ASCII datagram parser (tools and tests read what the board sends).
#include <cstdint>
#include <string_view>

#include "firmware_app/firmware/dtrack.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    (void)app::parseDtrack(std::string_view(reinterpret_cast<const char*>(data), size));
    return 0;
}
