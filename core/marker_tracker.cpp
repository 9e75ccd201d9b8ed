// Frame-to-frame correspondence of 3D markers (paper section 3.2, eq. 5) with constant-velocity
// prediction: each marker keeps a unique ID and an age while it is seen.
#include "core/marker_tracker.hpp"

#include <algorithm>
#include <cmath>

namespace edgetrack {

namespace {
constexpr std::size_t idx(int i) {
    return static_cast<std::size_t>(i);
}
} // namespace

MarkerTracker::MarkerTracker(const FrameToFrameConfig& config)
    : config_(config)
    , previous_(config.maxMarkers)
    , current_(config.maxMarkers)
    , predicted_(config.maxMarkers)
    , matchOf_(config.maxMarkers)
    , predictedByX_(config.maxMarkers)
    , blocks_(config.maxMarkers, config.maxMarkers) {}

void MarkerTracker::reset() {
    previous_.clear();
    current_.clear();
    havePrevious_ = false;
}

std::span<const TrackedMarker> MarkerTracker::update(double time_s, std::span<const Vec3> points) {
    ++counters_.frames;
    std::swap(previous_, current_);
    current_.clear();
    const std::size_t count = std::min(points.size(), config_.maxMarkers);
    if (points.size() > count)
        counters_.markerOverflow += points.size() - count;

    const double dt = havePrevious_ ? time_s - previousTime_s_ : 0.0;
    const bool usable = havePrevious_ && dt > 0.0 && dt <= config_.maxPredictionGap_s;
    if (!usable)
        previous_.clear(); // too long ago (or time went backwards): start afresh

    predicted_.clear();
    for (const TrackedMarker& m : previous_)
        predicted_.push_back(m.position_rig_mm + dt * m.velocity_rig_mm_s);

    matchOf_.clear();
    matchOf_.resize(count);
    std::fill(matchOf_.begin(), matchOf_.end(), -1);

    const double gate2 = config_.gate_mm * config_.gate_mm;
    const double twoSigma2 = 2.0 * config_.sigma_mm * config_.sigma_mm;
    // Only predictions within the gate can link; in x they lie in a slab of twice its width.
    predictedByX_.clear();
    for (std::size_t j = 0; j < predicted_.size(); ++j)
        predictedByX_.push_back(static_cast<int>(j));
    std::sort(predictedByX_.begin(), predictedByX_.end(),
              [this](int a, int b) { return predicted_[idx(a)].x() < predicted_[idx(b)].x(); });
    blocks_.reset(count, predicted_.size());
    for (std::size_t i = 0; i < count; ++i) {
        const double slabStart = points[i].x() - config_.gate_mm;
        auto j = std::partition_point(predictedByX_.begin(), predictedByX_.end(),
                                      [&](int k) { return predicted_[idx(k)].x() < slabStart; });
        for (;
             j != predictedByX_.end() && predicted_[idx(*j)].x() <= points[i].x() + config_.gate_mm;
             ++j)
            if ((points[i] - predicted_[idx(*j)]).squaredNorm() <= gate2)
                blocks_.link(i, idx(*j));
    }
    blocks_.build();

    auto proximity = [&](int i, int j) {
        const double d2 = (points[idx(i)] - predicted_[idx(j)]).squaredNorm();
        return d2 <= gate2 ? std::exp(-d2 / twoSigma2) : 0.0;
    };
    for (std::size_t b = 0; b < blocks_.blockCount(); ++b) {
        const bool solved =
            solver_.solve(blocks_.leftOf(b), blocks_.rightOf(b), config_.minProximity, proximity,
                          [this](int i, int j) { matchOf_[idx(i)] = j; });
        if (!solved)
            ++counters_.blockOverflow;
    }

    for (std::size_t i = 0; i < count; ++i) {
        TrackedMarker* m = current_.append();
        m->position_rig_mm = points[i];
        const int j = matchOf_[i];
        if (j >= 0) {
            const TrackedMarker& before = previous_[idx(j)];
            m->id = before.id;
            m->age = before.age + 1;
            m->velocity_rig_mm_s = (points[i] - before.position_rig_mm) / dt;
            ++counters_.continued;
        } else {
            m->id = nextId_++;
            if (nextId_ == 0)
                nextId_ = 1; // 0 means "no marker"
            m->age = 0;
            ++counters_.born;
        }
    }
    previousTime_s_ = time_s;
    havePrevious_ = true;
    return current_.span();
}

} // namespace edgetrack
