// The board's firmware: the frame loop and state machine (tracking, calibrating, degraded).
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/marker_pipeline.hpp"
#include "core/model_tracker.hpp"
#include "core/ring_buffer.hpp"
#include "firmware_app/firmware/button_input.hpp"
#include "firmware_app/firmware/field_calibration.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "firmware_app/firmware/model_store.hpp"
#include "firmware_app/firmware/pose_outputs.hpp"
#include "firmware_app/firmware/rig_session.hpp"
#include "firmware_app/firmware/rig_store.hpp"
#include "firmware_app/firmware/status_pattern.hpp"
#include "firmware_app/firmware/strobe_scheduler.hpp"
#include "hal/hal.hpp"

namespace edgetrack::app {

enum class FirmwareState : std::uint8_t {
    /// Models are tracked and poses sent (with no models, empty frames are sent).
    Tracking,
    /// A field calibration is learning objects; their growing models are sent as markers.
    Calibrating,
    /// A calibration has ended and its models are being completed and saved in a worker thread;
    /// meanwhile the models from before are tracked and sent as in Tracking.
    Finishing,
    /// The cameras are gone: nothing is sent and the cameras are restarted every retry_s.
    Degraded,
    /// A rig calibration (double press) collects sightings of the wand; nothing is tracked.
    RigCalibrating,
    /// The rig calibration is solved in a worker thread; the models are tracked meanwhile with
    /// the rig from before, as in Tracking.
    RigFinishing,
};

const char* stateName(FirmwareState state);

/// \brief The stages of one frame whose run time the status view shows.
enum class Stage : std::uint8_t { Blobs, Stereo, Track, Output, Frame };
inline constexpr std::size_t kStageCount = 5;
const char* stageName(Stage stage);

/// \brief Run time of one stage (microseconds of the host's steady clock): last, mean, max.
struct StageTime {
    double last_us = 0.0;
    double mean_us = 0.0;
    double max_us = 0.0;
    std::uint64_t count = 0;

    void add(double us);
};

/// \brief Counters of the frame loop, for the status view (PX4's perf counters).
struct FirmwareCounters {
    std::uint64_t framesProcessed = 0;
    /// Frames dropped from the full capture queue (the oldest goes) because processing lagged.
    std::uint64_t framesDroppedQueue = 0;
    /// Frames whose processing took longer than the frame budget.
    std::uint64_t framesOverBudget = 0;
    /// Frames of a size other than the rig's; dropped.
    std::uint64_t framesWrongSize = 0;
    std::uint64_t cameraTimeouts = 0;
    std::uint64_t cameraFailures = 0;
    std::uint64_t cameraRestarts = 0;
    std::uint64_t strobePulsesRefused = 0;
    /// Blob detection and stereo: what did not fit their capacities.
    std::uint64_t blobOverflow = 0;
    std::uint64_t labelOverflow = 0;
    std::uint64_t markerOverflow = 0;
    /// Blobs of touching markers split into their discs, and those that could not be.
    std::uint64_t blobsSplit = 0;
    std::uint64_t blobsNotSplit = 0;
    /// Discs cut by an edge in front of them, centred by their visible arc.
    std::uint64_t blobsCut = 0;
    /// Blobs not round kept whole: one marker's image, an ellipse (off the axis, at a slant).
    std::uint64_t blobsOneEllipse = 0;
    /// Blobs split by stereo on the epipolar lines of the other camera's blobs, and splits not
    /// tried for want of a frame's budget.
    std::uint64_t blobsSplitOnLines = 0;
    std::uint64_t splitsOnLinesSkipped = 0;
    /// Stereo pairs given up for another partner whose point continues a marker of the frame
    /// before.
    std::uint64_t stereoPairsForContinuity = 0;
    /// Markers carried while hidden in one image inside another marker's blob (marker-frames).
    std::uint64_t markersCarried = 0;
    /// Markers found again in a blob of several discs where they were expected.
    std::uint64_t markersFoundWhereExpected = 0;
    std::uint64_t calibrationsStarted = 0;
    std::uint64_t calibrationsSaved = 0;
    std::uint64_t calibrationsEmpty = 0;
    std::uint64_t calibrationsAbandoned = 0;
    /// Calibration frames the session buffer had no room for (the session then ends).
    std::uint64_t sessionFramesRefused = 0;
    /// Learnt models that did not fit max_models.
    std::uint64_t modelOverflow = 0;
    /// Learnt objects whose layout is part of a body with more than twice their markers.
    std::uint64_t fragmentsDropped = 0;
    /// Pairs of learnt models that are pieces of one object nothing in the session tied.
    std::uint64_t untiedPieces = 0;
    /// Learnt models that need more markers in view to be found (S_min) than their session
    /// ever showed at once: seldom or never found.
    std::uint64_t modelsSeldomFindable = 0;
    std::uint64_t modelDeletions = 0;
    std::uint64_t flashErrors = 0;
    std::uint64_t rigCalibrationsStarted = 0;
    /// New rigs taken into use (they fit the wand better than the rig before).
    std::uint64_t rigCalibrationsAdopted = 0;
    /// New rigs that fitted worse than the one in use, which stayed.
    std::uint64_t rigCalibrationsKept = 0;
    /// Sessions that gave no rig: too few wand frames, no pose that fits, abandoned.
    std::uint64_t rigCalibrationsFailed = 0;
    /// Times the epipolar error of matched markers rose above [rig_calibration] drift_warning_px.
    std::uint64_t rigDriftWarnings = 0;
};

/**
 * \brief The firmware on one board: owns every stage's storage and runs the frame loop.
 *
 * The constructor allocates everything a frame needs from the configuration (buffers, blob and
 * marker capacities, calibration session and its frame buffer, queues); step() then allocates
 * nothing while tracking or calibrating. Loading and saving models (start-up, a long press)
 * allocates: those are state changes, not frames. A calibration's end (completion, merge, save)
 * runs in a CalibrationFinisher's worker thread while step() goes on tracking.
 *
 * One step() handles the button, waits for the next paired frame (at most a frame period and a
 * bit), drains any other completed frames into the capture queue (dropping the oldest when it is
 * full, so capture never waits for processing), schedules the LED strobe for the coming
 * exposures, processes the oldest queued frame (blobs, stereo, tracking or calibration, outputs)
 * and updates the status LED.
 */
class Firmware {
public:
    /// \param rig the stereo calibration of \a board's cameras.
    Firmware(const FirmwareConfig& config, hal::Board& board, const StereoRig& rig);
    /// Waits for a finishing calibration's worker, which uses the session and the model store.
    ~Firmware();
    Firmware(const Firmware&) = delete;
    Firmware& operator=(const Firmware&) = delete;

