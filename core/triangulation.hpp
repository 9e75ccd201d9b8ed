// Triangulation of a pair of rays by their common perpendicular.
#pragma once

#include <optional>

#include "core/camera_model.hpp"

namespace edgetrack {

/// \brief A triangulated point and how well the two rays agreed.
struct TriangulatedPoint {
    /// Midpoint of the shortest segment between the rays, rig frame (mm).
    Vec3 point_rig_mm = Vec3::Zero();
    /// Length of that segment (mm): zero for rays that truly intersect.
    double rayGap_mm = 0.0;
    /// Signed distances along each ray to the segment's ends (mm); negative means behind a camera.
    double range0_mm = 0.0;
    double range1_mm = 0.0;
};

/**
 * \brief Triangulate two rays (rig frame, unit directions) by the midpoint method.
 * \return nothing when the rays are parallel within numerical precision.
 */
std::optional<TriangulatedPoint> triangulate(const Ray& ray0, const Ray& ray1);

} // namespace edgetrack
