// The two-camera rig of rig.toml (INTERFACES §2) with its rectification.
#include "core/stereo_rig.hpp"

namespace edgetrack {

StereoRig::StereoRig(const CameraModel& camera0, const CameraModel& camera1)
    : cameras_{camera0, camera1} {
    const Vec3 baseline = camera1.centre_rig_mm() - camera0.centre_rig_mm();
    baseline_mm_ = baseline.norm();
    valid_ = camera0.isValid() && camera1.isValid() && baseline_mm_ > 1e-6;
    if (!valid_)
        return;

    // New x along the baseline; new y perpendicular to it and to camera 0's optical axis, so the
    // rectified frame stays as close to camera 0 as the baseline allows.
    const Vec3 xAxis = baseline / baseline_mm_;
    const Vec3 opticalAxis0 = camera0.extrinsics().rotation_cam_from_rig.row(2).transpose();
    Vec3 yAxis = opticalAxis0.cross(xAxis);
    if (yAxis.norm() < 1e-9) {
        // The baseline runs along the optical axis: no rectification can make epipolar lines rows.
        valid_ = false;
        return;
    }
    yAxis.normalize();
    const Vec3 zAxis = xAxis.cross(yAxis);
    rotation_rect_from_rig_.row(0) = xAxis.transpose();
    rotation_rect_from_rig_.row(1) = yAxis.transpose();
    rotation_rect_from_rig_.row(2) = zAxis.transpose();

    const CameraIntrinsics& a = camera0.intrinsics();
    const CameraIntrinsics& b = camera1.intrinsics();
    rectifiedFocal_px_ = (a.fx_px + a.fy_px + b.fx_px + b.fy_px) / 4.0;
}

std::optional<Vec2> StereoRig::rectifyDirection(const Vec3& direction_rig) const {
    const Vec3 d = rotation_rect_from_rig_ * direction_rig;
    if (d.z() <= 1e-9)
        return std::nullopt;
    return Vec2{rectifiedFocal_px_ * d.x() / d.z(), rectifiedFocal_px_ * d.y() / d.z()};
}

std::optional<Vec2> StereoRig::rectify(int cameraIndex, const Vec2& pixel) const {
    const std::optional<Ray> r = camera(cameraIndex).ray(pixel);
    if (!r)
        return std::nullopt;
    return rectifyDirection(r->direction_rig);
}

std::optional<Vec2> StereoRig::rectifyPoint(int cameraIndex, const Vec3& point_rig_mm) const {
    return rectifyDirection(point_rig_mm - camera(cameraIndex).centre_rig_mm());
}

} // namespace edgetrack
