// Optional smoothing and latency compensation of one body's poses for the host (alpha-beta).
#pragma once

#include <optional>

#include "core/geometry.hpp"
#include "core/rigid_transform.hpp"

namespace edgetrack {

/// \brief Settings of the pose filter; the default passes poses through untouched.
struct PoseFilterConfig {
    /// Off: update() returns the measured pose, so output is raw unless a user asks otherwise.
    bool enabled = false;
    /// Weight of a new measurement in the position and orientation (1 = raw, smaller = smoother
    /// and later).
    double poseGain = 0.6;
    /// Weight of a new measurement's innovation in the velocity and turn rate (per frame).
    double rateGain = 0.2;
    /// The output is extrapolated this far past the measurement (s): the latency from
    /// mid-exposure to the host's display, so that the host sees where the body is now.
    double predictAhead_s = 0.0;
    /// A body unseen for longer than this starts afresh from its next measurement (s).
    double resetAfter_s = 0.1;

    bool operator==(const PoseFilterConfig&) const = default;
};

/**
 * \brief An alpha-beta filter of one body's pose: position and velocity in the rig frame (mm,
 * mm/s), orientation and turn rate (rotation vector per second, rig frame).
 *
 * The alpha-beta form (a steady-state Kalman filter of a constant-velocity model) needs no
 * covariances and no allocation; the gains set the trade between jitter and lag. Orientation
 * innovations are rotation vectors of q_measured * q_predicted^-1, so the filter never averages
 * quaternion components and is indifferent to their sign.
 */
class PoseFilter {
public:
    explicit PoseFilter(const PoseFilterConfig& config = {})
        : config_(config) {}

    /**
     * \brief Take the pose measured at \a time_s (mid-exposure).
     * \return T_rig_from_model filtered and extrapolated to time_s + predictAhead_s; the
     * measurement itself when the filter is off.
     */
    RigidTransform update(double time_s, const RigidTransform& T_rig_from_model);

    /// \brief The pose expected at \a time_s from the state alone (no measurement), or nothing
    /// when the filter is off, empty, or the body has been unseen for longer than resetAfter_s.
    std::optional<RigidTransform> predict(double time_s) const;

    void reset() { initialised_ = false; }

private:
    RigidTransform extrapolate(double ahead_s) const;

    PoseFilterConfig config_;
    bool initialised_ = false;
    double time_s_ = 0.0;
    Vec3 position_mm_ = Vec3::Zero();
    Vec3 velocity_mmps_ = Vec3::Zero();
    Quat orientation_ = Quat::Identity();
    Vec3 turnRate_radps_ = Vec3::Zero();
};

} // namespace edgetrack
