// Completes a field calibration's models in a lower-priority worker thread beside the frame loop.
#pragma once

#include <atomic>
#include <cstddef>
#include <optional>
#include <span>
#include <thread>
#include <vector>

#include "core/calibration_session.hpp"
#include "core/result.hpp"
#include "firmware_app/firmware/model_merge.hpp"
#include "firmware_app/firmware/model_store.hpp"
#include "firmware_app/formats/named_model.hpp"

namespace edgetrack::app {

/// \brief Give the calling (worker) thread a lower scheduling priority than the frame loop's.
void lowerThisThreadsPriority();

/// \brief What finishing a calibration produced, for the frame loop to take over.
struct FinishedCalibration {
    /// The new model set (the known models merged with the learnt ones) and what happened to
    /// each learnt model; meaningful only when learnt > 0.
    MergedModels merged;
    /// Models the completion stage produced (0: nothing learnt, the models stay as they were).
    std::size_t learnt = 0;
    /// Online models the completion started from.
    std::size_t seeds = 0;
    CompletionCounters completion{};
    /// Per learnt model: how closely the session fixed its layout (merged.learntIndex says which
    /// model of the new set each is).
    std::vector<LayoutPrecision> precision;
    /// Learnt models (by learnt index) that are pieces of one object the session did not tie.
    std::vector<UntiedPieces> untiedPieces;
    /// Per learnt model: the most of its markers one frame of the session showed.
    std::vector<std::size_t> mostSeenTogether;
    /// Whether the new set reached flash (only tried when learnt > 0).
    Status saved = Ok{};
    /// Wall time the worker took (s), completion, merge and save.
    double took_s = 0.0;
};

/**
 * \brief Finishes a calibration session off the frame loop.
 *
 * Completion (CalibrationSession::complete) takes up to a second or two and allocates, and the
 * save to flash waits for the flash; done in the frame loop they would stall it for many frames.
 * start() hands them to a worker thread with a lower scheduling priority (a higher nice value),
 * so the frame loop keeps its core and its deadline; poll() hands the result back without
 * waiting. Between start() and the result, the caller must leave the session, the known models
 * and the model store alone (the firmware neither calibrates nor saves meanwhile).
 */
class CalibrationFinisher {
public:
    CalibrationFinisher() = default;
    CalibrationFinisher(const CalibrationFinisher&) = delete;
    CalibrationFinisher& operator=(const CalibrationFinisher&) = delete;
    /// Waits for a running worker: its save to flash is never cut off.
    ~CalibrationFinisher();

    /**
     * \brief Complete \a session, tie its models to the \a known bodies it showed (\a sightings,
     * findKnownInSession with \a tracking), merge them into \a known and save the set to
     * \a store, in a worker thread.
     * \param maxModels, shape as mergeLearntModels() takes them.
     */
    void start(CalibrationSession& session, std::vector<NamedModel> known,
               std::vector<KnownSighting> sightings, const ModelTrackingConfig& tracking,
               std::size_t maxModels, const SminConfig& shape, ModelStore& store);

    /// \return true from start() until the result has been taken.
    bool busy() const { return worker_.joinable(); }

    /// \return the result when the worker is done, else nothing; never waits.
    std::optional<FinishedCalibration> poll();

    /// \return the result, waiting for the worker (nothing when none was started).
    std::optional<FinishedCalibration> wait();

private:
    std::thread worker_;
    std::atomic<bool> done_{false};
    FinishedCalibration result_;
};

} // namespace edgetrack::app
