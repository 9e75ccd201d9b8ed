// Marker layouts for tests (random ones in an 80 mm cube, kept apart like real markers) and models
// of them.
#pragma once

#include <random>
#include <vector>

#include "core/geometry.hpp"
#include "core/marker_model.hpp"

namespace edgetrack::test {

/// \return \a count markers (mm) in [-40, 40]^3, each at least \a minSpacing_mm from the others.
inline std::vector<Vec3> irregularLayout(std::size_t count, unsigned seed, double minSpacing_mm) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> coordinate(-40.0, 40.0);
    std::vector<Vec3> layout;
    while (layout.size() < count) {
        const Vec3 p(coordinate(random), coordinate(random), coordinate(random));
        bool apart = true;
        for (const Vec3& q : layout)
            apart = apart && (p - q).norm() > minSpacing_mm;
        if (apart)
            layout.push_back(p);
    }
    return layout;
}

/// \return a model of \a layout (mm) in which every pair of markers can be seen together.
inline MarkerModel fullyConnectedModel(const std::vector<Vec3>& layout, std::uint32_t id = 0,
                                       std::uint32_t sMin = 4) {
    MarkerModel model(layout.size());
    model.id = id;
    model.sMin = sMin;
    for (const Vec3& p : layout)
        model.markers_model_mm.push_back(p);
    for (std::size_t i = 0; i < layout.size(); ++i)
        for (std::size_t j = i + 1; j < layout.size(); ++j)
            model.edges.push_back(ModelEdge{static_cast<std::uint16_t>(i),
                                            static_cast<std::uint16_t>(j),
                                            (layout[i] - layout[j]).norm()});
    return model;
}

} // namespace edgetrack::test
