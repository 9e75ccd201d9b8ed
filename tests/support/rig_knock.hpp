// A rig's camera 1 knocked out of place, and how far two rigs' camera 1 poses are apart.
#pragma once

#include <numbers>

#include "core/stereo_rig.hpp"

namespace edgetrack::test {

/// \brief \a rig with camera 1 moved by \a offset_mm and turned by \a turn_deg about a tilted
/// axis: a starting guess far off, or the cameras after a knock.
inline StereoRig knockedRig(const StereoRig& rig, double offset_mm, double turn_deg) {
    CameraExtrinsics ex = rig.camera(1).extrinsics();
    ex.rotation_cam_from_rig =
        Eigen::AngleAxisd(turn_deg * std::numbers::pi / 180.0, Vec3(0.6, 0.8, 0.0))
            .toRotationMatrix() *
        ex.rotation_cam_from_rig;
    ex.translation_cam_from_rig_mm += offset_mm * Vec3(0.48, -0.6, 0.64);
    return StereoRig(rig.camera(0), CameraModel(rig.camera(1).intrinsics(), ex));
}

/// \return the angle between the two rigs' camera 1 orientations (degrees).
inline double cameraOneTurn_deg(const StereoRig& a, const StereoRig& b) {
    return Eigen::AngleAxisd(a.camera(1).extrinsics().rotation_cam_from_rig *
                             b.camera(1).extrinsics().rotation_cam_from_rig.transpose())
               .angle() *
           180.0 / std::numbers::pi;
}

/// \return the distance between the two rigs' camera 1 centres (mm).
inline double cameraOneShift_mm(const StereoRig& a, const StereoRig& b) {
    return (a.camera(1).centre_rig_mm() - b.camera(1).centre_rig_mm()).norm();
}

} // namespace edgetrack::test
