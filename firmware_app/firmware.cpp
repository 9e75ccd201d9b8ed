// The board's frame loop: capture queue, strobe, pipeline, state machine, outputs, status.
#include "firmware_app/firmware.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "core/marker_set.hpp"
#include "firmware_app/model_merge.hpp"
#include "firmware_app/output/can_pose.hpp"

namespace edgetrack::app {

namespace {

/// The host's steady clock: stage times are CPU work, also on the simulated board's virtual time.
std::int64_t hostNanos() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}

hal::Nanoseconds fromSeconds(double s) {
    return static_cast<hal::Nanoseconds>(std::llround(s * 1e9));
}

/// Strobe pulses are scheduled this many exposures ahead of the last delivered one: a frame whose
/// processing stalls the loop for up to this many periods still leaves every exposure lit.
constexpr int kStrobeAhead = 4;
/// The ring stays lit continuously for the first frames, until pulses cover the exposures.
constexpr std::uint64_t kContinuousFrames = 2;
/// Markers in one calibration preview (`3d` line); the datagram buffer holds them.
constexpr std::size_t kMaxPreviewMarkers = 128;
constexpr std::size_t kDatagramBytes = 8192;

/// The completion stage as the board runs it: the calibration's own capacities and S_min, markers
/// seen from between the two cameras.
/// Frames a session can last: its longest duration at the camera rate, and a margin for jitter.
std::size_t sessionFrames(const FirmwareConfig& config) {
    return static_cast<std::size_t>(
               std::ceil(config.session.maxDuration_s * config.cameras.frameRate_hz * 1.05)) +
           16;
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
    , markers_(rig, config.markers)
    , calibration_(config.calibration, completionFor(config, &rig), sessionFrames(config),
                   sessionFrames(config) * config.session.bufferPointsPerFrame)
    , store_(board.flash, MarkerSet::kCapacity)
    , button_(fromSeconds(config.gpio.debounce_ms * 1e-3), fromSeconds(config.gpio.longPress_s)) {
    if (!markers_.isValid())
        error_ = markers_.error();
    if (!calibration_.isValid())
        error_ = "[calibration] settings are unusable (markers per object must be 4 to " +
                 std::to_string(MarkerSet::kCapacity) + ", the session buffer not empty)";
    if (!store_.isValid())
        error_ = "the flash partition cannot hold two model slots";
    tracker_.emplace(std::span<const MarkerModel>{}, config.tracking);
    if (!tracker_->isValid())
        error_ = "[tracking] settings are unusable";

    objectViews_.resize(config.calibration.maxObjects);
    models_.reserve(config.maxModels);
    filters_.assign(config.maxModels, PoseFilter(config.filter));
    outputPoses_.resize(config.maxModels);
    queue_ = RingBuffer<Queued>(config.cameras.queueDepth);
    dtrackBodies_.reserve(config.maxModels);
    dtrackMarkers_.reserve(kMaxPreviewMarkers);
    datagram_.resize(kDatagramBytes);
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
        flashReport_ = "loaded " + std::to_string(count) + (count == 1 ? " model" : " models") +
                       " from flash slot " + (loaded->slot == 0 ? "A" : "B") + " (save #" +
                       std::to_string(loaded->sequence) + ")";
    } else {
        setModels({});
        flashReport_ = loaded.error().message;
    }
    state_ = FirmwareState::Tracking;
    if (Status s = board_.cameras.start(); !s) {
        enterDegraded(("cameras did not start: " + s.error().message).c_str());
        return;
    }
    cameraStarted_ = true;
    strobing_ = false;
    board_.ledRing.setContinuous(true);
    lastFrameAt_ = board_.clock.now();
}

Firmware::~Firmware() {
    (void)finisher_.wait();
}

void Firmware::stop() {
    // A finishing calibration's models are saved before the board stops: never lost.
    waitForFinishing();
    board_.cameras.stop();
    board_.ledRing.setContinuous(false);
    board_.statusLed.set(false);
    cameraStarted_ = false;
}

void Firmware::setModels(std::vector<NamedModel> models) {
    models_ = std::move(models);
    std::vector<MarkerModel> layouts;
    layouts.reserve(models_.size());
    for (const NamedModel& m : models_)
        layouts.push_back(copyOf(m.model));
    tracker_.emplace(layouts, config_.tracking);
    for (PoseFilter& f : filters_)
        f.reset();
}

Status Firmware::replaceModels(std::vector<NamedModel> models) {
    if (models.size() > config_.maxModels)
        return Error{std::to_string(models.size()) + " models; [tracking] max_models is " +
                     std::to_string(config_.maxModels)};
    waitForFinishing();
    Status saved = store_.save(models);
    if (!saved)
        ++counters_.flashErrors;
    setModels(std::move(models));
    return saved;
}

std::span<const TrackedBody> Firmware::bodies() const {
    if (!tracksModels())
        return {};
    return tracker_->bodies();
}

std::size_t Firmware::calibrationObjects() const {
    return state_ == FirmwareState::Calibrating ? calibration_.online().objectCount() : 0;
}

void Firmware::note(std::string event) {
    lastEvent_ = std::move(event);
}

// ---------------------------------------------------------------------------------------------
// Button and calibration sessions

void Firmware::handleButton(hal::Nanoseconds now) {
    hal::ButtonEdge edge;
    while (board_.button.nextEdge(edge))
        button_.edge(edge);
    for (ButtonEvent event = button_.poll(now); event != ButtonEvent::None;
         event = button_.poll(now)) {
        if (finisher_.busy()) {
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
    calibration_.reset();
    calibrationStart_s_ = hal::toSeconds(board_.clock.now());
    calibrationChanged_s_ = calibrationStart_s_;
    learntSoFar_ = {};
    lastPreview_s_ = -1e9;
    state_ = FirmwareState::Calibrating;
    ++counters_.calibrationsStarted;
    note("calibration started");
}

void Firmware::calibrationStep(double time_s) {
    if (!calibration_.update(time_s, markers_.points_rig_mm())) {
        ++counters_.sessionFramesRefused;
        finishCalibration("its full session buffer");
        return;
    }
    // The session settles when the objects that would be exported, and their markers, stop
    // changing.
    const LearntSoFar learnt = learntSoFar();
    if (learnt != learntSoFar_) {
        learntSoFar_ = learnt;
        calibrationChanged_s_ = time_s;
    }
    const double elapsed = time_s - calibrationStart_s_;
    if (elapsed >= config_.session.maxDuration_s)
        finishCalibration("its time limit");
    else if (learnt.objects > 0 && elapsed >= config_.session.minDuration_s &&
             time_s - calibrationChanged_s_ >= config_.session.settle_s)
        finishCalibration("the models settled");
}

Firmware::LearntSoFar Firmware::learntSoFar() {
    LearntSoFar learnt;
    const std::size_t views = calibration_.online().objectViews(objectViews_);
    for (std::size_t i = 0; i < views; ++i)
        if (objectViews_[i].established >= config_.calibration.minModelMarkers) {
            ++learnt.objects;
            learnt.markers += objectViews_[i].established;
        }
    return learnt;
}

void Firmware::finishCalibration(const char* why) {
    char lasted[32];
    std::snprintf(lasted, sizeof lasted, " after %.1f s", frameTime_s_ - calibrationStart_s_);
    finishingEvent_ = std::string("calibration ended by ") + why + lasted;
    const std::size_t objects = learntSoFar().objects;
    if (objects == 0) {
        state_ = FirmwareState::Tracking;
        ++counters_.calibrationsEmpty;
        tracker_->reset();
        note(finishingEvent_ + ": no object learnt; models unchanged");
        return;
    }
    // Completion and the save run beside the frame loop; the models from before are tracked
    // until the new ones are in use.
    state_ = FirmwareState::Finishing;
    tracker_->reset();
    finisher_.start(calibration_, copyOf(models_), config_.maxModels, config_.calibration.smin,
                    store_);
    note(finishingEvent_ + ": finishing " + std::to_string(objects) + " objects");
}

void Firmware::takeFinishedCalibration(FinishedCalibration finished) {
    if (state_ == FirmwareState::Finishing)
        state_ = FirmwareState::Tracking;
    lastFinish_s_ = finished.took_s;
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
    for (std::size_t i = 0; i < merge.models.size(); ++i)
        text += (i ? ", " : "") + std::to_string(merge.models[i].model.markers_model_mm.size());
    text += " markers)";
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
    setModels(std::move(finished.merged.models));
    note(std::move(text));
}

void Firmware::waitForFinishing() {
    if (std::optional<FinishedCalibration> finished = finisher_.wait())
        takeFinishedCalibration(std::move(*finished));
}

void Firmware::deleteModels() {
    if (state_ == FirmwareState::Calibrating) {
        ++counters_.calibrationsAbandoned;
        state_ = FirmwareState::Tracking;
    }
    const Status saved = store_.save({});
    if (!saved)
        ++counters_.flashErrors;
    setModels({});
    ++counters_.modelDeletions;
    oneShot_ = LedPattern::Confirm;
    oneShotUntil_ = board_.clock.now() + patternDuration(LedPattern::Confirm);
    ledPatternSince_ = board_.clock.now();
    note(saved ? "all models deleted (long press)"
               : "models deleted, but flash failed: " + saved.error().message);
}

// ---------------------------------------------------------------------------------------------
// Frame loop

void Firmware::step() {
    const hal::Nanoseconds now = board_.clock.now();
    if (finisher_.busy())
        if (std::optional<FinishedCalibration> finished = finisher_.poll())
            takeFinishedCalibration(std::move(*finished));
    handleButton(now);
    if (state_ == FirmwareState::Degraded) {
        retryCameras(now);
        updateStatusLed(board_.clock.now());
        return;
    }
    capture();
    if (Queued next; queue_.pop(next)) {
        process(next.frame, next.acquiredAt, next.acquiredHost_ns);
        board_.cameras.release(next.frame);
    }
    drainCanErrors();
    updateStatusLed(board_.clock.now());
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
        lastFrameAt_ = at;
        scheduleStrobe(frame);
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
        if (board_.clock.now() - lastFrameAt_ > fromSeconds(config_.cameras.timeout_s))
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

void Firmware::scheduleStrobe(const hal::StereoFrame& frame) {
    const hal::Nanoseconds start =
        std::min(frame.camera[0].exposureStart, frame.camera[1].exposureStart);
    const hal::Nanoseconds end = std::max(frame.camera[0].exposureEnd, frame.camera[1].exposureEnd);
    const hal::Nanoseconds period = board_.cameras.framePeriod();
    const hal::Nanoseconds lead = fromSeconds(config_.gpio.strobeLead_us * 1e-6);
    const hal::Nanoseconds tail = fromSeconds(config_.gpio.strobeTail_us * 1e-6);
    for (int k = 1; k <= kStrobeAhead; ++k) {
        const hal::Nanoseconds next = start + k * period;
        if (strobing_ && next <= lastStrobeStart_ + period / 2)
            continue;
        if (!board_.ledRing.schedulePulse(next - lead, next + (end - start) + tail))
            ++counters_.strobePulsesRefused;
        lastStrobeStart_ = next;
        strobing_ = true;
    }
    // Lit continuously until the pulses already cover the exposure being taken now.
    if (++strobeFrames_ == kContinuousFrames)
        board_.ledRing.setContinuous(false);
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
    markers_.matchStereo();
    const std::int64_t t2 = hostNanos();

    const double time_s = hal::toSeconds(frame.midExposure());
    if (state_ == FirmwareState::Calibrating) {
        calibrationStep(time_s);
    } else {
        tracker_->update(time_s, markers_.points_rig_mm());
        const std::span<const TrackedBody> tracked = tracker_->bodies();
        for (std::size_t b = 0; b < tracked.size() && b < outputPoses_.size(); ++b)
            if (tracked[b].found())
                outputPoses_[b] = filters_[b].update(time_s, tracked[b].T_rig_from_model);
    }
    const std::int64_t t3 = hostNanos();
    sendOutputs(frame, acquiredAt, acquiredHost_ns);
    const std::int64_t t4 = hostNanos();

    stageTimes_[static_cast<std::size_t>(Stage::Blobs)].add(static_cast<double>(t1 - t0) * 1e-3);
    stageTimes_[static_cast<std::size_t>(Stage::Stereo)].add(static_cast<double>(t2 - t1) * 1e-3);
    stageTimes_[static_cast<std::size_t>(Stage::Track)].add(static_cast<double>(t3 - t2) * 1e-3);
    stageTimes_[static_cast<std::size_t>(Stage::Output)].add(static_cast<double>(t4 - t3) * 1e-3);
    stageTimes_[static_cast<std::size_t>(Stage::Frame)].add(static_cast<double>(t4 - t0) * 1e-3);
    const hal::Nanoseconds budget = config_.health.frameBudget_ms > 0.0
                                        ? fromSeconds(config_.health.frameBudget_ms * 1e-3)
                                        : board_.cameras.framePeriod();
    if (t4 - t0 > budget)
        ++counters_.framesOverBudget;

    const MarkerPipelineCounters refused = markers_.counters();
    counters_.blobOverflow = refused.blobOverflow;
    counters_.labelOverflow = refused.labelOverflow;
    counters_.markerOverflow = refused.markerOverflow;
    ++counters_.framesProcessed;
    lastFrame_ = frame.number;
    frameTime_s_ = time_s;
}

// ---------------------------------------------------------------------------------------------
// Outputs

void Firmware::sendOutputs(const hal::StereoFrame& frame, hal::Nanoseconds acquiredAt,
                           std::int64_t acquiredHost_ns) {
    // Time on the board's clock until the frame was in hand, then the host's time spent on it:
    // on the real board both are CLOCK_MONOTONIC; the simulated board's clock is virtual.
    const double latency_s = hal::toSeconds(acquiredAt - frame.midExposure()) +
                             static_cast<double>(hostNanos() - acquiredHost_ns) * 1e-9;
    lastLatency_s_ = latency_s;
    if (config_.udp.enabled)
        sendDtrack(frame, latency_s);
    if (config_.can.enabled && tracksModels())
        sendCan(frame, latency_s);
}

void Firmware::sendDtrack(const hal::StereoFrame& frame, double latency_s) {
    dtrackBodies_.clear();
    if (tracksModels()) {
        const std::span<const TrackedBody> tracked = tracker_->bodies();
        for (std::size_t b = 0; b < tracked.size() && b < outputPoses_.size(); ++b)
            if (tracked[b].found())
                dtrackBodies_.push_back({tracked[b].modelId, 1.0, outputPoses_[b]});
    }
    if (state_ != FirmwareState::Calibrating) {
        // Every frame carries its `3d` line: `3d 0` clears a client's preview markers.
        dtrackMarkers_.clear();
    } else if (config_.session.previewRate_hz > 0.0 &&
               frameTime_s_ - lastPreview_s_ >= 1.0 / config_.session.previewRate_hz) {
        lastPreview_s_ = frameTime_s_;
        dtrackMarkers_.clear();
        // The growing models where they are now: established members, id = object * 1000 +
        // marker, so a viewer can colour them by object. Refreshed at the preview rate and
        // repeated in the frames between.
        calibration_.online().forEachMember([&](const ObjectCalibrator::MemberView& m) {
            if (m.established && dtrackMarkers_.size() < kMaxPreviewMarkers)
                dtrackMarkers_.push_back(
                    {m.objectId * 1000 + m.markerId % 1000, 1.0, m.position_rig_mm});
        });
    }
    DtrackFrame out;
    out.frame = frame.number;
    out.midExposureUtc_ns = frame.midExposure() + board_.clock.utcOffset();
    out.calibrated = static_cast<std::uint32_t>(models_.size());
    out.bodies = dtrackBodies_;
    out.markers = dtrackMarkers_;
    if (config_.udp.latencyLine)
        out.latency_s = latency_s;
    const std::size_t length = formatDtrack(out, datagram_);
    if (length == 0) {
        ++counters_.udpTooLarge;
        return;
    }
    const std::span<const std::uint8_t> bytes(
        reinterpret_cast<const std::uint8_t*>(datagram_.data()), length);
    for (const hal::UdpEndpoint& to : config_.udp.destinations) {
        if (board_.udp.send(to, bytes) == hal::UdpSendResult::Sent)
            ++counters_.udpSent;
        else
            ++counters_.udpFailed;
    }
}

void Firmware::sendCan(const hal::StereoFrame& frame, double latency_s) {
    auto send = [&](const hal::CanFrame& canFrame) {
        switch (board_.can.send(canFrame)) {
        case hal::CanSendResult::Queued:
            ++counters_.canSent;
            break;
        case hal::CanSendResult::DroppedOldest:
            ++counters_.canSent;
            ++counters_.canDropped;
            break;
        default:
            ++counters_.canRefused;
            break;
        }
    };
    const std::span<const TrackedBody> tracked = tracker_->bodies();
    for (std::size_t b = 0; b < tracked.size() && b < outputPoses_.size(); ++b) {
        const TrackedBody& body = tracked[b];
        if (body.modelId >= config_.can.layout.maxBodies) {
            ++counters_.canBodiesBeyondLayout;
            continue;
        }
        CanPose pose;
        pose.body = body.modelId;
        pose.found = body.found();
        pose.frame = frame.number;
        pose.T_rig_from_model = outputPoses_[b];
        pose.markers = body.markers;
        pose.rms_mm = body.rms_mm;
        pose.latency_s = latency_s;
        if (config_.can.fd) {
            send(encodeFdPose(pose, config_.can.layout));
            continue;
        }
        const std::array<hal::CanFrame, 3> frames = encodeClassicPose(pose, config_.can.layout);
        // A body not found sends its status only: the bus carries what a receiver can use.
        for (std::size_t i = pose.found ? 0 : 2; i < frames.size(); ++i)
            send(frames[i]);
    }
}

void Firmware::drainCanErrors() {
    hal::CanErrorEvent event;
    while (board_.can.nextError(event))
        ++counters_.canErrors;
}

// ---------------------------------------------------------------------------------------------
// Degraded state and the status LED

void Firmware::enterDegraded(const char* why) {
    // Frames go back before the stream stops: a backend frees its buffers when it stops.
    for (Queued queued; queue_.pop(queued);)
        board_.cameras.release(queued.frame);
    board_.cameras.stop();
    cameraStarted_ = false;
    if (state_ == FirmwareState::Calibrating)
        ++counters_.calibrationsAbandoned;
    state_ = FirmwareState::Degraded;
    nextRetryAt_ = board_.clock.now() + fromSeconds(config_.cameras.retry_s);
    board_.ledRing.setContinuous(false);
    note(std::string("degraded: ") + why + "; retrying every " +
         std::to_string(config_.cameras.retry_s).substr(0, 4) + " s");
}

void Firmware::retryCameras(hal::Nanoseconds now) {
    if (now < nextRetryAt_) {
        board_.clock.sleepUntil(std::min(nextRetryAt_, now + board_.cameras.framePeriod()));
        return;
    }
    ++counters_.cameraRestarts;
    if (Status s = board_.cameras.start(); !s) {
        nextRetryAt_ = now + fromSeconds(config_.cameras.retry_s);
        return;
    }
    cameraStarted_ = true;
    strobing_ = false;
    strobeFrames_ = 0;
    board_.ledRing.setContinuous(true);
    lastFrameAt_ = board_.clock.now();
    tracker_->reset();
    state_ = finisher_.busy() ? FirmwareState::Finishing : FirmwareState::Tracking;
    note("cameras restarted");
}

void Firmware::updateStatusLed(hal::Nanoseconds now) {
    LedPattern pattern = LedPattern::Heartbeat;
    if (now < oneShotUntil_)
        pattern = oneShot_;
    else if (state_ == FirmwareState::Degraded)
        pattern = LedPattern::FastBlink;
    else if (state_ == FirmwareState::Calibrating)
        pattern = LedPattern::Blink;
    else if (state_ == FirmwareState::Finishing)
        pattern = LedPattern::Finishing;
    else if (std::any_of(tracker_->bodies().begin(), tracker_->bodies().end(),
                         [](const TrackedBody& b) { return b.found(); }))
        pattern = LedPattern::On;
    if (pattern != ledPattern_) {
        ledPattern_ = pattern;
        ledPatternSince_ = now;
    }
    const bool on = ledLevel(pattern, now - ledPatternSince_);
    if (on != ledOn_) {
        ledOn_ = on;
        board_.statusLed.set(on);
    }
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
                      static_cast<unsigned long long>(lastFrame_), calibrationObjects());
    else
        std::snprintf(line, sizeof line, "%s: frame %llu, %zu of %zu bodies", stateName(state_),
                      static_cast<unsigned long long>(lastFrame_), found, models_.size());
    std::string text = line;
    std::snprintf(line, sizeof line,
                  "; frame %.2f ms (max %.2f), latency %.2f ms; dropped %llu, over budget %llu; "
                  "udp %llu sent, can %llu sent",
                  frame.mean_us * 1e-3, frame.max_us * 1e-3, lastLatency_s_ * 1e3,
                  static_cast<unsigned long long>(counters_.framesDroppedQueue +
                                                  board_.cameras.counters().droppedUnpaired +
                                                  board_.cameras.counters().droppedNoBuffer),
                  static_cast<unsigned long long>(counters_.framesOverBudget),
                  static_cast<unsigned long long>(counters_.udpSent),
                  static_cast<unsigned long long>(counters_.canSent));
    return text + line;
}

std::string Firmware::statusReport() const {
    std::string out = "state " + std::string(stateName(state_)) + ", " +
                      std::to_string(models_.size()) + " models\n";
    out += "flash: " + flashReport_ + "\n";
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
    row("blob labels refused (capacity)", c.labelOverflow);
    row("markers refused (capacity)", c.markerOverflow);
    const ModelTrackingCounters& t = tracker_->counters();
    row("tracking: points refused", t.pointOverflow);
    row("tracking: frames out of budget", t.budgetExhausted);
    row("udp sent", c.udpSent);
    row("udp failed", c.udpFailed);
    row("udp frames too large", c.udpTooLarge);
    row("can sent", c.canSent);
    row("can dropped (queue full)", c.canDropped);
    row("can refused (bus-off, down)", c.canRefused);
    row("can error events", c.canErrors);
    row("can bodies beyond the layout", c.canBodiesBeyondLayout);
    row("calibrations started", c.calibrationsStarted);
    row("calibrations saved", c.calibrationsSaved);
    row("calibrations with no object", c.calibrationsEmpty);
    row("calibrations abandoned", c.calibrationsAbandoned);
    row("calibration frames refused (buffer)", c.sessionFramesRefused);
    std::snprintf(line, sizeof line, "%-34s %.2f\n", "last calibration completed in (s)",
                  lastFinish_s_);
    out += line;
    row("models refused (max_models)", c.modelOverflow);
    row("learnt fragments dropped", c.fragmentsDropped);
    row("model deletions", c.modelDeletions);
    row("flash errors", c.flashErrors);
    return out;
}

} // namespace edgetrack::app
