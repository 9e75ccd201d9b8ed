// Pinhole camera with OpenCV's five distortion coefficients: projection, undistortion, rays.
#pragma once

#include <array>
#include <optional>

#include "core/geometry.hpp"

namespace edgetrack {

/// \brief Intrinsics of one camera, in pixels, as in rig.toml (INTERFACES §2).
struct CameraIntrinsics {
    int width_px = 0;
    int height_px = 0;
    double fx_px = 0.0;
    double fy_px = 0.0;
    double cx_px = 0.0;
    double cy_px = 0.0;
    /// OpenCV order: k1, k2, p1, p2, k3.
    std::array<double, 5> distortion{};
};

/// \brief Where a camera sits in the rig: p_cam = rotation * p_rig + translation (millimetres).
struct CameraExtrinsics {
    Mat3 rotation_cam_from_rig = Mat3::Identity();
    Vec3 translation_cam_from_rig_mm = Vec3::Zero();
};

/// \brief A half-line in the rig frame: origin (mm) plus a unit direction.
struct Ray {
    Vec3 origin_rig_mm = Vec3::Zero();
    Vec3 direction_rig = Vec3::UnitZ();
};

/**
 * \brief A calibrated camera: pinhole plus radial (k1, k2, k3) and tangential (p1, p2) distortion.
 *
 * "Normalized" coordinates are x/z, y/z in the camera frame (no unit); "pixel" coordinates are raw,
 * distorted sensor pixels with (0, 0) at the centre of the top-left pixel, as OpenCV.
 */
class CameraModel {
public:
    CameraModel() = default;
    CameraModel(const CameraIntrinsics& intrinsics, const CameraExtrinsics& extrinsics);

    /// \return true when the focal lengths and size are positive and the rotation is proper.
    bool isValid() const { return valid_; }

    const CameraIntrinsics& intrinsics() const { return intrinsics_; }
    const CameraExtrinsics& extrinsics() const { return extrinsics_; }

    /// \return the camera's optical centre in the rig frame (mm).
    Vec3 centre_rig_mm() const { return centre_rig_mm_; }

    /// \return \a point_rig_mm in the camera frame (mm).
    Vec3 toCamera(const Vec3& point_rig_mm) const;

    /**
     * \brief Project a point of the rig frame (mm) to raw pixel coordinates.
     * \return the pixel, or nothing when the point is not in front of the camera.
     */
    std::optional<Vec2> project(const Vec3& point_rig_mm) const;

    /// \brief Apply the lens distortion to undistorted normalized coordinates.
    Vec2 distortNormalized(const Vec2& undistorted) const;

    /// \brief The 2x2 Jacobian of distortNormalized() at \a undistorted (no unit).
    Eigen::Matrix2d distortionJacobian(const Vec2& undistorted) const;

    /**
     * \brief How large the image of a small sphere seen along \a direction_rig is: the radius
     * (px) of the disc of the same area as its image, per radian of the sphere's angular radius.
     *
     * A sphere of radius R at range d subtends a cone of half-angle R / d. At an angle theta off
     * the optical axis that cone cuts the normalized image plane in an ellipse of semi-axes
     * (R / d) / cos(theta) across and (R / d) / cos^2(theta) along the radius, of area
     * pi (R / d)^2 / cos^3(theta); the lens distortion then scales areas by its Jacobian's
     * determinant, and the focal lengths by fx fy. So the disc radius of the image is (R / d)
     * times sqrt(fx fy det J / cos^3(theta)), which this returns: on the axis of an undistorted
     * lens it is the focal length.
     * \return 0 when the direction looks away from the camera.
     */
    double pixelsPerRadian(const Vec3& direction_rig) const;

    /**
     * \brief Where the radial distortion folds the image back inside it: the distance (px, from
     * the principal point) at which the distorted radius r (1 + k1 r^2 + k2 r^4 + k3 r^6) stops
     * growing before it reaches the farthest corner. Past a fold two directions image to one
     * pixel and no undistortion is right; a lens model fitted outside the image can do this
     * (k1 = -5), a lens cannot. Nothing when the mapping grows out to every corner.
     */
    std::optional<double> foldInsideImage_px() const;

    /// \brief Map normalized (distorted or not) coordinates to pixels.
    Vec2 pixelFromNormalized(const Vec2& normalized) const;

    /**
     * \brief Undistort a raw pixel by Newton iteration on the distortion model.
     * \return undistorted normalized coordinates, or nothing when the iteration does not converge
     * (a pixel outside the lens model's invertible region).
     */
    std::optional<Vec2> undistortPixel(const Vec2& pixel) const;

    /// \brief The ray through a raw pixel, in the rig frame; nothing when undistortion fails.
    std::optional<Ray> ray(const Vec2& pixel) const;

private:
    /// Newton's method for the undistorted point whose distortion is \a target, from \a estimate.
    std::optional<Vec2> newtonUndistort(const Vec2& target, Vec2 estimate) const;
    CameraIntrinsics intrinsics_{};
    CameraExtrinsics extrinsics_{};
    Vec3 centre_rig_mm_ = Vec3::Zero();
    bool valid_ = false;
};

} // namespace edgetrack
