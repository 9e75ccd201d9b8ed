// The board's frame loop: capture queue, strobe, pipeline, state machine, outputs, status.
#include "firmware_app/firmware/firmware.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <optional>

#include "core/marker_set.hpp"
#include "firmware_app/firmware/model_merge.hpp"

namespace edgetrack::app {

namespace {

/// A body lost this recently (s) still has its blobs kept first where its last pose put them: in
/// a burst of reflections, a body lost for a marker's sake is found again only if its markers'
/// blobs keep their places (any window from 0.1 to 2 s gave the same in the burst test).
constexpr double kExpectLost_s = 0.5;

/// The host's steady clock: stage times are CPU work, also on the simulated board's virtual time.
std::int64_t hostNanos() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

hal::Nanoseconds fromSeconds(double s) {
    return static_cast<hal::Nanoseconds>(std::llround(s * 1e9));
}

} // namespace

const char* stateName(FirmwareState state) {
    switch (state) {
    case FirmwareState::Tracking:
        return "tracking";
    case FirmwareState::Calibrating:
        return "calibrating";
    case FirmwareState::Finishing:
        return "finishing";
    case FirmwareState::Degraded:
        return "degraded";
    case FirmwareState::RigCalibrating:
        return "calibrating rig";
    case FirmwareState::RigFinishing:
        return "finishing rig";
    }
    return "?";
}

const char* stageName(Stage stage) {
    static constexpr const char* kNames[kStageCount] = {"blobs", "stereo", "track", "output",
                                                        "frame"};
    return kNames[static_cast<std::size_t>(stage)];
}

void StageTime::add(double us) {
    last_us = us;
    max_us = std::max(max_us, us);
    ++count;
    mean_us += (us - mean_us) / static_cast<double>(count);
}

Firmware::Firmware(const FirmwareConfig& config, hal::Board& board, const StereoRig& rig)
    : config_(config)
    , board_(board)
    , button_(fromSeconds(config.gpio.debounce_ms * 1e-3), fromSeconds(config.gpio.longPress_s),
              fromSeconds(config.gpio.doublePress_s))
    , queue_(config.cameras.queueDepth)
    , strobe_(fromSeconds(config.gpio.strobeLead_us * 1e-6),
              fromSeconds(config.gpio.strobeTail_us * 1e-6))
    , markers_(rig, config.markers)
    , store_(board.flash, MarkerSet::kCapacity)
    , calibration_(config, rig)
    , rigStore_(board.rigFlash)
    , rigSession_(config.rig)
    , outputs_(config) {
    if (!markers_.isValid())
        error_ = markers_.error();
    if (!calibration_.isValid())
        error_ = "[calibration] settings are unusable (markers per object must be 4 to " +
                 std::to_string(MarkerSet::kCapacity) + ", the session buffer not empty)";
    if (!store_.isValid())
        error_ = "the flash partition cannot hold two model slots";
    if (!rigStore_.isValid())
        error_ = "the rig's flash partition cannot hold two rig slots";
    if (!rigSession_.isValid())
        error_ = "[rig_calibration] wand: 1 to 7 positive spacings (mm)";
    tracker_.emplace(std::span<const MarkerModel>{}, config.tracking);
    if (!tracker_->isValid())
        error_ = "[tracking] settings are unusable";
    models_.reserve(config.maxModels);
}

// ---------------------------------------------------------------------------------------------
// Start, stop, models

void Firmware::start() {
    Result<StoredModels> loaded = store_.load();
    if (loaded) {
        std::vector<NamedModel> models = std::move(loaded->models);
        if (models.size() > config_.maxModels) {
            counters_.modelOverflow += models.size() - config_.maxModels;
            models.resize(config_.maxModels);
        }
        const std::size_t count = models.size();
        setModels(std::move(models));
        flashModels_ = "loaded " + std::to_string(count) + (count == 1 ? " model" : " models") +
                       " from flash slot " + (loaded->slot == 0 ? "A" : "B") + " (save #" +
                       std::to_string(loaded->sequence) + ")";
        // A damaged slot beside it may have held a later save: the user should know.
        if (!loaded->otherSlotProblem.empty())
            flashModels_ += "; " + loaded->otherSlotProblem +
                            ": a later save may be lost, calibrate again or import it";
    } else {
        setModels({});
        flashModels_ = loaded.error().message;
    }
    // The board's own rig, measured by wand, wins over the configured one.
    if (Result<StoredRig> rig = rigStore_.load(); !rig)
        flashRig_ = "configured rig (" + rig.error().message + ")";
    else if (!markers_.setRig(rig->rig))
        flashRig_ = "configured rig (the rig on flash is for another image size)";
    else
        flashRig_ = "rig from flash slot " + std::string(rig->slot == 0 ? "A" : "B") + " (save #" +
                    std::to_string(rig->sequence) + ")";
    changeState(FirmwareState::Tracking);
    if (Status s = board_.cameras.start(); !s) {
        enterDegraded(("cameras did not start: " + s.error().message).c_str());
        return;
    }
    cameras_.started = true;
    strobe_.restart(board_.ledRing);
    cameras_.lastFrameAt = board_.clock.now();
}

Firmware::~Firmware() {
    (void)calibration_.wait();
}

void Firmware::stop() {
    // A session still open is abandoned (counted so), a finishing one's models are saved before
    // the board stops: never lost.
    if (state_ == FirmwareState::Calibrating || state_ == FirmwareState::RigCalibrating)
        changeState(FirmwareState::Tracking);
    waitForFinishing();
    board_.cameras.stop();
    board_.ledRing.setContinuous(false);
    board_.statusLed.set(false);
    cameras_.started = false;
}

void Firmware::setModels(std::vector<NamedModel> models, SameFrames same) {
    std::optional<ModelTracker> previous = std::move(tracker_);
    const std::vector<NamedModel> before = std::move(models_);
    models_ = std::move(models);
    std::vector<MarkerModel> layouts;
    layouts.reserve(models_.size());
    for (const NamedModel& m : models_)
        layouts.push_back(copyOf(m.model));
    tracker_.emplace(layouts, config_.tracking);
    if (previous && same == SameFrames::ForKeptIds)
        for (std::size_t i = 0; i < models_.size(); ++i)
            for (std::size_t j = 0; j < before.size(); ++j)
                if (before[j].model.id == models_[i].model.id)
                    tracker_->continueBody(i, *previous, j);
    sightings_.assign(models_.size(), std::nullopt);
    outputs_.resetFilters();
}

Status Firmware::replaceModels(std::vector<NamedModel> models) {
    if (models.size() > config_.maxModels)
        return Error{std::to_string(models.size()) + " models; [tracking] max_models is " +
                     std::to_string(config_.maxModels)};
    waitForFinishing();
    Status saved = store_.save(models);
    if (!saved)
        ++counters_.flashErrors;
    reportModelsSaved(saved, models.size());
    setModels(std::move(models));
    return saved;
}

std::span<const TrackedBody> Firmware::bodies() const {
    if (!tracksModels())
        return {};
    return tracker_->bodies();
}

std::size_t Firmware::calibrationObjects() const {
    return calibration_.objectCount();
}

void Firmware::note(std::string event) {
    lastEvent_ = std::move(event);
}

// ---------------------------------------------------------------------------------------------
// The state machine

void Firmware::changeState(FirmwareState next) {
    if (state_ == FirmwareState::Calibrating && calibration_.isOpen()) {
        calibration_.close();
        ++counters_.calibrationsAbandoned;
    }
    if (state_ == FirmwareState::RigCalibrating && rigSession_.isOpen()) {
        rigSession_.abandon();
        ++counters_.rigCalibrationsFailed;
    }
    // Whatever was tracked before a calibration, or before the cameras went down, has moved.
    const bool trackingResumes = next == FirmwareState::Tracking ||
                                 next == FirmwareState::Finishing ||
                                 next == FirmwareState::RigFinishing;
    // The known bodies are tracked through a calibration session (findKnownInSession), so they
    // are followed on after it with their identities.
    if (trackingResumes &&
        (state_ == FirmwareState::Degraded || state_ == FirmwareState::RigCalibrating))
        tracker_->reset();
    // Where the tracked markers were expected holds only for the tracking frame that follows.
    if (next != state_)
        markers_.clearExpected();
    state_ = next;
}

void Firmware::handleButton(hal::Nanoseconds now) {
    hal::ButtonEdge edge;
    while (board_.button.nextEdge(edge))
        button_.edge(edge);
    for (ButtonEvent event = button_.poll(now); event != ButtonEvent::None;
         event = button_.poll(now)) {
        if (rigSession_.busy()) {
            note("button ignored: the rig calibration is still finishing");
            continue;
        }
        if (state_ == FirmwareState::RigCalibrating) {
            // Any press ends the wand session; a long one also deletes the models, as always.
            finishRigCalibration("the button");
            if (event == ButtonEvent::LongPress)
                deleteModels();
            continue;
        }
        if (event == ButtonEvent::DoublePress) {
            if (state_ == FirmwareState::Tracking && !calibration_.finishing())
                startRigCalibration();
            else
                note("double press ignored: the board is " + std::string(stateName(state_)));
            continue;
        }
        if (calibration_.finishing()) {
            // The worker owns the session and the flash until it is done.
            if (event == ButtonEvent::LongPress) {
                deletePending_ = true;
                note("long press: the models will be deleted once the calibration has finished");
            } else {
                note("button ignored: the last calibration is still finishing");
            }
            continue;
        }
        if (event == ButtonEvent::LongPress) {
            deleteModels();
            continue;
        }
        if (state_ == FirmwareState::Calibrating)
            finishCalibration("the button");
        else if (state_ == FirmwareState::Tracking)
            startCalibration();
        else
            note("button ignored: the cameras are down");
    }
}

void Firmware::startCalibration() {
    std::fill(sightings_.begin(), sightings_.end(), std::nullopt);
    calibration_.open(hal::toSeconds(board_.clock.now()));
    changeState(FirmwareState::Calibrating);
    ++counters_.calibrationsStarted;
    note("calibration started");
}

void Firmware::finishCalibration(const char* why) {
    char lasted[32];
    std::snprintf(lasted, sizeof lasted, " after %.1f s", last_.time_s - calibration_.opened_s());
    finishingEvent_ = std::string("calibration ended by ") + why + lasted;
    const std::size_t objects = calibration_.learntObjects();
    if (objects == 0) {
        calibration_.close();
        ++counters_.calibrationsEmpty;
        changeState(FirmwareState::Tracking);
        note(finishingEvent_ + ": no object learnt; models unchanged");
        return;
    }
    // Completion and the save run beside the frame loop; the models from before are tracked
    // until the new ones are in use.
    std::vector<KnownSighting> sightings;
    for (const std::optional<KnownSighting>& s : sightings_)
        if (s)
            sightings.push_back(*s);
    calibration_.finish(copyOf(models_), std::move(sightings), store_);
    changeState(FirmwareState::Finishing);
    note(finishingEvent_ + ": finishing " + std::to_string(objects) + " objects");
}

void Firmware::takeFinishedCalibration(FinishedCalibration finished) {
    if (state_ == FirmwareState::Finishing)
        changeState(FirmwareState::Tracking);
    last_.completion_s = finished.took_s;
    char took[48];
    std::snprintf(took, sizeof took, ", completed in %.2f s", finished.took_s);
    const std::string event = finishingEvent_ + took;
    if (deletePending_) {
        deletePending_ = false;
        if (finished.learnt > 0)
            ++(finished.saved ? counters_.calibrationsSaved : counters_.flashErrors);
        deleteModels();
        note(event + "; its models deleted by the long press meanwhile");
        return;
    }
    if (finished.learnt == 0) {
        ++counters_.calibrationsEmpty;
        note(event + ": no object learnt; models unchanged");
        return;
    }
    const MergedModels& merge = finished.merged;
    counters_.fragmentsDropped += merge.fragments;
    counters_.modelOverflow += merge.refused;
    std::string text = event + ": " + std::to_string(merge.added) + " new, " +
                       std::to_string(merge.updated) + " updated; " +
                       std::to_string(merge.models.size()) + " models (";
    // And how closely the session fixed each learnt layout: whether waving longer would help.
    std::string fixedTo;
    for (std::size_t i = 0; i < merge.models.size(); ++i) {
        text += (i ? ", " : "") + std::to_string(merge.models[i].model.markers_model_mm.size());
        const int learnt = merge.learntIndex[i];
        if (learnt < 0 || static_cast<std::size_t>(learnt) >= finished.precision.size())
            continue;
        const LayoutPrecision& p = finished.precision[static_cast<std::size_t>(learnt)];
        char one[48];
        if (p.looseModes > 0)
            std::snprintf(one, sizeof one, "body %u not fixed", merge.models[i].model.id);
        else
            std::snprintf(one, sizeof one, "body %u to %.3f mm", merge.models[i].model.id,
                          p.markerRms_mm);
        fixedTo += (fixedTo.empty() ? "" : ", ") + std::string(one);
    }
    text += " markers)";
    if (!fixedTo.empty())
        text += "; layouts fixed, RMS: " + fixedTo;
    // Pieces of one object the session could not tie: the user must show it again.
    auto idOfLearnt = [&](std::size_t learnt) -> std::optional<std::uint32_t> {
        for (std::size_t i = 0; i < merge.models.size(); ++i)
            if (merge.learntIndex[i] == static_cast<int>(learnt))
                return merge.models[i].model.id;
        return std::nullopt;
    };
    for (const UntiedPieces& pieces : finished.untiedPieces) {
        const std::optional<std::uint32_t> first = idOfLearnt(pieces.first);
        const std::optional<std::uint32_t> second = idOfLearnt(pieces.second);
        if (!first || !second)
            continue;
        ++counters_.untiedPieces;
        text += "; body " + std::to_string(*first) + " and body " + std::to_string(*second) +
                " are pieces of one object (" + std::to_string(pieces.sharedMarkers) +
                " shared markers, never tied): calibrate it again, turning it through the side "
                "between them";
    }
    for (std::size_t i = 0; i < merge.models.size(); ++i) {
        const int learnt = merge.learntIndex[i];
        if (learnt < 0 || static_cast<std::size_t>(learnt) >= finished.mostSeenTogether.size())
            continue;
        const MarkerModel& model = merge.models[i].model;
        if (const std::optional<std::string> why = seldomFindable(
                model, finished.mostSeenTogether[static_cast<std::size_t>(learnt)])) {
            ++counters_.modelsSeldomFindable;
            text += "; body " + std::to_string(model.id) + " " + *why;
        }
    }
    for (const std::uint32_t id : merge.kept)
        text += "; body " + std::to_string(id) +
                " kept as it was (its new layout would be found less often)";
    if (merge.fragments > 0)
        text += "; " + std::to_string(merge.fragments) + " fragment" +
                (merge.fragments == 1 ? "" : "s") + " of a larger body dropped";
    if (merge.refused > 0)
        text += "; " + std::to_string(merge.refused) + " refused (max_models)";
    if (finished.saved) {
        ++counters_.calibrationsSaved;
        text += ", saved to flash";
    } else {
        ++counters_.flashErrors;
        text += ", NOT saved to flash (" + finished.saved.error().message + ")";
    }
    reportModelsSaved(finished.saved, finished.merged.models.size());
    setModels(std::move(finished.merged.models), SameFrames::ForKeptIds);
    note(std::move(text));
}

void Firmware::startRigCalibration() {
    rigSession_.open(last_.time_s);
    changeState(FirmwareState::RigCalibrating);
    ++counters_.rigCalibrationsStarted;
    note("rig calibration started: wave the wand through the whole view");
}

void Firmware::finishRigCalibration(const char* why) {
    char lasted[96];
    std::snprintf(lasted, sizeof lasted, " after %.1f s, the wand in both images in %zu frames",
                  last_.time_s - rigSession_.opened_s(), rigSession_.pairs());
    rigEvent_ = std::string("rig calibration ended by ") + why + lasted;
    if (rigSession_.pairs() < RigCalibrationConfig{}.minFrames) {
        changeState(FirmwareState::Tracking); // abandons the session: counted as failed
        statusLed_.showOnce(LedPattern::RigPoor, board_.clock.now());
        note(rigEvent_ + ": too few to calibrate; rig unchanged");
        return;
    }
    // The solver runs beside the frame loop; the rig from before is used until it is done.
    rigSession_.finish(markers_.rig(), rigStore_);
    changeState(FirmwareState::RigFinishing);
    note(rigEvent_ + ": solving");
}

void Firmware::takeFinishedRig(FinishedRigCalibration finished) {
    if (state_ == FirmwareState::RigFinishing)
        changeState(restingState());
    char text[256];
    if (!finished.calibrated) {
        ++counters_.rigCalibrationsFailed;
        statusLed_.showOnce(LedPattern::RigPoor, board_.clock.now());
        note(rigEvent_ + ": " + finished.error + "; rig unchanged");
        return;
    }
    const RigCalibrationReport& report = finished.calibrated->report;
    const double before = finished.previous ? meanReprojection_px(*finished.previous) : 0.0;
    if (!finished.adopted) {
        ++counters_.rigCalibrationsKept;
        statusLed_.showOnce(LedPattern::RigPoor, board_.clock.now());
        std::snprintf(text, sizeof text,
                      ": the new rig fits the wand worse (%.3f px) than the rig in use (%.3f px), "
                      "which stays",
                      finished.heldOut_px, before);
        note(rigEvent_ + text);
        return;
    }
    const CameraModel& was = markers_.rig().camera(1);
    const CameraModel& now = finished.calibrated->rig.camera(1);
    const double turned_deg = Eigen::AngleAxisd(now.extrinsics().rotation_cam_from_rig *
                                                was.extrinsics().rotation_cam_from_rig.transpose())
                                  .angle() *
                              180.0 / 3.14159265358979323846;
    const double moved_mm = (now.centre_rig_mm() - was.centre_rig_mm()).norm();
    markers_.setRig(finished.calibrated->rig);
    ++counters_.rigCalibrationsAdopted;
    epipolar_ = EpipolarWatch{};
    statusLed_.showOnce(finished.good() ? LedPattern::RigGood : LedPattern::RigPoor,
                        board_.clock.now());
    std::snprintf(text, sizeof text,
                  ": new rig in use (reprojection %.3f px, was %.3f px; wand length RMS %.2f mm; "
                  "camera 1 moved %.2f mm, turned %.3f degrees; %s)",
                  finished.heldOut_px, before, report.lengthErrorRms_mm, moved_mm, turned_deg,
                  report.good() ? "good" : report.warnings.front().c_str());
    std::string event = rigEvent_ + text;
    if (finished.saved) {
        event += ", saved to flash";
        flashRig_ = "rig measured by wand, saved to flash";
    } else {
        flashRig_ =
            "rig measured by wand, NOT saved to flash (" + finished.saved.error().message + ")";
        ++counters_.flashErrors;
        event += ", NOT saved to flash (" + finished.saved.error().message + ")";
    }
    note(std::move(event));
}

void Firmware::waitForRigCalibration() {
    if (std::optional<FinishedRigCalibration> finished = rigSession_.wait())
        takeFinishedRig(std::move(*finished));
}

FirmwareState Firmware::restingState() const {
    if (calibration_.finishing())
        return FirmwareState::Finishing;
    if (rigSession_.busy())
        return FirmwareState::RigFinishing;
    return FirmwareState::Tracking;
}

void Firmware::watchEpipolar() {
    // Carried markers are seen by one camera only: they say nothing of the rig.
    double sum = 0.0;
    std::size_t matched = 0;
    for (const StereoMarker& m : markers_.markers()) {
        if (m.carried)
            continue;
        sum += static_cast<double>(m.epipolar_px) * static_cast<double>(m.epipolar_px);
        ++matched;
    }
    if (matched < 3)
        return;
    const double rms = std::sqrt(sum / static_cast<double>(matched));
    // An exponential average over about a hundred frames: a second at the camera rate.
    ++epipolar_.frames;
    epipolar_.rms_px =
        epipolar_.frames == 1 ? rms : epipolar_.rms_px + 0.01 * (rms - epipolar_.rms_px);
    const bool drifted = epipolar_.frames >= 100 && epipolar_.rms_px > config_.rig.driftWarning_px;
    if (drifted && !epipolar_.warned) {
        ++counters_.rigDriftWarnings;
        char text[160];
        std::snprintf(text, sizeof text,
                      "the rig seems to have drifted: matched markers are %.2f px off their "
                      "epipolar lines; a rig calibration (double press) is due",
                      epipolar_.rms_px);
        note(text);
    }
    epipolar_.warned = drifted;
}

void Firmware::waitForFinishing() {
    if (std::optional<FinishedCalibration> finished = calibration_.wait())
        takeFinishedCalibration(std::move(*finished));
}

void Firmware::reportModelsSaved(const Status& saved, std::size_t count) {
    flashModels_ =
        saved ? std::to_string(count) + (count == 1 ? " model" : " models") + " saved to flash"
              : "models NOT saved to flash (" + saved.error().message +
                    "); flash holds the set from before";
}

void Firmware::deleteModels() {
    if (state_ == FirmwareState::Calibrating)
        changeState(FirmwareState::Tracking);
    const Status saved = store_.save({});
    if (!saved)
        ++counters_.flashErrors;
    reportModelsSaved(saved, 0);
    setModels({});
    ++counters_.modelDeletions;
    statusLed_.showOnce(LedPattern::Confirm, board_.clock.now());
    note(saved ? "all models deleted (long press)"
               : "models deleted, but flash failed: " + saved.error().message);
}

void Firmware::enterDegraded(const char* why) {
    // Frames go back before the stream stops: a backend frees its buffers when it stops.
    for (Queued queued; queue_.pop(queued);)
        board_.cameras.release(queued.frame);
    board_.cameras.stop();
    cameras_.started = false;
    changeState(FirmwareState::Degraded);
    cameras_.nextRetryAt = board_.clock.now() + fromSeconds(config_.cameras.retry_s);
    board_.ledRing.setContinuous(false);
    note(std::string("degraded: ") + why + "; retrying every " +
         std::to_string(config_.cameras.retry_s).substr(0, 4) + " s");
}

void Firmware::retryCameras(hal::Nanoseconds now) {
    if (now < cameras_.nextRetryAt) {
        board_.clock.sleepUntil(std::min(cameras_.nextRetryAt, now + board_.cameras.framePeriod()));
        return;
    }
    ++counters_.cameraRestarts;
    if (Status s = board_.cameras.start(); !s) {
        cameras_.nextRetryAt = now + fromSeconds(config_.cameras.retry_s);
        return;
    }
    cameras_.started = true;
    strobe_.restart(board_.ledRing);
    cameras_.lastFrameAt = board_.clock.now();
    changeState(restingState());
    note("cameras restarted");
}

LedPattern Firmware::statePattern() const {
    switch (state_) {
    case FirmwareState::Degraded:
        return LedPattern::FastBlink;
    case FirmwareState::Calibrating:
        return LedPattern::Blink;
    case FirmwareState::Finishing:
    case FirmwareState::RigFinishing:
        return LedPattern::Finishing;
    case FirmwareState::RigCalibrating:
        return LedPattern::Wand;
    case FirmwareState::Tracking:
        break;
    }
    const std::span<const TrackedBody> tracked = tracker_->bodies();
    return std::any_of(tracked.begin(), tracked.end(),
                       [](const TrackedBody& b) { return b.found(); })
               ? LedPattern::On
               : LedPattern::Heartbeat;
}

// ---------------------------------------------------------------------------------------------
// Frame loop

void Firmware::step() {
    const hal::Nanoseconds now = board_.clock.now();
    if (calibration_.finishing())
        if (std::optional<FinishedCalibration> finished = calibration_.poll())
            takeFinishedCalibration(std::move(*finished));
    if (rigSession_.busy())
        if (std::optional<FinishedRigCalibration> finished = rigSession_.poll())
            takeFinishedRig(std::move(*finished));
    handleButton(now);
    if (state_ == FirmwareState::Degraded) {
        retryCameras(now);
        statusLed_.update(statePattern(), board_.clock.now(), board_.statusLed);
        return;
    }
    capture();
    if (Queued next; queue_.pop(next)) {
        process(next.frame, next.acquiredAt, next.acquiredHost_ns);
        board_.cameras.release(next.frame);
    }
    outputs_.drainCanErrors(board_.can);
    statusLed_.update(statePattern(), board_.clock.now(), board_.statusLed);
}

void Firmware::capture() {
    const hal::Nanoseconds period = board_.cameras.framePeriod();
    // Wait for a frame only when there is nothing to process: capture never waits on processing.
    const hal::Nanoseconds wait = queue_.empty() ? period + period / 2 : 0;
    hal::StereoFrame frame;
    hal::AcquireStatus status = board_.cameras.acquire(frame, wait);
    bool any = false;
    while (status == hal::AcquireStatus::Frame) {
        any = true;
        const hal::Nanoseconds at = board_.clock.now();
        cameras_.lastFrameAt = at;
        counters_.strobePulsesRefused += strobe_.schedule(frame, period, board_.ledRing);
        enqueue(Queued{frame, at, hostNanos()});
        status = board_.cameras.acquire(frame, 0);
    }
    if (status == hal::AcquireStatus::Failed) {
        ++counters_.cameraFailures;
        enterDegraded("a camera failed");
    } else if (status == hal::AcquireStatus::Stopped) {
        enterDegraded("the cameras stopped");
    } else if (!any && wait > 0) {
        ++counters_.cameraTimeouts;
        if (board_.clock.now() - cameras_.lastFrameAt > fromSeconds(config_.cameras.timeout_s))
            enterDegraded("no frames from the cameras");
    }
}

void Firmware::enqueue(const Queued& queued) {
    // Drop the oldest: the newest exposure is the one worth processing. Its buffers go back to
    // the cameras first.
    if (Queued oldest; queue_.full() && queue_.pop(oldest)) {
        board_.cameras.release(oldest.frame);
        ++counters_.framesDroppedQueue;
    }
    if (!queue_.tryPush(queued)) // a queue of depth 0: the frame is dropped at once
        board_.cameras.release(queued.frame);
}

void Firmware::process(const hal::StereoFrame& frame, hal::Nanoseconds acquiredAt,
                       std::int64_t acquiredHost_ns) {
    const std::int64_t t0 = hostNanos();
    for (std::size_t c = 0; c < 2; ++c)
        if (frame.camera[c].width_px != markers_.width_px() ||
            frame.camera[c].height_px != markers_.height_px() ||
            frame.camera[c].stride_bytes < markers_.width_px() ||
            frame.camera[c].pixels == nullptr) {
            ++counters_.framesWrongSize;
            return;
        }
    for (int c = 0; c < 2; ++c)
        markers_.detectBlobs(c, frame.camera[static_cast<std::size_t>(c)].pixels,
                             frame.camera[static_cast<std::size_t>(c)].stride_bytes);
    const std::int64_t t1 = hostNanos();
    markers_.matchStereo(StereoMethod::Svd,
                         {{{frame.camera[0].pixels, frame.camera[0].stride_bytes},
                           {frame.camera[1].pixels, frame.camera[1].stride_bytes}}});
    const std::int64_t t2 = hostNanos();

    last_.number = frame.number;
    last_.time_s = hal::toSeconds(frame.midExposure());
    if (state_ == FirmwareState::Calibrating) {
        // The known bodies are followed beside the session: where each was last found tells
        // which learnt model it is (its id and frame stay), and keeps identical objects apart.
        tracker_->update(last_.time_s, markers_.points_rig_mm());
        const std::span<const TrackedBody> tracked = tracker_->bodies();
        for (std::size_t b = 0; b < tracked.size() && b < sightings_.size(); ++b)
            if (tracked[b].found())
                sightings_[b] = KnownSighting{b, last_.time_s, tracked[b].T_rig_from_model};
        const SessionStep step = calibration_.update(last_.time_s, markers_.points_rig_mm());
        if (step == SessionStep::BufferFull)
            ++counters_.sessionFramesRefused;
        if (step != SessionStep::Continue)
            finishCalibration(endReason(step));
    } else if (state_ == FirmwareState::RigCalibrating) {
        const RigSessionStep step = rigSession_.update(
            last_.time_s, markers_.rig(), markers_.blobs(0).span(), markers_.blobs(1).span());
        if (step != RigSessionStep::Continue)
            finishRigCalibration(step == RigSessionStep::TimeUp ? "its duration" : "a full buffer");
    } else {
        watchEpipolar();
        tracker_->update(last_.time_s, markers_.points_rig_mm());
        expectTrackedMarkers();
        outputs_.updatePoses(last_.time_s, tracker_->bodies());
    }
    const std::int64_t t3 = hostNanos();
    sendOutputs(frame, acquiredAt, acquiredHost_ns);
    const std::int64_t t4 = hostNanos();

    const std::int64_t stageEnds[kStageCount] = {t1, t2, t3, t4, t4};
    const std::int64_t stageStarts[kStageCount] = {t0, t1, t2, t3, t0};
    for (std::size_t s = 0; s < kStageCount; ++s)
        stageTimes_[s].add(static_cast<double>(stageEnds[s] - stageStarts[s]) * 1e-3);
    const hal::Nanoseconds budget = config_.health.frameBudget_ms > 0.0
                                        ? fromSeconds(config_.health.frameBudget_ms * 1e-3)
                                        : board_.cameras.framePeriod();
    if (t4 - t0 > budget)
        ++counters_.framesOverBudget;

    const MarkerPipelineCounters refused = markers_.counters();
    counters_.blobOverflow = refused.blobOverflow;
    counters_.blobsSplit = refused.splitBlobs;
    counters_.blobsNotSplit = refused.splitRefused;
    counters_.blobsCut = refused.cutDiscs;
    counters_.blobsOneEllipse = refused.ellipses;
    counters_.blobsSplitOnLines = refused.splitOnLines;
    counters_.splitsOnLinesSkipped = refused.splitAttemptsSkipped;
    counters_.stereoPairsForContinuity = refused.pairsForContinuity;
    counters_.markersCarried = refused.carriedMarkers;
    counters_.markersFoundWhereExpected = refused.markersSplitWhereExpected;
    counters_.labelOverflow = refused.labelOverflow;
    counters_.markerOverflow = refused.markerOverflow;
    ++counters_.framesProcessed;
}

void Firmware::expectTrackedMarkers() {
    // Every marker of a found body where its pose puts it now, and of one lost for under
    // kExpectLost_s where it last was: next frame, a burst of reflections then costs stray blobs,
    // not the tracked markers' (the found and the briefly hidden alike).
    markers_.clearExpected();
    const std::span<const TrackedBody> tracked = tracker_->bodies();
    for (std::size_t b = 0; b < tracked.size() && b < models_.size(); ++b)
        if (tracked[b].found() || last_.time_s - tracked[b].lastFound_s <= kExpectLost_s)
            for (const Vec3& m : models_[b].model.markers_model_mm)
                markers_.expect(tracked[b].T_rig_from_model.apply(m));
}

void Firmware::sendOutputs(const hal::StereoFrame& frame, hal::Nanoseconds acquiredAt,
                           std::int64_t acquiredHost_ns) {
    // Time on the board's clock until the frame was in hand, then the host's time spent on it:
    // on the real board both are CLOCK_MONOTONIC; the simulated board's clock is virtual.
    last_.latency_s = hal::toSeconds(acquiredAt - frame.midExposure()) +
                      static_cast<double>(hostNanos() - acquiredHost_ns) * 1e-9;
    if (state_ == FirmwareState::Calibrating)
        outputs_.preview(last_.time_s, calibration_.online());
    else
        outputs_.clearPreview();
    OutputFrame out;
    out.number = frame.number;
    out.midExposureUtc_ns = frame.midExposure() + board_.clock.utcOffset();
    out.latency_s = last_.latency_s;
    out.calibrated = dtrackCalibratedCount(models_);
    out.bodies = bodies();
    outputs_.send(out, board_.udp, board_.can);
}

// ---------------------------------------------------------------------------------------------
// Status view

std::string Firmware::statusLine() const {
    std::size_t found = 0;
    for (const TrackedBody& b : bodies())
        found += b.found() ? 1u : 0u;
    char line[256];
    const StageTime& frame = stageTime(Stage::Frame);
    if (state_ == FirmwareState::Calibrating)
        std::snprintf(line, sizeof line, "%s: frame %llu, %zu objects", stateName(state_),
                      static_cast<unsigned long long>(last_.number), calibrationObjects());
    else if (state_ == FirmwareState::RigCalibrating)
        std::snprintf(line, sizeof line, "%s: frame %llu, the wand in both images in %zu frames",
                      stateName(state_), static_cast<unsigned long long>(last_.number),
                      rigSession_.pairs());
    else
        std::snprintf(line, sizeof line, "%s: frame %llu, %zu of %zu bodies", stateName(state_),
                      static_cast<unsigned long long>(last_.number), found, models_.size());
    std::string text = line;
    std::snprintf(line, sizeof line,
                  "; frame %.2f ms (max %.2f), latency %.2f ms; dropped %llu, over budget %llu; "
                  "udp %llu sent, can %llu sent",
                  frame.mean_us * 1e-3, frame.max_us * 1e-3, last_.latency_s * 1e3,
                  static_cast<unsigned long long>(counters_.framesDroppedQueue +
                                                  board_.cameras.counters().droppedUnpaired +
                                                  board_.cameras.counters().droppedNoBuffer),
                  static_cast<unsigned long long>(counters_.framesOverBudget),
                  static_cast<unsigned long long>(outputs_.counters().udpSent),
                  static_cast<unsigned long long>(outputs_.counters().canSent));
    return text + line;
}

std::string Firmware::statusReport() const {
    std::string out = "state " + std::string(stateName(state_)) + ", " +
                      std::to_string(models_.size()) + " models\n";
    out += "flash: " + flashReport() + "\n";
    if (!lastEvent_.empty())
        out += "last event: " + lastEvent_ + "\n";
    char line[160];
    out += "stage      last_us    mean_us     max_us\n";
    for (std::size_t s = 0; s < kStageCount; ++s) {
        const StageTime& t = stageTimes_[s];
        std::snprintf(line, sizeof line, "%-8s %9.1f %10.1f %10.1f\n",
                      stageName(static_cast<Stage>(s)), t.last_us, t.mean_us, t.max_us);
        out += line;
    }
    const hal::CameraPairCounters cam = board_.cameras.counters();
    auto row = [&](const char* name, std::uint64_t value) {
        std::snprintf(line, sizeof line, "%-34s %llu\n", name,
                      static_cast<unsigned long long>(value));
        out += line;
    };
    const FirmwareCounters& c = counters_;
    row("frames delivered by the cameras", cam.delivered);
    row("frames processed", c.framesProcessed);
    row("frames dropped: unpaired", cam.droppedUnpaired);
    row("frames dropped: no free buffer", cam.droppedNoBuffer);
    row("frames dropped: queue full", c.framesDroppedQueue);
    row("frames dropped: wrong size", c.framesWrongSize);
    row("frames over budget", c.framesOverBudget);
    row("camera timeouts", c.cameraTimeouts);
    row("camera failures", c.cameraFailures + cam.failures);
    row("camera restarts", c.cameraRestarts);
    row("strobe pulses refused", c.strobePulsesRefused + board_.ledRing.droppedPulses());
    row("blobs refused (capacity)", c.blobOverflow);
    row("blobs of touching markers split", c.blobsSplit);
    row("blobs not round, not split", c.blobsNotSplit);
    row("blobs one ellipse (one marker off the axis or at a slant)", c.blobsOneEllipse);
    row("discs cut by an edge, centred by their arc", c.blobsCut);
    row("blobs split on the other camera's lines", c.blobsSplitOnLines);
    row("splits on lines not tried (frame budget)", c.splitsOnLinesSkipped);
    row("stereo pairs changed to continue a marker", c.stereoPairsForContinuity);
    row("markers carried while hidden in one image", c.markersCarried);
    row("markers found where expected", c.markersFoundWhereExpected);
    row("blob labels refused (capacity)", c.labelOverflow);
    row("markers refused (capacity)", c.markerOverflow);
    const ModelTrackingCounters& t = tracker_->counters();
    row("tracking: points refused", t.pointOverflow);
    row("tracking: frames out of budget", t.budgetExhausted);
    row("tracking: poses refused (markers on one line)", t.degeneratePoses);
    const OutputCounters& o = outputs_.counters();
    row("udp sent", o.udpSent);
    row("udp failed", o.udpFailed);
    row("udp frames too large", o.udpTooLarge);
    row("can sent", o.canSent);
    row("can dropped (queue full)", o.canDropped);
    row("can refused (bus-off, down)", o.canRefused);
    row("can error events", o.canErrors);
    row("can bodies beyond the layout", o.canBodiesBeyondLayout);
    row("calibrations started", c.calibrationsStarted);
    row("calibrations saved", c.calibrationsSaved);
    row("calibrations with no object", c.calibrationsEmpty);
    row("calibrations abandoned", c.calibrationsAbandoned);
    row("calibration frames refused (buffer)", c.sessionFramesRefused);
    std::snprintf(line, sizeof line, "%-34s %.2f\n", "last calibration completed in (s)",
                  last_.completion_s);
    out += line;
    row("models refused (max_models)", c.modelOverflow);
    row("learnt fragments dropped", c.fragmentsDropped);
    row("learnt pieces of one object untied", c.untiedPieces);
    row("learnt models seldom findable (S_min)", c.modelsSeldomFindable);
    row("model deletions", c.modelDeletions);
    row("rig calibrations started", c.rigCalibrationsStarted);
    row("rig calibrations adopted", c.rigCalibrationsAdopted);
    row("rig calibrations kept the old rig", c.rigCalibrationsKept);
    row("rig calibrations without a rig", c.rigCalibrationsFailed);
    row("rig drift warnings", c.rigDriftWarnings);
    std::snprintf(line, sizeof line, "%-34s %.3f (warns above %.2f)\n",
                  "epipolar RMS of markers (px)", epipolar_.rms_px, config_.rig.driftWarning_px);
    out += line;
    row("flash errors", c.flashErrors);
    return out;
}

} // namespace edgetrack::app