    /// \return false when the configuration cannot run (see error()).
    bool isValid() const { return error_.empty(); }
    const std::string& error() const { return error_; }

    /// \brief Load the models from flash (with none when both slots are bad; see flashReport())
    /// and start the cameras (degraded, and retried, when they do not start).
    void start();
    /// \brief One turn of the loop (see the class description).
    void step();
    void stop();

    /// \brief Replace the model set (e.g. from `--models DIR`) and keep it on flash.
    Status replaceModels(std::vector<NamedModel> models);

    FirmwareState state() const { return state_; }
    /// \return true once cameras, flash and outputs are up: when systemd may be told READY=1.
    bool ready() const { return cameras_.started && state_ != FirmwareState::Degraded; }
    std::span<const NamedModel> models() const { return models_; }
    /// \return the bodies after the last processed frame (empty while calibrating).
    std::span<const TrackedBody> bodies() const;
    /// \return how many objects the running calibration holds (0 when not calibrating).
    std::size_t calibrationObjects() const;
    /// \brief Wait until a finishing calibration's models are in use (tests; shutting down).
    void waitForFinishing();
    const FirmwareCounters& counters() const { return counters_; }
    const StageTime& stageTime(Stage stage) const {
        return stageTimes_[static_cast<std::size_t>(stage)];
    }
    /// \return frame number of the last processed frame.
    std::uint64_t lastFrame() const { return last_.number; }
    /// \return mid-exposure of the last processed frame (s, the board's clock).
    double lastFrameTime_s() const { return last_.time_s; }
    /// \return the rig in use: from the configuration, from flash, or from a rig calibration.
    const StereoRig& rig() const { return markers_.rig(); }
    /// \return the running RMS of matched markers' epipolar errors (rectified px), about the
    /// last second of tracking: it grows when the cameras have moved against each other.
    double epipolarRms_px() const { return epipolar_.rms_px; }
    /// \brief Wait until a rig calibration's worker is done and its rig in use (tests).
    void waitForRigCalibration();
    /// \return the marker front end: the last processed frame's blobs and 3D markers.
    const MarkerPipeline& markerPipeline() const { return markers_; }
    /// \return latency of the last processed frame, mid-exposure to send (s).
    double lastLatency_s() const { return last_.latency_s; }
    const OutputCounters& outputCounters() const { return outputs_.counters(); }
    /// \return what is on flash, as start-up found it or the last save left it, and the last
    /// event worth telling (one line each).
    std::string flashReport() const { return flashModels_ + "; " + flashRig_; }
    const std::string& lastEvent() const { return lastEvent_; }

