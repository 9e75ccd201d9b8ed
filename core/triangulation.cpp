// Triangulation of a pair of rays by their common perpendicular.
#include "core/triangulation.hpp"

namespace edgetrack {

std::optional<TriangulatedPoint> triangulate(const Ray& ray0, const Ray& ray1) {
    const Vec3& d0 = ray0.direction_rig;
    const Vec3& d1 = ray1.direction_rig;
    const Vec3 w = ray0.origin_rig_mm - ray1.origin_rig_mm;
    const double a = d0.dot(d0);
    const double b = d0.dot(d1);
    const double c = d1.dot(d1);
    const double d = d0.dot(w);
    const double e = d1.dot(w);
    const double denominator = a * c - b * b;
    if (denominator <= 1e-14 * a * c)
        return std::nullopt;

    TriangulatedPoint result;
    result.range0_mm = (b * e - c * d) / denominator;
    result.range1_mm = (a * e - b * d) / denominator;
    const Vec3 on0 = ray0.origin_rig_mm + result.range0_mm * d0;
    const Vec3 on1 = ray1.origin_rig_mm + result.range1_mm * d1;
    result.point_rig_mm = 0.5 * (on0 + on1);
    result.rayGap_mm = (on0 - on1).norm();
    return result;
}

} // namespace edgetrack
