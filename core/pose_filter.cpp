// Alpha-beta pose filter: constant velocity and turn rate, innovations as rotation vectors.
#include "core/pose_filter.hpp"

namespace edgetrack {

namespace {

/// Rotation by rotation vector \a v (axis times angle, radians).
Quat fromRotationVector(const Vec3& v) {
    const double angle = v.norm();
    if (angle < 1e-12)
        return Quat::Identity();
    return Quat(Eigen::AngleAxisd(angle, v / angle));
}

/// Rotation vector of \a q, the short way round (angle at most pi).
Vec3 toRotationVector(const Quat& q) {
    const Eigen::AngleAxisd aa(q.w() < 0.0 ? Quat(-q.w(), -q.x(), -q.y(), -q.z()) : q);
    return aa.angle() * aa.axis();
}

} // namespace

RigidTransform PoseFilter::update(double time_s, const RigidTransform& T_rig_from_model) {
    if (!config_.enabled)
        return T_rig_from_model;
    const double dt = time_s - time_s_;
    if (!initialised_ || !(dt > 0.0) || dt > config_.resetAfter_s) {
        initialised_ = true;
        time_s_ = time_s;
        position_mm_ = T_rig_from_model.translation_mm;
        velocity_mmps_ = Vec3::Zero();
        orientation_ = T_rig_from_model.rotation.normalized();
        turnRate_radps_ = Vec3::Zero();
        return extrapolate(config_.predictAhead_s);
    }
    const Vec3 predictedPosition = position_mm_ + velocity_mmps_ * dt;
    const Quat predictedOrientation = fromRotationVector(turnRate_radps_ * dt) * orientation_;
    const Vec3 positionInnovation = T_rig_from_model.translation_mm - predictedPosition;
    const Vec3 rotationInnovation =
        toRotationVector(T_rig_from_model.rotation * predictedOrientation.inverse());
    position_mm_ = predictedPosition + config_.poseGain * positionInnovation;
    velocity_mmps_ += (config_.rateGain / dt) * positionInnovation;
    orientation_ =
        (fromRotationVector(config_.poseGain * rotationInnovation) * predictedOrientation)
            .normalized();
    turnRate_radps_ += (config_.rateGain / dt) * rotationInnovation;
    time_s_ = time_s;
    return extrapolate(config_.predictAhead_s);
}

std::optional<RigidTransform> PoseFilter::predict(double time_s) const {
    if (!config_.enabled || !initialised_ || time_s - time_s_ > config_.resetAfter_s)
        return std::nullopt;
    return extrapolate(time_s - time_s_);
}

RigidTransform PoseFilter::extrapolate(double ahead_s) const {
    RigidTransform out;
    out.translation_mm = position_mm_ + velocity_mmps_ * ahead_s;
    out.rotation = (fromRotationVector(turnRate_radps_ * ahead_s) * orientation_).normalized();
    return out;
}

} // namespace edgetrack
