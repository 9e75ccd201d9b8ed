// Rigid transforms (rotation plus translation in mm) and quaternion conversions.
#include "core/rigid_transform.hpp"

#include <algorithm>
#include <cmath>

namespace edgetrack {

RigidTransform RigidTransform::fromMatrix(const Mat3& rotationMatrix, const Vec3& translation_mm) {
    RigidTransform t;
    t.rotation = Quat(rotationMatrix).normalized();
    t.translation_mm = translation_mm;
    return t;
}

RigidTransform RigidTransform::inverse() const {
    RigidTransform t;
    t.rotation = rotation.conjugate();
    t.translation_mm = -(t.rotation * translation_mm);
    return t;
}

RigidTransform RigidTransform::operator*(const RigidTransform& other) const {
    RigidTransform t;
    t.rotation = (rotation * other.rotation).normalized();
    t.translation_mm = rotation * other.translation_mm + translation_mm;
    return t;
}

Quat quaternionFromWxyz(double w, double x, double y, double z) {
    return Quat(w, x, y, z).normalized();
}

std::array<double, 4> wxyzFromQuaternion(const Quat& q) {
    const Quat n = q.normalized();
    const double sign = n.w() < 0.0 ? -1.0 : 1.0;
    return {sign * n.w(), sign * n.x(), sign * n.y(), sign * n.z()};
}

double rotationAngleBetween_rad(const Quat& a, const Quat& b) {
    // |dot| handles the double cover; clamping guards acos against rounding just above one.
    const double dot = std::abs(a.normalized().dot(b.normalized()));
    return 2.0 * std::acos(std::clamp(dot, 0.0, 1.0));
}

} // namespace edgetrack
