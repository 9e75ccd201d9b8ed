// Joint least squares of a marker layout over many poses: its normal equations and its precision.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include <Eigen/Core>

#include "core/rigid_transform.hpp"

namespace edgetrack {

/**
 * \brief How closely a session's frames fix a learnt layout: the covariance of the joint least
 * squares that places its markers (the normal equations with the poses eliminated, scaled by the
 * residual variance), the layout's placement as a whole left out.
 *
 * It is the error any unbiased estimate of the layout from these frames would have (the
 * Cramér-Rao bound of the least squares), so it tells whether a model is as good as the session
 * allows and whether a longer session would help: a layout whose sides were each seen in few
 * attitudes, or a part tied to the rest by few frames, is known no better however it is computed.
 */
struct LayoutPrecision {
    /// Residual noise of a point, per coordinate (mm): the squared fit residuals over their
    /// degrees of freedom (3 per matched marker, less 6 per pose).
    double pointSigma_mm = 0.0;
    /// Expected RMS distance of the markers from their true places (mm), rigid placement
    /// removed; infinite when the layout has loose modes.
    double markerRms_mm = 0.0;
    /// The same for the marker known least precisely (mm).
    double worstMarker_mm = 0.0;
    /// Deformations of the layout that no frame constrains (a part turning about the line
    /// through the two markers it shares with the rest): where there is one, the places of some
    /// markers are not fixed by the data at all.
    std::uint32_t looseModes = 0;
};

/**
 * \brief Add one frame's observations to the reduced normal equations of a joint least squares
 * over poses and markers, the frame's pose eliminated (its Schur complement).
 *
 * Residual r = R m + t - p, the pose perturbed on the left (rotation, then translation), markers
 * in the body frame. Frames with fewer than three observations add nothing.
 * \param T_rig_from_body the frame's pose (rig from body).
 * \param markers_mm the matched markers (body frame, mm).
 * \param points_mm their points (rig frame, mm), in the same order.
 * \param which each marker's index in the layout: rows 3 which[i] .. 3 which[i] + 2.
 * \param reduced the system (3 rows per layout marker), added to.
 * \param rhs its right-hand side, added to.
 */
void addToReducedSystem(const RigidTransform& T_rig_from_body, std::span<const Vec3> markers_mm,
                        std::span<const Vec3> points_mm, std::span<const std::size_t> which,
                        Eigen::MatrixXd& reduced, Eigen::VectorXd& rhs);

/**
 * \brief The precision of a layout from its reduced normal equations and the fit residuals.
 * \param reduced the system addToReducedSystem() built (3 rows per marker), undamped.
 * \param counts per marker, the frames that matched it; markers with none are left out.
 * \param squaredResiduals_mm2 the sum of the squared fit residuals over those frames (mm^2).
 * \param degreesOfFreedom 3 per matched marker less 6 per frame, summed.
 */
LayoutPrecision layoutPrecision(const Eigen::MatrixXd& reduced,
                                std::span<const std::uint32_t> counts, double squaredResiduals_mm2,
                                double degreesOfFreedom);

} // namespace edgetrack
