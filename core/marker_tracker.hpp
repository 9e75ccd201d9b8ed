// Frame-to-frame correspondence of 3D markers (paper section 3.2, eq. 5) with constant-velocity
// prediction: each marker keeps a unique ID and an age while it is seen.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/bounded_vector.hpp"
#include "core/correspondence.hpp"
#include "core/geometry.hpp"

namespace edgetrack {

/// \brief Tuning of frame-to-frame correspondence; defaults suit hand motion at 100 Hz.
struct FrameToFrameConfig {
    /// sigma_t of eq. 5: expected error of the predicted position (mm).
    double sigma_mm = 5.0;
    /// Proximity is exactly zero beyond this distance from the prediction (mm); bounds the blocks.
    double gate_mm = 15.0;
    /// A correspondence needs at least this proximity.
    double minProximity = 1e-4;
    /// With a longer gap between frames (s) the velocity is not trusted for prediction.
    double maxPredictionGap_s = 0.1;
    /// Markers tracked at once; more are counted as overflow.
    std::size_t maxMarkers = 256;

    bool operator==(const FrameToFrameConfig&) const = default;
};

/// \brief A marker with its identity: ID stays constant while the marker is seen frame after frame.
struct TrackedMarker {
    std::uint32_t id = 0;
    /// Frames this marker has been seen without interruption before this one (0: new).
    std::uint32_t age = 0;
    /// Rig frame (mm).
    Vec3 position_rig_mm = Vec3::Zero();
    /// Rig frame (mm/s), from the last two frames.
    Vec3 velocity_rig_mm_s = Vec3::Zero();
};

struct TrackerCounters {
    std::uint64_t frames = 0;
    std::uint64_t continued = 0;
    std::uint64_t born = 0;
    std::uint64_t blockOverflow = 0;
    std::uint64_t markerOverflow = 0;
};

/**
 * \brief Assigns IDs to each frame's markers by matching them to the previous frame's markers,
 * moved ahead by their velocity, with the Scott and Longuet-Higgins method and proximity
 * G_ij = exp(-|p_i(t) - p^_j(t)|^2 / 2 sigma_t^2) (eq. 5 with prediction p^).
 */
class MarkerTracker {
public:
    explicit MarkerTracker(const FrameToFrameConfig& config);

    /**
     * \brief Track one frame.
     * \param points this frame's markers (rig frame, mm), in any order.
     * \return this frame's markers with IDs and ages, in the order of \a points.
     */
    std::span<const TrackedMarker> update(double time_s, std::span<const Vec3> points);

    /// \brief Forget every marker (a new recording, or after a long gap).
    void reset();

    std::span<const TrackedMarker> current() const { return current_.span(); }
    const TrackerCounters& counters() const { return counters_; }

private:
    FrameToFrameConfig config_;
    TrackerCounters counters_{};
    BoundedVector<TrackedMarker> previous_;
    BoundedVector<TrackedMarker> current_;
    BoundedVector<Vec3> predicted_;
    BoundedVector<int> matchOf_;
    /// Predicted markers in order of x, so that gating looks only at a slab of them.
    BoundedVector<int> predictedByX_;
    BipartiteBlocks blocks_;
    BlockSolver solver_;
    double previousTime_s_ = 0.0;
    bool havePrevious_ = false;
    std::uint32_t nextId_ = 1;
};

} // namespace edgetrack
