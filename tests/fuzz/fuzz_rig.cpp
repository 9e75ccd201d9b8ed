// Fuzz target: rig.toml (INTERFACES section 2).
#include <cmath>
#include <cstdint>
#include <string_view>

#include "firmware_app/formats/recording.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const Result<StereoRig> rig = recording::parseRig(text, "rig.toml");
    if (!rig && rig.error().message.rfind("rig.toml", 0) != 0)
        fuzz::fail("an error does not start with the file's name");
    return 0;
}
