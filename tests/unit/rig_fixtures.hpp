// Camera and rig fixtures shared by the geometry tests: the simulated desktop rig's numbers.
#pragma once

#include <cmath>

#include "core/stereo_rig.hpp"

namespace edgetrack::test {

inline CameraIntrinsics desktopIntrinsics(double k1 = 0.0, double k2 = 0.0) {
    CameraIntrinsics in;
    in.width_px = 1280;
    in.height_px = 800;
    in.fx_px = 910.0;
    in.fy_px = 912.0;
    in.cx_px = 641.5;
    in.cy_px = 398.25;
    in.distortion = {k1, k2, 0.0, 0.0, 0.0};
    return in;
}

inline Mat3 rotationAboutY(double angle_rad) {
    return Eigen::AngleAxisd(angle_rad, Vec3::UnitY()).toRotationMatrix();
}

/// Camera 1 sits \a baseline_mm to the right of camera 0 and toes in by \a toeIn_rad.
inline StereoRig desktopRig(double baseline_mm = 120.0, double toeIn_rad = 0.05, double k1 = -0.12,
                            double k2 = 0.03) {
    CameraExtrinsics ex0;
    CameraExtrinsics ex1;
    ex1.rotation_cam_from_rig = rotationAboutY(toeIn_rad);
    const Vec3 centre1{baseline_mm, 0.0, 0.0};
    ex1.translation_cam_from_rig_mm = -(ex1.rotation_cam_from_rig * centre1);
    CameraIntrinsics in1 = desktopIntrinsics(k1, k2);
    in1.fx_px = 905.0;
    in1.distortion[2] = 0.0007;
    in1.distortion[3] = -0.0004;
    return StereoRig(CameraModel(desktopIntrinsics(k1, k2), ex0), CameraModel(in1, ex1));
}

} // namespace edgetrack::test
