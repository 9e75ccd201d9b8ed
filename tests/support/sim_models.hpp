// Marker models made from a simulated scene's true layouts, for tracking tests and benchmarks.
#pragma once

#include <vector>

#include "core/marker_model.hpp"
#include "core/marker_set.hpp"
#include "hal/sim/scene.hpp"

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
        MarkerModel m(markers.size());
        m.id = static_cast<std::uint32_t>(k);
        for (const sim::SimMarker& marker : markers)
            m.markers_model_mm.push_back(marker.position_object_mm);
        for (std::size_t i = 0; i < markers.size(); ++i)
            for (std::size_t j = i + 1; j < markers.size(); ++j)
                m.edges.push_back(ModelEdge{
                    static_cast<std::uint16_t>(i), static_cast<std::uint16_t>(j),
                    (markers[i].position_object_mm - markers[j].position_object_mm).norm()});
        models.push_back(std::move(m));
    }
    computeSmin(models, SminConfig{});
    return models;
}

} // namespace edgetrack::test
