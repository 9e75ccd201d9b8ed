// Rigid transforms (rotation plus translation in mm) and quaternion conversions.
#pragma once

#include <array>

#include "core/geometry.hpp"

namespace edgetrack {

/**
 * \brief A proper rigid transform p_to = rotation * p_from + translation_mm.
 *
 * Name instances after the frames they connect, e.g. `T_rig_from_model` maps model coordinates to
 * rig coordinates (the convention of truth.csv and of the pose output).
 */
struct RigidTransform {
    Quat rotation = Quat::Identity();
    Vec3 translation_mm = Vec3::Zero();

    static RigidTransform identity() { return {}; }
    /// \brief From a rotation matrix (re-orthonormalised through its quaternion) and a translation.
    static RigidTransform fromMatrix(const Mat3& rotationMatrix, const Vec3& translation_mm);

    Vec3 apply(const Vec3& point_mm) const { return rotation * point_mm + translation_mm; }
    Mat3 rotationMatrix() const { return rotation.toRotationMatrix(); }
    RigidTransform inverse() const;
    /// \brief Composition: (a * b).apply(p) == a.apply(b.apply(p)).
    RigidTransform operator*(const RigidTransform& other) const;
};

/// \brief Unit quaternion from scalar-first components; normalises its input.
Quat quaternionFromWxyz(double w, double x, double y, double z);

/**
 * \brief Scalar-first components {w, x, y, z} of a rotation, with w >= 0.
 *
 * q and -q are the same rotation; the sign is fixed so that files and the wire are repeatable.
 */
std::array<double, 4> wxyzFromQuaternion(const Quat& q);

/// \return the angle (radians, 0..pi) of the rotation that takes \a a to \a b.
double rotationAngleBetween_rad(const Quat& a, const Quat& b);

} // namespace edgetrack