    /// \brief One status line for the console: state, frame, bodies, stage times, drops.
    std::string statusLine() const;
    /// \brief Every counter and stage time, one per line (`edgetrack status`).
    std::string statusReport() const;

private:
    /// The one place the state changes; a calibration left while its session is still open
    /// (neither finished nor ended with nothing learnt) is counted as abandoned.
    void changeState(FirmwareState next);
    void handleButton(hal::Nanoseconds now);
    void startCalibration();
    void finishCalibration(const char* why);
    void takeFinishedCalibration(FinishedCalibration finished);
    void startRigCalibration();
    void finishRigCalibration(const char* why);
    void takeFinishedRig(FinishedRigCalibration finished);
    /// The state to be in when nothing is being calibrated in the frame loop: Finishing or
    /// RigFinishing while a worker runs, else Tracking.
    FirmwareState restingState() const;
    /// Follow the epipolar error of the frame's matched markers (the rig's self-check).
    void watchEpipolar();
    /// Tracking or a worker finishing: the known models are tracked and sent.
    bool tracksModels() const {
        return state_ == FirmwareState::Tracking || state_ == FirmwareState::Finishing ||
               state_ == FirmwareState::RigFinishing;
    }
    void deleteModels();
    /// What flashReport() says of the models after a save of \a count models that gave \a saved.
    void reportModelsSaved(const Status& saved, std::size_t count);
    /// How a new model set relates to the one in use: a set merged by a calibration keeps each
    /// remaining body's frame (a relearnt layout is registered onto the old one), a set from
    /// outside (files, deletion) may put another layout under an id.
    enum class SameFrames : bool { No, ForKeptIds };
    /// \brief Track \a models from the next frame; with SameFrames::ForKeptIds each body whose
    /// id stays is followed on from where it was, so identical objects keep their ids.
    void setModels(std::vector<NamedModel> models, SameFrames same = SameFrames::No);

    struct Queued;
    void capture();
    void enqueue(const Queued& queued);
    void process(const hal::StereoFrame& frame, hal::Nanoseconds acquiredAt,
                 std::int64_t acquiredHost_ns);
    /// Tell the front end where the found bodies' markers are, to keep their blobs first.
    void expectTrackedMarkers();
    void sendOutputs(const hal::StereoFrame& frame, hal::Nanoseconds acquiredAt,
                     std::int64_t acquiredHost_ns);
    void enterDegraded(const char* why);
    void retryCameras(hal::Nanoseconds now);
    LedPattern statePattern() const;
    void note(std::string event);

    // Every member below is one job of the board (a pipeline stage, a device, a piece of state):
    // about twenty, each a class with its own storage.
    FirmwareConfig config_;
    hal::Board& board_;
    std::string error_;
    FirmwareState state_ = FirmwareState::Tracking;
    ButtonInput button_;

    // Frames: the capture queue (taken from the cameras, not yet processed, oldest first), the
    // strobe, the cameras' health, the marker front end.
    struct Queued {
        hal::StereoFrame frame;
        hal::Nanoseconds acquiredAt = 0;
        std::int64_t acquiredHost_ns = 0;
    };
    RingBuffer<Queued> queue_{0};
    StrobeScheduler strobe_;
    struct CameraHealth {
        bool started = false;
        hal::Nanoseconds lastFrameAt = 0;
        hal::Nanoseconds nextRetryAt = 0;
    } cameras_;
    MarkerPipeline markers_;

    // Models: the set in use, on flash, tracked; a field calibration.
    std::vector<NamedModel> models_;
    ModelStore store_;
    std::optional<ModelTracker> tracker_;
    FieldCalibration calibration_;
    /// Per model: where the body was last found while the calibration session ran (sized with
    /// the models, so filling it allocates nothing).
    std::vector<std::optional<KnownSighting>> sightings_;
    /// Finishing: "calibration ended by ... after ... s", and a long press waiting for the end.
    std::string finishingEvent_;
    bool deletePending_ = false;

    // The rig: its store on flash, a rig calibration by wand, and the epipolar self-check.
    RigStore rigStore_;
    RigSession rigSession_;
    std::string rigEvent_;
    struct EpipolarWatch {
        double rms_px = 0.0;
        std::uint64_t frames = 0;
        bool warned = false;
    } epipolar_;

    PoseOutputs outputs_;
    StatusLedDriver statusLed_;

    // Status view.
    struct LastFrame {
        std::uint64_t number = 0;
        /// Mid-exposure (s, the board's clock).
        double time_s = 0.0;
        /// Mid-exposure to sending (s).
        double latency_s = 0.0;
        /// How long the last calibration's completion took (s).
        double completion_s = 0.0;
    } last_;
    FirmwareCounters counters_{};
    std::array<StageTime, kStageCount> stageTimes_{};
    /// The models' and the rig's part of flashReport().
    std::string flashModels_;
    std::string flashRig_;
    std::string lastEvent_;
};

} // namespace edgetrack::app
