// Merging learnt models into the board's model set: known bodies keep id and frame, new ones ids.
#include "firmware_app/firmware/model_merge.hpp"

#include <algorithm>
#include <optional>
#include <string>

#include "core/rigid_fit.hpp"

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

std::optional<std::string> seldomFindable(const MarkerModel& model, std::size_t mostSeenTogether) {
    if (mostSeenTogether == 0 || model.sMin <= mostSeenTogether)
        return std::nullopt;
    return "needs " + std::to_string(model.sMin) +
           " of its markers in view to be found, and the session showed at most " +
           std::to_string(mostSeenTogether) +
           " at once: it will seldom or never be found. Make its layout less regular (move a "
           "marker or two off their pattern) and calibrate again";
}

namespace {

/// \a model moved into the known frame by \a T_known_from_learnt, then refitted over every
/// marker that lands within \a tolerance_mm of a known one (the transform that tied the two came
/// from the few markers one frame showed of both).
MarkerModel registeredOnto(const MarkerModel& model, const MarkerModel& known,
                           RigidTransform T_known_from_learnt, double tolerance_mm) {
    for (int round = 0; round < 2; ++round) {
        const MarkerPairs pairs =
            coincidingMarkers(model, known, T_known_from_learnt, tolerance_mm);
        if (pairs.learnt_mm.size() < 3)
            break;
        if (const std::optional<RigidFit> fit = fitRigid(pairs.learnt_mm, pairs.known_mm))
            T_known_from_learnt = fit->transform;
    }
    MarkerModel moved = copyOf(model);
    for (Vec3& m : moved.markers_model_mm)
        m = T_known_from_learnt.apply(m);
    return moved;
}

} // namespace

MergedModels mergeLearntModels(std::span<const NamedModel> known,
                               std::span<const MarkerModel> learnt,
                               std::span<const SameObject> sameObjects, std::size_t maxModels,
                               const SminConfig& shape, double trackingTolerance_mm) {
    auto fragmentOf = [&](const MarkerModel& part, const MarkerModel& whole) {
        return 2 * part.markers_model_mm.size() < whole.markers_model_mm.size() &&
               isPartOf(part, whole, shape);
    };
    MergedModels result;
    result.models = copyOf(known);
    result.learntIndex.assign(result.models.size(), -1);
    // Known bodies a learnt model was tied to, by position in the session or by shape.
    std::vector<bool> tied(known.size(), false);
    for (const SameObject& same : sameObjects)
        if (same.known < known.size() && same.learnt < learnt.size())
            tied[same.known] = true;
    auto adopt = [&](std::size_t i, std::size_t j, const RigidTransform& T_known_from_learnt) {
        tied[j] = true;
        MarkerModel model =
            registeredOnto(learnt[i], known[j].model, T_known_from_learnt, shape.tolerance_mm);
        // Fewer markers find a body in fewer views: the layout from before tracks better.
        if (model.markers_model_mm.size() < known[j].model.markers_model_mm.size()) {
            result.kept.push_back(known[j].model.id);
            return;
        }
        model.id = known[j].model.id;
        result.models[j].model = std::move(model);
        result.learntIndex[j] = static_cast<int>(i);
        ++result.updated;
    };
    for (std::size_t i = 0; i < learnt.size(); ++i) {
        const auto same = std::find_if(sameObjects.begin(), sameObjects.end(),
                                       [&](const SameObject& s) { return s.learnt == i; });
        if (same != sameObjects.end() && same->known < known.size()) {
            adopt(i, same->known, same->T_known_from_learnt);
            continue;
        }
        bool fragment = false;
        for (std::size_t j = 0; j < learnt.size() && !fragment; ++j)
            fragment = j != i && fragmentOf(learnt[i], learnt[j]);
        for (std::size_t j = 0; j < known.size() && !fragment; ++j)
            fragment = fragmentOf(learnt[i], known[j].model);
        if (fragment) {
            ++result.fragments;
            continue;
        }
        // A body the session did not place: the same layout is the same object.
        std::optional<RigidTransform> T_known_from_learnt;
        std::size_t match = 0;
        for (; match < known.size() && !T_known_from_learnt; ++match)
            if (!tied[match])
                T_known_from_learnt = sameShapeTransform(learnt[i], known[match].model, shape);
        if (T_known_from_learnt) {
            adopt(i, match - 1, *T_known_from_learnt);
            continue;
        }
        if (result.models.size() >= maxModels) {
            ++result.refused;
            continue;
        }
        MarkerModel model = copyOf(learnt[i]);
        std::uint32_t id = 0;
        while (std::any_of(result.models.begin(), result.models.end(),
                           [&](const NamedModel& m) { return m.model.id == id; }))
            ++id;
        model.id = id;
        result.models.push_back({std::move(model), "body " + std::to_string(id)});
        result.learntIndex.push_back(static_cast<int>(i));
        ++result.added;
    }
    // S_min holds against the whole set, the models kept from before included, as the tracker
    // tells distances apart.
    SminConfig findable = shape;
    findable.tolerance_mm = std::min(shape.tolerance_mm, trackingTolerance_mm);
    auto sminOf = [&](const std::vector<NamedModel>& set) {
        std::vector<MarkerModel> layouts;
        for (const NamedModel& m : set)
            layouts.push_back(copyOf(m.model));
        computeSmin(layouts, findable);
        return layouts;
    };
    std::vector<MarkerModel> layouts = sminOf(result.models);
    if (result.updated > 0) {
        // A new layout that needs more markers in view to be found than the one from before
        // (both judged now, in this set) would find the body in fewer frames: the one from
        // before stays.
        std::vector<NamedModel> before = copyOf(result.models);
        for (std::size_t j = 0; j < known.size(); ++j)
            if (result.learntIndex[j] >= 0)
                before[j].model = copyOf(known[j].model);
        const std::vector<MarkerModel> beforeLayouts = sminOf(before);
        bool reverted = false;
        for (std::size_t j = 0; j < known.size(); ++j)
            if (result.learntIndex[j] >= 0 && layouts[j].sMin > beforeLayouts[j].sMin) {
                result.models[j].model = copyOf(known[j].model);
                result.learntIndex[j] = -1;
                --result.updated;
                result.kept.push_back(known[j].model.id);
                reverted = true;
            }
        if (reverted)
            layouts = sminOf(result.models);
    }
    for (std::size_t i = 0; i < result.models.size(); ++i) {
        result.models[i].model.sMin = layouts[i].sMin;
        result.models[i].model.sameShapeAs = layouts[i].sameShapeAs;
    }
    return result;
}

} // namespace edgetrack::app
