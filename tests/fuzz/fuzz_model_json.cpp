// Fuzz target: model files (body_<id>.json, INTERFACES section 4).
#include <cmath>
#include <cstdint>
#include <string_view>

#include "firmware_app/formats/model_file.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    constexpr std::size_t kMaxMarkers = 64;
    const std::string_view text(reinterpret_cast<const char*>(data), size);
    const auto model = app::parseModelJson(text, "body_0.json", kMaxMarkers);
    if (!model) {
        if (model.error().message.rfind("body_0.json", 0) != 0)
            fuzz::fail("an error does not start with the file's name");
        return 0;
    }
    const MarkerModel& m = model->model;
    const std::size_t n = m.markers_model_mm.size();
    if (n > kMaxMarkers)
        fuzz::fail("more markers than allowed");
    for (const Vec3& p : m.markers_model_mm)
        if (!p.allFinite())
            fuzz::fail("a marker that is not finite");
    for (const ModelEdge& e : m.edges)
        if (e.from >= n || e.to >= n)
            fuzz::fail("an edge to a marker that does not exist");
    if (m.sMin < 3 || m.sMin > n)
        fuzz::fail("S_min out of range");
    return 0;
}
