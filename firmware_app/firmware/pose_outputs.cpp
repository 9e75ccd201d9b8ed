// The board's outputs: filtered poses as DTrack UDP datagrams and CAN frames, calibration preview.
#include "firmware_app/firmware/pose_outputs.hpp"

#include <array>

#include "firmware_app/firmware/can_pose.hpp"

namespace edgetrack::app {

namespace {

/// Markers in one calibration preview (`3d` line); the datagram buffer holds them.
constexpr std::size_t kMaxPreviewMarkers = 128;
constexpr std::size_t kDatagramBytes = 8192;

} // namespace

PoseOutputs::PoseOutputs(const FirmwareConfig& config)
    : udp_(config.udp)
    , can_(config.can)
    , previewRate_hz_(config.session.previewRate_hz)
    , filters_(config.maxModels, PoseFilter(config.filter))
    , poses_(config.maxModels)
    , datagram_(kDatagramBytes) {
    dtrackBodies_.reserve(config.maxModels);
    previewMarkers_.reserve(kMaxPreviewMarkers);
}

void PoseOutputs::resetFilters() {
    for (PoseFilter& filter : filters_)
        filter.reset();
}

void PoseOutputs::updatePoses(double time_s, std::span<const TrackedBody> bodies) {
    for (std::size_t b = 0; b < bodies.size() && b < poses_.size(); ++b)
        if (bodies[b].found())
            poses_[b] = filters_[b].update(time_s, bodies[b].T_rig_from_model);
}

void PoseOutputs::preview(double time_s, const ObjectCalibrator& online) {
    if (previewRate_hz_ <= 0.0 || time_s - lastPreview_s_ < 1.0 / previewRate_hz_)
        return; // the last preview is repeated in the frames between
    lastPreview_s_ = time_s;
    previewMarkers_.clear();
    // The growing models where they are now: their established markers.
    online.forEachMember([&](const ObjectCalibrator::MemberView& m) {
        if (m.established && previewMarkers_.size() < kMaxPreviewMarkers)
            previewMarkers_.push_back(
                {previewMarkerId(m.objectId, m.markerId), 1.0, m.position_rig_mm});
    });
}

void PoseOutputs::clearPreview() {
    previewMarkers_.clear();
    lastPreview_s_ = -1e9;
}

void PoseOutputs::send(const OutputFrame& frame, hal::UdpSender& udp, hal::CanBus& can) {
    if (udp_.enabled)
        sendDtrack(frame, udp);
    if (can_.enabled)
        sendCan(frame, can);
}

void PoseOutputs::sendDtrack(const OutputFrame& frame, hal::UdpSender& udp) {
    dtrackBodies_.clear();
    for (std::size_t b = 0; b < frame.bodies.size() && b < poses_.size(); ++b)
        if (frame.bodies[b].found())
            dtrackBodies_.push_back({frame.bodies[b].modelId, 1.0, poses_[b]});
    DtrackFrame out;
    out.frame = frame.number;
    out.midExposureUtc_ns = frame.midExposureUtc_ns;
    out.calibrated = frame.calibrated;
    out.bodies = dtrackBodies_;
    out.markers = previewMarkers_;
    if (udp_.latencyLine)
        out.latency_s = frame.latency_s;
    const std::size_t length = formatDtrack(out, datagram_);
    if (length == 0) {
        ++counters_.udpTooLarge;
        return;
    }
    const std::span<const std::uint8_t> bytes(
        reinterpret_cast<const std::uint8_t*>(datagram_.data()), length);
    for (const hal::UdpEndpoint& to : udp_.destinations) {
        if (udp.send(to, bytes) == hal::UdpSendResult::Sent)
            ++counters_.udpSent;
        else
            ++counters_.udpFailed;
    }
}

void PoseOutputs::sendCan(const OutputFrame& frame, hal::CanBus& can) {
    auto send = [&](const hal::CanFrame& canFrame) {
        switch (can.send(canFrame)) {
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
    for (std::size_t b = 0; b < frame.bodies.size() && b < poses_.size(); ++b) {
        const TrackedBody& body = frame.bodies[b];
        if (body.modelId >= can_.layout.maxBodies) {
            ++counters_.canBodiesBeyondLayout;
            continue;
        }
        CanPose pose;
        pose.body = body.modelId;
        pose.found = body.found();
        pose.frame = frame.number;
        pose.T_rig_from_model = poses_[b];
        pose.markers = body.markers;
        pose.rms_mm = body.rms_mm;
        pose.latency_s = frame.latency_s;
        if (can_.fd) {
            send(encodeFdPose(pose, can_.layout));
            continue;
        }
        const std::array<hal::CanFrame, 3> frames = encodeClassicPose(pose, can_.layout);
        // A body not found sends its status only: the bus carries what a receiver can use.
        for (std::size_t i = pose.found ? 0 : 2; i < frames.size(); ++i)
            send(frames[i]);
    }
}

void PoseOutputs::drainCanErrors(hal::CanBus& can) {
    hal::CanErrorEvent event;
    while (can.nextError(event))
        ++counters_.canErrors;
}

} // namespace edgetrack::app
