// A rig's camera 1 knocked out of place, and how far two rigs' camera 1 poses are apart.
#pragma once

#include <numbers>

#include "core/stereo_rig.hpp"
#include "hal/sim/scene.hpp"

namespace edgetrack::test {

/// \brief The simulator's knock: camera 1 moved by \a offset_mm, turned by \a turn_deg.
inline StereoRig knockedRig(const StereoRig& rig, double offset_mm, double turn_deg) {
    return sim::knockedRig(rig, offset_mm, turn_deg);
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
