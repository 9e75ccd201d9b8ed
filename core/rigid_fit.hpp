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
 * \brief Whether \a points (mm) stand at least \a minSpread_mm off the line through the two
 * farthest apart of them: points on one line leave the turn about it undetermined, and a fit to
 * them places everything off that line at random. False for fewer than three points.
 */
bool offOneLine(std::span<const Vec3> points, double minSpread_mm);

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

/**
 * \brief The RMS (mm) of fitRigid(\a from, \a to) without the fit: from the largest eigenvalue of
 * Horn's quaternion key matrix (see leaveOneOutRms). For hypothesis tests that refuse most of
 * what they try on the residual alone. Accurate to about 1e-6 mm near zero and 1e-10 mm at
 * 0.01 mm and above; like leaveOneOutRms it does not refuse collinear sets.
 * \return nothing when the spans differ in size, hold fewer than three pairs, or Newton's method
 * did not settle.
 */
std::optional<double> fitRms(std::span<const Vec3> from, std::span<const Vec3> to);

/**
 * \brief The RMS (mm) of fitRigid(\a from, \a to) with pair k left out, for every k, into
 * \a rms_mm[k], without a fit per k.
 *
 * Leaving one pair out changes the centred cross-covariance by a rank-one term and the spreads by
 * a scalar; the residual of the best rotation follows from the largest eigenvalue of Horn's
 * quaternion key matrix, found by Newton's method on its characteristic polynomial (Theobald's
 * QCP). For outlier trimming, which fitted every leave-one-out set in full: on large plate-like
 * layouts with noisy points, most of a tracker's time. Unlike fitRigid it does not refuse
 * collinear sets; a caller that takes one of them fits it with fitRigid.
 * \return false when the spans differ in size, \a rms_mm is smaller, there are fewer than four
 * pairs, or Newton's method did not settle for some k.
 */
bool leaveOneOutRms(std::span<const Vec3> from, std::span<const Vec3> to, std::span<double> rms_mm);

} // namespace edgetrack
