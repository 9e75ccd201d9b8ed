// Fuzz target: the flash model store's decoder, which reads whatever a power cut left on flash.
#include <cstdint>
#include <span>

#include "firmware_app/firmware/model_store.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    constexpr std::size_t kMaxMarkers = 64;
    const auto models = app::decodeModels(std::span(data, size), kMaxMarkers);
    if (!models)
        return 0;
    // What decodes must encode to a payload that decodes to the same models.
    const std::vector<std::uint8_t> again = app::encodeModels(*models);
    const auto twice = app::decodeModels(again, kMaxMarkers);
    if (!twice || twice->size() != models->size())
        fuzz::fail("decoded models do not survive encoding");
    for (std::size_t i = 0; i < models->size(); ++i) {
        const MarkerModel& a = (*models)[i].model;
        const MarkerModel& b = (*twice)[i].model;
        if (a.id != b.id || a.sMin != b.sMin ||
            a.markers_model_mm.size() != b.markers_model_mm.size() ||
            a.edges.size() != b.edges.size() || (*models)[i].name != (*twice)[i].name)
            fuzz::fail("a model changed through encoding");
        for (std::size_t k = 0; k < a.markers_model_mm.size(); ++k)
            if (a.markers_model_mm[k] != b.markers_model_mm[k])
                fuzz::fail("a marker moved through encoding");
    }
    return 0;
}
