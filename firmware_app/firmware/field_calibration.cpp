// A field calibration on the board: the session, when it ends on its own, and its finishing.
#include "firmware_app/firmware/field_calibration.hpp"

#include <cmath>

namespace edgetrack::app {

const char* endReason(SessionStep step) {
    switch (step) {
    case SessionStep::BufferFull:
        return "its full session buffer";
    case SessionStep::TimeLimit:
        return "its time limit";
    case SessionStep::Settled:
        return "the models settled";
    case SessionStep::Continue:
        break;
    }
    return "?";
}

FieldCalibration::FieldCalibration(const FirmwareConfig& config, const StereoRig& rig)
    : settings_(config.session)
    , maxModels_(config.maxModels)
    , tracking_(config.tracking)
    , online_(config.calibration)
    , session_(config.calibration, completionFor(config, &rig), sessionFrames(config),
               sessionFrames(config) * config.session.bufferPointsPerFrame)
    , views_(config.calibration.maxObjects) {}

void FieldCalibration::open(double now_s) {
    session_.reset();
    open_ = true;
    opened_s_ = now_s;
    changed_s_ = now_s;
    learnt_ = {};
}

SessionStep FieldCalibration::update(double time_s, std::span<const Vec3> points_rig_mm) {
    if (!session_.update(time_s, points_rig_mm))
        return SessionStep::BufferFull;
    // The session settles when the objects that would be finished, and their markers, stop
    // changing.
    const Learnt now = learnt();
    if (now != learnt_) {
        learnt_ = now;
        changed_s_ = time_s;
    }
    const double elapsed = time_s - opened_s_;
    if (elapsed >= settings_.maxDuration_s)
        return SessionStep::TimeLimit;
    if (now.objects > 0 && elapsed >= settings_.minDuration_s &&
        time_s - changed_s_ >= settings_.settle_s)
        return SessionStep::Settled;
    return SessionStep::Continue;
}

FieldCalibration::Learnt FieldCalibration::learnt() {
    Learnt learnt;
    const std::size_t count = session_.online().objectViews(views_);
    for (std::size_t i = 0; i < count; ++i)
        if (views_[i].established >= online_.minModelMarkers) {
            ++learnt.objects;
            learnt.markers += views_[i].established;
        }
    return learnt;
}

std::size_t FieldCalibration::learntObjects() {
    return learnt().objects;
}

void FieldCalibration::finish(std::vector<NamedModel> known, std::vector<KnownSighting> sightings,
                              ModelStore& store) {
    open_ = false;
    finisher_.start(session_, std::move(known), std::move(sightings), tracking_, maxModels_,
                    online_.smin, store);
}

} // namespace edgetrack::app
