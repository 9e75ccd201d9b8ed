// Completes a field calibration's models in a worker thread of lower priority.
#include "firmware_app/firmware/calibration_finisher.hpp"

#include <chrono>
#include <sys/resource.h>
#include <unistd.h>
#include <utility>

namespace edgetrack::app {

namespace {

/// The worker's nice value: below the frame loop's share of the CPU, yet done within seconds on
/// an idle core (the board's four cores leave three to it).
constexpr int kWorkerNice = 10;

} // namespace

void lowerThisThreadsPriority() {
    // Linux keeps a nice value per thread; setpriority on the thread id changes only this one.
    // Failing (a sandbox that forbids it) costs nothing but the priority.
    (void)setpriority(PRIO_PROCESS, static_cast<id_t>(gettid()), kWorkerNice);
}

CalibrationFinisher::~CalibrationFinisher() {
    if (worker_.joinable())
        worker_.join();
}

void CalibrationFinisher::start(CalibrationSession& session, std::vector<NamedModel> known,
                                std::vector<KnownSighting> sightings,
                                const ModelTrackingConfig& tracking, std::size_t maxModels,
                                const SminConfig& shape, ModelStore& store) {
    (void)wait();
    done_.store(false, std::memory_order_relaxed);
    result_ = FinishedCalibration{};
    worker_ = std::thread([this, &session, known = std::move(known),
                           sightings = std::move(sightings), tracking, maxModels, shape, &store] {
        lowerThisThreadsPriority();
        const auto begin = std::chrono::steady_clock::now();
        FinishedCalibration result;
        const std::vector<MarkerModel> learnt = session.complete();
        result.learnt = learnt.size();
        result.seeds = session.seedsUsed();
        result.completion = session.completionCounters();
        const std::span<const LayoutPrecision> precision = session.completionPrecision();
        result.precision.assign(precision.begin(), precision.end());
        const std::span<const UntiedPieces> untied = session.completionUntiedPieces();
        result.untiedPieces.assign(untied.begin(), untied.end());
        const std::span<const std::size_t> mostSeen = session.completionMostSeenTogether();
        result.mostSeenTogether.assign(mostSeen.begin(), mostSeen.end());
        if (!learnt.empty()) {
            std::vector<MarkerModel> knownLayouts;
            for (const NamedModel& m : known)
                knownLayouts.push_back(copyOf(m.model));
            const std::vector<SameObject> same = findKnownInSession(
                session.frames(), knownLayouts, sightings, learnt, tracking, shape.tolerance_mm);
            result.merged = mergeLearntModels(known, learnt, same, maxModels, shape,
                                              tracking.distanceTolerance_mm);
            result.saved = store.save(result.merged.models);
        }
        result.took_s =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - begin).count();
        result_ = std::move(result);
        done_.store(true, std::memory_order_release);
    });
}

std::optional<FinishedCalibration> CalibrationFinisher::poll() {
    if (!worker_.joinable() || !done_.load(std::memory_order_acquire))
        return std::nullopt;
    worker_.join();
    return std::move(result_);
}

std::optional<FinishedCalibration> CalibrationFinisher::wait() {
    if (!worker_.joinable())
        return std::nullopt;
    worker_.join();
    return std::move(result_);
}

} // namespace edgetrack::app
