// Aligns a learnt marker model with a known layout without knowing which marker is which.
#pragma once

#include <cstddef>
#include <vector>

#include "core/marker_model.hpp"

namespace edgetrack::test {

/// \brief A model laid onto a reference layout.
struct ModelAlignment {
    /// Maps model coordinates onto the layout's (mm).
    RigidTransform T_layout_from_model{};
    /// For each model marker, the layout marker it lands on (within the tolerance), or -1.
    std::vector<int> layoutMarkerOf;
    std::size_t matched = 0;
    /// RMS distance of the matched markers after the final fit (mm).
    double rms_mm = 0.0;
};

/**
 * \brief The rigid transform that lays most model markers onto layout markers: tried from every
 * pair of congruent triangles (model triangles on its edges), refined by a least-squares fit of
 * all matched markers.
 */
ModelAlignment alignModel(const MarkerModel& model, const std::vector<Vec3>& layout,
                          double tolerance_mm);

} // namespace edgetrack::test
