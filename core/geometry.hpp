// Geometry vocabulary of the core: fixed-size Eigen types in double precision.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace edgetrack {

// Geometry runs in double: triangulation at half a metre must be exact to well below a micrometre,
// and the A72/A76 FPU does double at the same throughput as float for scalar code.
using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Quat = Eigen::Quaterniond;

} // namespace edgetrack
