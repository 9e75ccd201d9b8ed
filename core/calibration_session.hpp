// One object-calibration session: online stage per frame, every frame kept, completion at the end.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "core/calibration_completion.hpp"
#include "core/object_calibrator.hpp"
#include "core/session_buffer.hpp"

namespace edgetrack {

/**
 * \brief A calibration session from its first frame to its models.
 *
 * Every frame goes to the paper's online stage (ObjectCalibrator), whose growing objects are the
 * live feedback, and into a SessionBuffer. When the session ends, complete() takes the online
 * models as seeds and completes them over every kept frame (CalibrationCompletion): these are the
 * session's models. The firmware, `edgetrack calibrate` and the tests all learn this one way.
 *
 * The constructor allocates all storage; update() allocates nothing. complete() allocates and
 * takes up to a second or two: it runs once per session, off the frame loop (the firmware runs it
 * in a worker thread while the loop goes on; the session must not be updated or reset meanwhile).
 */
class CalibrationSession {
public:
    /// \param maxFrames, maxPoints room for frames and for points over all frames (rig frame).
    CalibrationSession(const CalibrationConfig& online, const CompletionConfig& completion,
                       std::size_t maxFrames, std::size_t maxPoints);

    /// \brief False when a configuration or the room cannot work.
    bool isValid() const { return online_.isValid() && buffer_.isValid() && completion_.isValid(); }

    /// \brief Forget everything (a new session).
    void reset();

    /**
     * \brief One frame of the session.
     * \param time_s frame time (s), not before the last frame's.
     * \param points_rig_mm the frame's points, rig frame (mm), any order.
     * \return false when the buffer is full and the frame was not kept (the online stage still
     * saw it): the session should end.
     */
    bool update(double time_s, std::span<const Vec3> points_rig_mm);

    /// \brief The online stage, for live feedback (objects, members, preview models).
    const ObjectCalibrator& online() const { return online_; }
    /// \brief The frames kept so far.
    const SessionBuffer& frames() const { return buffer_; }

    /**
     * \brief The session's models: the online models completed over every kept frame, ids 0, 1,
     * ... in order of size. Allocates.
     */
    std::vector<MarkerModel> complete();

    /// \brief What the last complete() did, and how many online models it started from.
    const CompletionCounters& completionCounters() const { return completion_.counters(); }
    /// \brief Per model of the last complete() (by id): how closely the session fixed its layout.
    std::span<const LayoutPrecision> completionPrecision() const { return completion_.precision(); }
    std::span<const std::size_t> completionMostSeenTogether() const {
        return completion_.mostSeenTogether();
    }
    /// \brief Models of the last complete() (by id) that are untied pieces of one object.
    std::span<const UntiedPieces> completionUntiedPieces() const {
        return completion_.untiedPieces();
    }
    std::size_t seedsUsed() const { return seedsUsed_; }

private:
    CalibrationConfig onlineConfig_;
    CompletionConfig completionConfig_;
    ObjectCalibrator online_;
    SessionBuffer buffer_;
    CalibrationCompletion completion_;
    std::size_t seedsUsed_ = 0;
};

} // namespace edgetrack
