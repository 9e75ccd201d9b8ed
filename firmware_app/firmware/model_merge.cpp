// Merging learnt models into the board's model set: replace by layout, drop fragments, new ids.
#include "firmware_app/firmware/model_merge.hpp"

#include <algorithm>
#include <string>

namespace edgetrack::app {

MarkerModel copyOf(const MarkerModel& model) {
    MarkerModel copy(model.markers_model_mm.size());
    copy.assign(model);
    return copy;
}

std::vector<NamedModel> copyOf(std::span<const NamedModel> models) {
    std::vector<NamedModel> copies;
    copies.reserve(models.size());
    for (const NamedModel& m : models)
        copies.push_back({copyOf(m.model), m.name});
    return copies;
}

MergedModels mergeLearntModels(std::span<const NamedModel> known,
                               std::span<const MarkerModel> learnt, std::size_t maxModels,
                               const SminConfig& shape) {
    auto fragmentOf = [&](const MarkerModel& part, const MarkerModel& whole) {
        return 2 * part.markers_model_mm.size() < whole.markers_model_mm.size() &&
               isPartOf(part, whole, shape);
    };
    MergedModels result;
    result.models = copyOf(known);
    result.learntIndex.assign(result.models.size(), -1);
    std::vector<bool> replaced(result.models.size(), false);
    for (std::size_t i = 0; i < learnt.size(); ++i) {
        bool fragment = false;
        for (std::size_t j = 0; j < learnt.size() && !fragment; ++j)
            fragment = j != i && fragmentOf(learnt[i], learnt[j]);
        for (std::size_t j = 0; j < known.size() && !fragment; ++j)
            fragment = fragmentOf(learnt[i], known[j].model);
        if (fragment) {
            ++result.fragments;
            continue;
        }
        MarkerModel model = copyOf(learnt[i]);
        std::size_t match = known.size();
        for (std::size_t j = 0; j < known.size() && match == known.size(); ++j)
            if (!replaced[j] && sameShape(result.models[j].model, model, shape))
                match = j;
        if (match < known.size()) {
            model.id = result.models[match].model.id;
            result.models[match].model = std::move(model);
            result.learntIndex[match] = static_cast<int>(i);
            replaced[match] = true;
            ++result.updated;
            continue;
        }
        if (result.models.size() >= maxModels) {
            ++result.refused;
            continue;
        }
        std::uint32_t id = 0;
        while (std::any_of(result.models.begin(), result.models.end(),
                           [&](const NamedModel& m) { return m.model.id == id; }))
            ++id;
        model.id = id;
        result.models.push_back({std::move(model), "body " + std::to_string(id)});
        result.learntIndex.push_back(static_cast<int>(i));
        ++result.added;
    }
    // S_min holds against the whole set, the models kept from before included.
    std::vector<MarkerModel> layouts;
    for (const NamedModel& m : result.models)
        layouts.push_back(copyOf(m.model));
    computeSmin(layouts, shape);
    for (std::size_t i = 0; i < result.models.size(); ++i) {
        result.models[i].model.sMin = layouts[i].sMin;
        result.models[i].model.sameShapeAs = layouts[i].sameShapeAs;
    }
    return result;
}

} // namespace edgetrack::app
