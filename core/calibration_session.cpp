// One object-calibration session: the online stage, the kept frames, the completion.
#include "core/calibration_session.hpp"

namespace edgetrack {

CalibrationSession::CalibrationSession(const CalibrationConfig& online,
                                       const CompletionConfig& completion, std::size_t maxFrames,
                                       std::size_t maxPoints)
    : onlineConfig_(online)
    , completionConfig_(completion)
    , online_(online)
    , buffer_(maxFrames, maxPoints)
    , completion_(completion) {}

void CalibrationSession::reset() {
    online_.reset();
    buffer_.clear();
    seedsUsed_ = 0;
}

bool CalibrationSession::update(double time_s, std::span<const Vec3> points_rig_mm) {
    online_.update(time_s, points_rig_mm);
    return buffer_.append(time_s, points_rig_mm);
}

std::vector<MarkerModel> CalibrationSession::complete() {
    std::vector<MarkerModel> seeds;
    seeds.reserve(onlineConfig_.maxObjects);
    for (std::size_t i = 0; i < onlineConfig_.maxObjects; ++i)
        seeds.emplace_back(onlineConfig_.maxMarkersPerObject);
    // Completion reads the seeds' layouts and edges; it finds S_min for its own models.
    seeds.resize(online_.exportLayouts(seeds));
    seedsUsed_ = seeds.size();
    std::vector<MarkerModel> models;
    models.reserve(completionConfig_.maxModels);
    for (std::size_t i = 0; i < completionConfig_.maxModels; ++i)
        models.emplace_back(completionConfig_.maxMarkersPerModel);
    models.resize(completion_.run(buffer_, seeds, models));
    return models;
}

} // namespace edgetrack
