// The two-camera rig of rig.toml (INTERFACES §2) with its rectification.
#pragma once

#include <array>
#include <optional>

#include "core/camera_model.hpp"

namespace edgetrack {

/**
 * \brief Two calibrated cameras; camera 0 defines the rig frame (x right, y down, z forward, mm).
 *
 * Rectification rotates both cameras' rays into one common frame whose x axis runs along the
 * baseline (Fusiello's construction, as OpenCV's stereoRectify without the image warp). In that
 * frame corresponding blobs have equal rectified y: this is the epipolar constraint the stereo
 * matcher of the paper (eq. 1) measures. Only blob centres are rectified, never images.
 */
class StereoRig {
public:
    StereoRig() = default;
    StereoRig(const CameraModel& camera0, const CameraModel& camera1);

    /// \return true when both cameras are valid and their centres are apart.
    bool isValid() const { return valid_; }

    const CameraModel& camera(int index) const { return cameras_[index == 0 ? 0 : 1]; }
    const std::array<CameraModel, 2>& cameras() const { return cameras_; }

    /// \return the distance between the two optical centres (mm).
    double baseline_mm() const { return baseline_mm_; }

    /// \return R such that d_rect = R * d_rig for any direction of the rig frame.
    const Mat3& rotation_rect_from_rig() const { return rotation_rect_from_rig_; }

    /// \return focal length of the virtual rectified cameras (px): the mean of the four focals.
    double rectifiedFocal_px() const { return rectifiedFocal_px_; }

    /**
     * \brief Rectified coordinates of a raw pixel of camera \a cameraIndex.
     *
     * Units are pixels of a virtual camera with focal rectifiedFocal_px() and its principal point
     * at the origin, so epipolar thresholds read in pixels.
     * \return nothing when the pixel cannot be undistorted or looks away from the rectified plane.
     */
    std::optional<Vec2> rectify(int cameraIndex, const Vec2& pixel) const;

    /// \brief Rectified coordinates of a point of the rig frame as seen from camera \a cameraIndex.
    std::optional<Vec2> rectifyPoint(int cameraIndex, const Vec3& point_rig_mm) const;

    /// \brief Rectified coordinates of a viewing direction (rig frame), e.g. a blob's ray.
    std::optional<Vec2> rectifyDirection(const Vec3& direction_rig) const;

private:
    std::array<CameraModel, 2> cameras_{};
    Mat3 rotation_rect_from_rig_ = Mat3::Identity();
    double rectifiedFocal_px_ = 1.0;
    double baseline_mm_ = 0.0;
    bool valid_ = false;
};

} // namespace edgetrack
