// Pinhole camera with OpenCV's five distortion coefficients: projection, undistortion, rays.
#include "core/camera_model.hpp"

#include <algorithm>
#include <cmath>

namespace edgetrack {

namespace {

// The distortion of normalized coordinates and its 2x2 Jacobian, for Newton's method.
struct DistortionTerms {
    Vec2 distorted;
    Eigen::Matrix2d jacobian;
};

DistortionTerms distortWithJacobian(const std::array<double, 5>& d, const Vec2& p) {
    const double k1 = d[0], k2 = d[1], p1 = d[2], p2 = d[3], k3 = d[4];
    const double x = p.x(), y = p.y();
    const double r2 = x * x + y * y;
    const double radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3));
    const double dRadialDr2 = k1 + r2 * (2.0 * k2 + 3.0 * k3 * r2);

    DistortionTerms t;
    t.distorted = {x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                   y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y};
    t.jacobian(0, 0) = radial + 2.0 * x * x * dRadialDr2 + 2.0 * p1 * y + 6.0 * p2 * x;
    t.jacobian(0, 1) = 2.0 * x * y * dRadialDr2 + 2.0 * p1 * x + 2.0 * p2 * y;
    t.jacobian(1, 0) = 2.0 * x * y * dRadialDr2 + 2.0 * p1 * x + 2.0 * p2 * y;
    t.jacobian(1, 1) = radial + 2.0 * y * y * dRadialDr2 + 6.0 * p1 * y + 2.0 * p2 * x;
    return t;
}

} // namespace

CameraModel::CameraModel(const CameraIntrinsics& intrinsics, const CameraExtrinsics& extrinsics)
    : intrinsics_(intrinsics)
    , extrinsics_(extrinsics) {
    const Mat3& r = extrinsics.rotation_cam_from_rig;
    const bool orthonormal = (r * r.transpose() - Mat3::Identity()).norm() < 1e-6;
    const bool proper = std::abs(r.determinant() - 1.0) < 1e-6;
    const bool finite = r.allFinite() && extrinsics.translation_cam_from_rig_mm.allFinite();
    valid_ = intrinsics.width_px > 0 && intrinsics.height_px > 0 && intrinsics.fx_px > 0.0 &&
             intrinsics.fy_px > 0.0 && std::isfinite(intrinsics.cx_px) &&
             std::isfinite(intrinsics.cy_px) && orthonormal && proper && finite;
    for (double k : intrinsics.distortion)
        valid_ = valid_ && std::isfinite(k);
    centre_rig_mm_ = -(r.transpose() * extrinsics.translation_cam_from_rig_mm);
}

Vec3 CameraModel::toCamera(const Vec3& point_rig_mm) const {
    return extrinsics_.rotation_cam_from_rig * point_rig_mm +
           extrinsics_.translation_cam_from_rig_mm;
}

std::optional<Vec2> CameraModel::project(const Vec3& point_rig_mm) const {
    const Vec3 p = toCamera(point_rig_mm);
    // Closer than a micrometre to the image plane (or behind it) has no meaningful projection.
    if (p.z() <= 1e-3)
        return std::nullopt;
    return pixelFromNormalized(distortNormalized({p.x() / p.z(), p.y() / p.z()}));
}

Vec2 CameraModel::distortNormalized(const Vec2& undistorted) const {
    return distortWithJacobian(intrinsics_.distortion, undistorted).distorted;
}

Eigen::Matrix2d CameraModel::distortionJacobian(const Vec2& undistorted) const {
    return distortWithJacobian(intrinsics_.distortion, undistorted).jacobian;
}

double CameraModel::pixelsPerRadian(const Vec3& direction_rig) const {
    const Vec3 d = extrinsics_.rotation_cam_from_rig * direction_rig;
    const double length = d.norm();
    if (!(d.z() > 1e-9 * length))
        return 0.0;
    const double cosTheta = d.z() / length;
    const double det = distortionJacobian({d.x() / d.z(), d.y() / d.z()}).determinant();
    if (!(det > 0.0))
        return 0.0;
    return std::sqrt(intrinsics_.fx_px * intrinsics_.fy_px * det /
                     (cosTheta * cosTheta * cosTheta));
}

