// The board's outputs: filtered poses as DTrack UDP datagrams and CAN frames, calibration preview.
#pragma once

#include <cstdint>
#include <span>
#include <vector>

#include "core/model_tracker.hpp"
#include "core/object_calibrator.hpp"
#include "core/pose_filter.hpp"
#include "firmware_app/firmware/dtrack.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "hal/can_bus.hpp"
#include "hal/udp.hpp"

namespace edgetrack::app {

/// \brief What the outputs sent and refused (the status view's udp and can rows).
struct OutputCounters {
    std::uint64_t udpSent = 0;
    std::uint64_t udpFailed = 0;
    /// DTrack frames larger than the datagram buffer; not sent.
    std::uint64_t udpTooLarge = 0;
    std::uint64_t canSent = 0;
    std::uint64_t canDropped = 0;
    std::uint64_t canRefused = 0;
    std::uint64_t canErrors = 0;
    /// Bodies whose model id is beyond the CAN layout's bodies; not sent on CAN.
    std::uint64_t canBodiesBeyondLayout = 0;
};

/// \brief One processed frame as the outputs see it.
struct OutputFrame {
    std::uint64_t number = 0;
    /// Mid-exposure, UTC (ns since 1970-01-01).
    std::int64_t midExposureUtc_ns = 0;
    /// Mid-exposure to sending (s).
    double latency_s = 0.0;
    /// DTrack's `6dcal`: the highest model id on the board + 1 (receivers keep ids below it).
    std::uint32_t calibrated = 0;
    /// The tracker's bodies, in model order (empty while calibrating: nothing is tracked).
    std::span<const TrackedBody> bodies;
};

/**
 * \brief Sends every processed frame to the host (DTrack over UDP) and to the bus (CAN).
 *
 * Poses go out through a per-body filter (`[filter]`). While a calibration runs, the growing
 * models' markers go to the host as DTrack `3d` markers at the preview rate. All buffers are
 * sized by the constructor; sending allocates nothing.
 */
class PoseOutputs {
public:
    explicit PoseOutputs(const FirmwareConfig& config);

    /// \brief A new model set (or a tracker reset): the filters forget their bodies.
    void resetFilters();
    /// \brief Filter the found bodies' poses of the frame at \a time_s.
    void updatePoses(double time_s, std::span<const TrackedBody> bodies);

    /// \brief Show the calibration's established markers, refreshed at the preview rate.
    void preview(double time_s, const ObjectCalibrator& online);
    /// \brief No calibration runs: every frame clears a client's preview markers (`3d 0`).
    void clearPreview();

    /// \brief Send \a frame: DTrack to every destination, CAN when enabled.
    void send(const OutputFrame& frame, hal::UdpSender& udp, hal::CanBus& can);
    /// \brief Count the bus's error events.
    void drainCanErrors(hal::CanBus& can);

    const OutputCounters& counters() const { return counters_; }

    /// \brief The DTrack id of calibration marker \a markerId of object \a objectId: the wire
    /// has one id per `3d` marker, and object * 1000 + marker lets a viewer colour by object.
    static std::uint32_t previewMarkerId(std::uint32_t objectId, std::uint32_t markerId) {
        return objectId * 1000 + markerId % 1000;
    }

private:
    void sendDtrack(const OutputFrame& frame, hal::UdpSender& udp);
    void sendCan(const OutputFrame& frame, hal::CanBus& can);

    UdpSettings udp_;
    CanSettings can_;
    double previewRate_hz_;
    std::vector<PoseFilter> filters_;
    /// Per body: the pose sent (filtered when the filter is on), model to rig (mm).
    std::vector<RigidTransform> poses_;
    std::vector<DtrackBody> dtrackBodies_;
    std::vector<DtrackMarker> previewMarkers_;
    double lastPreview_s_ = -1e9;
    std::vector<char> datagram_;
    OutputCounters counters_{};
};

} // namespace edgetrack::app
