// Fuzz target: the binary 8-bit PGM images of a recording.
#include <cstdint>
#include <string_view>

#include "firmware_app/formats/recording.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    fuzz::FuzzInput in(data, size);
    // Half the inputs must match the camera's size from rig.toml, as the reader asks.
    const bool sized = in.byte() % 2 == 0;
    const int width = sized ? 16 : 0, height = sized ? 8 : 0;
    const auto image = recording::parsePgm(in.rest(), "f.pgm", width, height);
    if (!image) {
        if (image.error().message.rfind("f.pgm", 0) != 0)
            fuzz::fail("an error does not start with the file's name");
        return 0;
    }
    if (image->width <= 0 || image->height <= 0 ||
        image->pixels.size() !=
            static_cast<std::size_t>(image->width) * static_cast<std::size_t>(image->height))
        fuzz::fail("an image whose pixels do not fill its size");
    if (sized && (image->width != width || image->height != height))
        fuzz::fail("an image of another size than the camera's accepted");
    return 0;
}
