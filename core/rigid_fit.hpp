// Least-squares rigid fit of two point sets (Kabsch / Umeyama without scale).
#pragma once

#include <array>
#include <optional>
#include <span>

#include "core/rigid_transform.hpp"

namespace edgetrack {

/// \brief The best rigid transform between two point sets and its residual.
struct RigidFit {
    /// Maps the `from` points onto the `to` points: to ~ transform.apply(from).
    RigidTransform transform;
    /// Root mean square of |to_i - transform(from_i)| (mm): the paper's eq. 6 as an RMS.
    double rms_mm = 0.0;
};

/**
 * \brief Least-squares rotation and translation from \a from to \a to (paired by index).
 *
 * Accumulates the 3x3 cross-covariance and decomposes it with a fixed-size SVD, so it never
 * touches the heap whatever the number of points.
 * \return nothing when the spans differ in size, hold fewer than three points, or the points are
 * (nearly) collinear, so that the rotation about their line is undetermined.
 */
std::optional<RigidFit> fitRigid(std::span<const Vec3> from, std::span<const Vec3> to);

/**
 * \brief fitRigid's transform for two triangles of (nearly) equal sides, corners paired by
 * index, in closed form: three points lie in a plane, so the least-squares rotation turns the one
 * triangle's normal onto the other's and then turns in that plane by the two-dimensional
 * Procrustes angle. For searches that try thousands of triangle pairs (S_min), where the SVD was
 * most of a try's cost.
 * \return nothing when either triangle is (nearly) collinear.
 */
std::optional<RigidTransform> fitTriangle(const std::array<Vec3, 3>& from,
                                          const std::array<Vec3, 3>& to);

} // namespace edgetrack
