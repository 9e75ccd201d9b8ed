// Fuzz target: C3D files from other tracking systems (Vicon, Qualisys).
#include <cstdint>
#include <string_view>

#include "firmware_app/formats/c3d.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    const std::string_view bytes(reinterpret_cast<const char*>(data), size);
    const auto points = recording::parseC3d(bytes, "take.c3d");
    if (!points) {
        if (points.error().message.rfind("take.c3d", 0) != 0)
            fuzz::fail("an error does not start with the file's name");
        return 0;
    }
    if (points->positions_mm.size() != points->frameCount * points->pointCount ||
        points->valid.size() != points->positions_mm.size())
        fuzz::fail("samples that do not fill frames x points");
    return 0;
}
