// Random marker layouts for tests: markers in an 80 mm cube, kept apart like real markers.
#pragma once

#include <random>
#include <vector>

#include "core/geometry.hpp"

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

} // namespace edgetrack::test
