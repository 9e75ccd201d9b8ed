// The 3D points of a calibration session, kept in fixed storage for the completion stage.
#pragma once

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/bounded_vector.hpp"
#include "core/geometry.hpp"

namespace edgetrack {

/// \brief The canonical order of points: by x, then y, then z.
inline bool canonicallyBefore(const Vec3& a, const Vec3& b) {
    if (a.x() != b.x())
        return a.x() < b.x();
    if (a.y() != b.y())
        return a.y() < b.y();
    return a.z() < b.z();
}

/**
 * \brief Put a frame's points in one order whatever order they came in: by x, then y, then z.
 *
 * Recordings and stereo may list a frame's points in any order (INTERFACES §1). Everything that
 * learns from points first puts them in this order, so that its result cannot depend on it.
 */
inline void sortPointsCanonically(std::span<Vec3> points_mm) {
    std::sort(points_mm.begin(), points_mm.end(), canonicallyBefore);
}

/**
 * \brief Every frame of a calibration session: its time and its 3D points (rig frame, mm), each
 * frame's points in canonical order.
 *
 * Capacity (frames, and points over all frames) is allocated once by the constructor; 60 s at
 * 100 Hz with 40 points a frame is 6,000 frames and 240,000 points, 5.8 MB. A frame that does not
 * fit is refused whole and counted: the session then ends with what it holds.
 */
class SessionBuffer {
public:
    SessionBuffer(std::size_t maxFrames, std::size_t maxPoints)
        : frameTime_s_(maxFrames)
        , frameStart_(maxFrames + 1)
        , points_rig_mm_(maxPoints) {
        frameStart_.push_back(0);
    }

    /// \brief False when it can hold no frame.
    bool isValid() const { return frameTime_s_.capacity() > 0 && points_rig_mm_.capacity() > 0; }

    /**
     * \brief Keep one frame.
     * \param time_s frame time (s), not before the last frame's.
     * \param points_rig_mm the frame's points, rig frame (mm), any order.
     * \return false (and one refused frame counted) when the frame does not fit.
     */
    bool append(double time_s, std::span<const Vec3> points_rig_mm) {
        if (frameTime_s_.full() ||
            points_rig_mm_.size() + points_rig_mm.size() > points_rig_mm_.capacity()) {
            ++framesRefused_;
            return false;
        }
        const std::size_t first = points_rig_mm_.size();
        for (const Vec3& p : points_rig_mm)
            points_rig_mm_.push_back(p);
        sortPointsCanonically(points_rig_mm_.span().subspan(first));
        frameTime_s_.push_back(time_s);
        frameStart_.push_back(points_rig_mm_.size());
        return true;
    }

    /// \brief Forget every frame (a new session).
    void clear() {
        frameTime_s_.clear();
        frameStart_.clear();
        frameStart_.push_back(0);
        points_rig_mm_.clear();
        framesRefused_ = 0;
    }

    std::size_t frames() const { return frameTime_s_.size(); }
    std::size_t points() const { return points_rig_mm_.size(); }
    std::size_t frameCapacity() const { return frameTime_s_.capacity(); }
    std::size_t pointCapacity() const { return points_rig_mm_.capacity(); }
    /// \return time (s) of frame \a frame.
    double time_s(std::size_t frame) const { return frameTime_s_[frame]; }
    /// \return frame \a frame's points, rig frame (mm), in canonical order.
    std::span<const Vec3> points(std::size_t frame) const {
        return points_rig_mm_.span().subspan(frameStart_[frame],
                                             frameStart_[frame + 1] - frameStart_[frame]);
    }
    /// \return where frame \a frame's points begin among all the session's points, in the order
    /// points() lists them: points(f)[i] is point firstPoint(f) + i of points().
    std::size_t firstPoint(std::size_t frame) const { return frameStart_[frame]; }
    /// \return frames refused since the last clear() for lack of room.
    std::uint64_t framesRefused() const { return framesRefused_; }

private:
    BoundedVector<double> frameTime_s_;
    /// Frame f's points are points_rig_mm_[frameStart_[f], frameStart_[f + 1]).
    BoundedVector<std::size_t> frameStart_;
    BoundedVector<Vec3> points_rig_mm_;
    std::uint64_t framesRefused_ = 0;
};

} // namespace edgetrack