std::optional<double> CameraModel::foldInsideImage_px() const {
    const CameraIntrinsics& in = intrinsics_;
    double corner = 0.0; // the farthest corner, in distorted normalized coordinates
    for (const double x : {-0.5, in.width_px - 0.5})
        for (const double y : {-0.5, in.height_px - 0.5})
            corner =
                std::max(corner, std::hypot((x - in.cx_px) / in.fx_px, (y - in.cy_px) / in.fy_px));
    const double k1 = in.distortion[0], k2 = in.distortion[1], k3 = in.distortion[4];
    const auto distorted = [&](double r) {
        const double r2 = r * r;
        return r * (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)));
    };
    // Walk the undistorted radius out until the distorted one passes the corner (a lens maps
    // well under 90 degrees onto an image; 20 in normalized units is 87 degrees).
    constexpr int kSteps = 4000;
    constexpr double kFarthest = 20.0;
    double previous = 0.0;
    for (int i = 1; i <= kSteps; ++i) {
        const double r = kFarthest * static_cast<double>(i) / kSteps;
        const double now = distorted(r);
        if (now >= corner)
            return std::nullopt;
        if (!(now > previous))
            return previous * std::sqrt(in.fx_px * in.fy_px);
        previous = now;
    }
    return std::nullopt;
}

Vec2 CameraModel::pixelFromNormalized(const Vec2& normalized) const {
    return {intrinsics_.fx_px * normalized.x() + intrinsics_.cx_px,
            intrinsics_.fy_px * normalized.y() + intrinsics_.cy_px};
}

std::optional<Vec2> CameraModel::newtonUndistort(const Vec2& target, Vec2 estimate) const {
    constexpr int kMaxIterations = 30;
    constexpr double kTolerance = 1e-12;
    constexpr double kNegligibleStep = 1e-8;
    for (int i = 0; i < kMaxIterations; ++i) {
        const DistortionTerms t = distortWithJacobian(intrinsics_.distortion, estimate);
        const Vec2 residual = t.distorted - target;
        if (residual.squaredNorm() < kTolerance * kTolerance)
            return estimate;
        const double det = t.jacobian.determinant();
        // A non-positive Jacobian means the model folds back here: no unique undistorted point.
        if (!(det > 1e-9))
            return std::nullopt;
        const Vec2 step = t.jacobian.inverse() * residual;
        estimate -= step;
        if (!estimate.allFinite())
            return std::nullopt;
        // Newton converges quadratically: a step this small leaves an error of about its square,
        // far below the tolerance, so the distortion need not be evaluated once more to see it.
        if (step.squaredNorm() < kNegligibleStep * kNegligibleStep)
            return estimate;
    }
    const Vec2 residual = distortNormalized(estimate) - target;
    if (residual.norm() < 1e-9)
        return estimate;
    return std::nullopt;
}

std::optional<Vec2> CameraModel::undistortPixel(const Vec2& pixel) const {
    const Vec2 target{(pixel.x() - intrinsics_.cx_px) / intrinsics_.fx_px,
                      (pixel.y() - intrinsics_.cy_px) / intrinsics_.fy_px};
    // Newton converges quadratically where OpenCV's fixed-point iteration stalls near the corners
    // of strongly distorted lenses. It starts one fixed-point step away from the distorted point,
    // closer by about the distortion's square, which saves a Newton step or two per blob; where
    // that start overshoots into a fold of a strong lens, it starts again from the distorted point.
    if (const std::optional<Vec2> undistorted =
            newtonUndistort(target, 2.0 * target - distortNormalized(target)))
        return undistorted;
    return newtonUndistort(target, target);
}

std::optional<Ray> CameraModel::ray(const Vec2& pixel) const {
    const std::optional<Vec2> normalized = undistortPixel(pixel);
    if (!normalized)
        return std::nullopt;
    const Vec3 direction_cam{normalized->x(), normalized->y(), 1.0};
    Ray r;
    r.origin_rig_mm = centre_rig_mm_;
    r.direction_rig = (extrinsics_.rotation_cam_from_rig.transpose() * direction_cam).normalized();
    return r;
}

} // namespace edgetrack
