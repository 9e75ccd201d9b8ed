// Marker models made from a simulated scene's true layouts, for tracking tests and benchmarks.
#pragma once

#include <vector>

#include "core/marker_model.hpp"
#include "core/marker_set.hpp"
#include "hal/sim/scene.hpp"
#include "tests/support/layouts.hpp"

namespace edgetrack::test {

/**
 * \brief One model per scene object with 4 to 128 markers (ids are the objects' indices): the
 * true layout, every pair of markers co-visible (more edges than a calibration gives, so searches
 * meet more candidates), S_min from computeSmin as `edgetrack calibrate` sets it.
 */
inline std::vector<MarkerModel> truthModels(const sim::Scene& scene) {
    std::vector<MarkerModel> models;
    for (std::size_t k = 0; k < scene.objects.size(); ++k) {
        const auto& markers = scene.objects[k].object.markers;
        if (markers.size() < 4 || markers.size() > MarkerSet::kCapacity)
            continue;
        std::vector<Vec3> layout;
        for (const sim::SimMarker& marker : markers)
            layout.push_back(marker.position_object_mm);
        models.push_back(fullyConnectedModel(layout, static_cast<std::uint32_t>(k)));
    }
    computeSmin(models, SminConfig{});
    return models;
}

} // namespace edgetrack::test
