// The board's rig calibration: wand sightings per frame, the solver in a worker thread.
#include "firmware_app/firmware/rig_session.hpp"

#include <chrono>

#include "firmware_app/firmware/calibration_finisher.hpp"

namespace edgetrack::app {

double meanReprojection_px(const RigCalibrationReport& report) {
    return 0.5 * (report.reprojectionRms_px[0] + report.reprojectionRms_px[1]);
}

RigSession::RigSession(const RigCalibrationSettings& settings)
    : settings_(settings)
    , wand_(WandSpec::fromSpacings(settings.wand_mm))
    , finders_{WandFinder(wand_, {}), WandFinder(wand_, {})}
    , pairs_(settings.maxFrames) {}

RigSession::~RigSession() {
    if (worker_.joinable())
        worker_.join();
}

void RigSession::open(double now_s) {
    pairs_.clear();
    open_ = true;
    opened_s_ = now_s;
}

RigSessionStep RigSession::update(double time_s, const StereoRig& rig, std::span<const Blob> blobs0,
                                  std::span<const Blob> blobs1) {
    if (!open_)
        return RigSessionStep::Continue;
    WandFramePair pair;
    pair.frame = static_cast<std::int64_t>(pairs_.size());
    const std::optional<WandSighting> seen0 = finders_[0].find(rig.camera(0), blobs0);
    const std::optional<WandSighting> seen1 =
        seen0 ? finders_[1].find(rig.camera(1), blobs1) : std::nullopt;
    if (seen0 && seen1) {
        pair.sightings = {*seen0, *seen1};
        if (!pairs_.push_back(pair))
            return RigSessionStep::BufferFull;
    }
    if (time_s - opened_s_ >= settings_.duration_s)
        return RigSessionStep::TimeUp;
    return pairs_.full() ? RigSessionStep::BufferFull : RigSessionStep::Continue;
}

void RigSession::finish(const StereoRig& current, RigStore& store) {
    (void)wait();
    open_ = false;
    done_.store(false, std::memory_order_relaxed);
    result_ = FinishedRigCalibration{};
    worker_ = std::thread([this, current, &store] {
        lowerThisThreadsPriority();
        const auto begin = std::chrono::steady_clock::now();
        FinishedRigCalibration result;
        result.pairs = pairs_.size();
        RigCalibrationConfig config;
        config.refineIntrinsics = settings_.refineIntrinsics;
        config.minFrames = RigCalibrationConfig{}.minFrames / 2;
        // A rig fitted to some sightings always explains those better than the old one: the
        // judge is the other half. Every second pair calibrates, the rest tell the better rig.
        std::vector<WandFramePair> fit, check;
        for (std::size_t i = 0; i < pairs_.size(); ++i)
            (i % 2 == 0 ? fit : check).push_back(pairs_[i]);
        Result<RigCalibrationResult> halfRig = calibrateRig(current, wand_, fit, config);
        if (!halfRig) {
            result.error = halfRig.error().message;
        } else {
            const Result<RigCalibrationReport> newOnCheck =
                assessRig(halfRig->rig, wand_, check, config);
            const Result<RigCalibrationReport> oldOnCheck =
                assessRig(current, wand_, check, config);
            if (oldOnCheck)
                result.previous = *oldOnCheck;
            result.adopted = newOnCheck && (!oldOnCheck || meanReprojection_px(*newOnCheck) <
                                                               meanReprojection_px(*oldOnCheck));
            // Adopted: the rig of all the sightings, from the half's rig.
            Result<RigCalibrationResult> whole =
                result.adopted ? calibrateRig(halfRig->rig, wand_, pairs_.span(), config)
                               : std::move(halfRig);
            if (!whole) {
                result.adopted = false;
                result.error = whole.error().message;
            } else {
                result.calibrated = std::move(*whole);
                result.heldOut_px = newOnCheck ? meanReprojection_px(*newOnCheck) : 0.0;
            }
            if (result.adopted)
                result.saved = store.save(result.calibrated->rig,
                                          meanReprojection_px(result.calibrated->report));
        }
        result.took_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
        result_ = std::move(result);
        done_.store(true, std::memory_order_release);
    });
}

std::optional<FinishedRigCalibration> RigSession::poll() {
    if (!worker_.joinable() || !done_.load(std::memory_order_acquire))
        return std::nullopt;
    worker_.join();
    return std::move(result_);
}

std::optional<FinishedRigCalibration> RigSession::wait() {
    if (!worker_.joinable())
        return std::nullopt;
    worker_.join();
    return std::move(result_);
}

} // namespace edgetrack::app
