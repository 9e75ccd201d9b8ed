// A field calibration on the board: the session, when it ends on its own, and its finishing.
#pragma once

#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/calibration_session.hpp"
#include "core/stereo_rig.hpp"
#include "firmware_app/firmware/calibration_finisher.hpp"
#include "firmware_app/firmware/firmware_config.hpp"

namespace edgetrack::app {

/// \brief What a calibration frame decided.
enum class SessionStep : std::uint8_t {
    Continue,
    /// The session buffer had no room for the frame: the session ends there.
    BufferFull,
    /// max_duration_s has passed.
    TimeLimit,
    /// The learnt objects and their markers have not changed for settle_s.
    Settled,
};

/// \return why a session ended, for the event line ("its time limit").
const char* endReason(SessionStep step);

/**
 * \brief One field calibration at a time: open() starts a session, update() feeds it each frame
 * and says when it should end, finish() completes and saves its models in a worker thread.
 *
 * The session buffer (max_duration_s of frames) is allocated by the constructor. Between
 * finish() and the worker's result (poll(), wait()), the session is the worker's.
 */
class FieldCalibration {
public:
    FieldCalibration(const FirmwareConfig& config, const StereoRig& rig);

    bool isValid() const { return session_.isValid(); }

    /// \brief Start a new session at \a now_s (s, the board's clock).
    void open(double now_s);
    /// \return true from open() until close() or finish().
    bool isOpen() const { return open_; }
    /// \brief End the session without finishing it (nothing learnt, or abandoned).
    void close() { open_ = false; }

    /// \brief Feed one frame's markers (rig frame, mm) taken at \a time_s.
    SessionStep update(double time_s, std::span<const Vec3> points_rig_mm);

    /// \return the online objects with at least min_model_markers established markers: what the
    /// session would finish with now.
    std::size_t learntObjects();
    /// \return the online objects, learnt or not (the status line's count).
    std::size_t objectCount() const { return open_ ? session_.online().objectCount() : 0; }
    const ObjectCalibrator& online() const { return session_.online(); }
    /// \return when the session was opened (s).
    double opened_s() const { return opened_s_; }

    /**
     * \brief Close the session and complete its models, merge them into \a known (the bodies
     * the board found during the session, \a sightings, keep their ids and frames) and save the
     * set to \a store, in a worker thread of lower priority.
     */
    void finish(std::vector<NamedModel> known, std::vector<KnownSighting> sightings,
                ModelStore& store);
    /// \return true while the worker has not handed its result over.
    bool finishing() const { return finisher_.busy(); }
    std::optional<FinishedCalibration> poll() { return finisher_.poll(); }
    std::optional<FinishedCalibration> wait() { return finisher_.wait(); }

private:
    struct Learnt {
        std::size_t objects = 0;
        std::size_t markers = 0;
        bool operator==(const Learnt&) const = default;
    };
    Learnt learnt();

    CalibrationSessionSettings settings_;
    std::size_t maxModels_;
    ModelTrackingConfig tracking_;
    CalibrationConfig online_;
    CalibrationSession session_;
    CalibrationFinisher finisher_;
    std::vector<CalibrationObjectView> views_;
    bool open_ = false;
    double opened_s_ = 0.0;
    /// When the learnt objects or their markers last changed (s), and what they were.
    double changed_s_ = 0.0;
    Learnt learnt_{};
};

} // namespace edgetrack::app
