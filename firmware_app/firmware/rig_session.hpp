// The board's rig calibration: wand sightings collected in the frame loop, solved in a worker.
#pragma once

#include <atomic>
#include <cstddef>
#include <optional>
#include <span>
#include <string>
#include <thread>

#include "core/bounded_vector.hpp"
#include "core/rig_calibration.hpp"
#include "core/wand_finder.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "firmware_app/firmware/rig_store.hpp"

namespace edgetrack::app {

/// \brief What a rig calibration on the board came to.
struct FinishedRigCalibration {
    /// Frame pairs with the wand in both images.
    std::size_t pairs = 0;
    /// The new rig and its report; nothing when the sightings gave none (see error).
    std::optional<RigCalibrationResult> calibrated;
    std::string error;
    /// The rig in use until now, assessed on the half of the sightings the new rig was not
    /// fitted to, and the new rig's reprojection RMS there (px).
    std::optional<RigCalibrationReport> previous;
    double heldOut_px = 0.0;
    /// The new rig fits the held-out sightings better than the old one: it is taken into use
    /// (and saved); calibrated is then the rig of all the sightings.
    bool adopted = false;
    /// Whether the adopted rig reached flash.
    Status saved = Ok{};
    double took_s = 0.0;

    /// \return the new rig fits well by its own report (good coverage and agreement).
    bool good() const { return adopted && calibrated && calibrated->report.good(); }
};

/// \brief How a frame left the session.
enum class RigSessionStep { Continue, TimeUp, BufferFull };

/// \return the mean of a report's two cameras' reprojection RMS (px).
double meanReprojection_px(const RigCalibrationReport& report);

/**
 * \brief A rig calibration by wand on the board.
 *
 * While open, every frame's blobs go through a WandFinder per camera; pairs with the wand in both
 * images are kept in storage sized at construction ([rig_calibration] max_frames), so the frame
 * loop allocates nothing. finish() hands the sightings to a worker thread of lower priority,
 * which calibrates a rig on every second pair (core's calibrateRig, Ceres), compares it with the
 * rig in use on the other pairs (assessRig), and only when the new one fits them better
 * calibrates on all pairs and saves the result to \a store: a new rig always fits the sightings
 * it was made from, so only sightings it has not seen can tell whether it is better. Between
 * finish() and the result, the caller leaves the session and the store alone.
 */
class RigSession {
public:
    explicit RigSession(const RigCalibrationSettings& settings);
    ~RigSession();
    RigSession(const RigSession&) = delete;
    RigSession& operator=(const RigSession&) = delete;

    /// \return false when the wand of [rig_calibration] is not a wand.
    bool isValid() const { return finders_[0].isValid(); }

    void open(double now_s);
    bool isOpen() const { return open_; }
    /// \brief Close without solving (the cameras went down, or a long press).
    void abandon() { open_ = false; }

    /// \brief One frame: look for the wand in both cameras' blobs (raw px) with \a rig's lenses.
    RigSessionStep update(double time_s, const StereoRig& rig, std::span<const Blob> blobs0,
                          std::span<const Blob> blobs1);

    std::size_t pairs() const { return pairs_.size(); }
    double opened_s() const { return opened_s_; }
    const WandFinderCounters& finderCounters(int camera) const {
        return finders_[camera == 0 ? 0 : 1].counters();
    }

    /// \brief Close the session and solve in the worker; \a current is the rig in use.
    void finish(const StereoRig& current, RigStore& store);
    bool busy() const { return worker_.joinable(); }
    /// \return the result when the worker is done, else nothing; never waits.
    std::optional<FinishedRigCalibration> poll();
    /// \return the result, waiting for the worker (nothing when none was started).
    std::optional<FinishedRigCalibration> wait();

private:
    RigCalibrationSettings settings_;
    WandSpec wand_;
    std::array<WandFinder, 2> finders_;
    BoundedVector<WandFramePair> pairs_;
    bool open_ = false;
    double opened_s_ = 0.0;
    std::thread worker_;
    std::atomic<bool> done_{false};
    FinishedRigCalibration result_;
};

} // namespace edgetrack::app
