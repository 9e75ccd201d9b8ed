// Fuzz target: the configuration (edgetrack.toml) and the UDP endpoints given on the command line.
#include <cstdint>
#include <string_view>

#include "firmware_app/firmware/firmware_config.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    fuzz::FuzzInput in(data, size);
    if (in.byte() % 4 == 0) {
        (void)app::parseEndpoint(in.rest());
        return 0;
    }
    const auto config = app::parseFirmwareConfig(in.rest(), "edgetrack.toml");
    if (!config && config.error().message.rfind("edgetrack.toml", 0) != 0)
        fuzz::fail("an error does not start with the file's name");
    return 0;
}
