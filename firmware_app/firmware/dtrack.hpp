// A.R.T. DTrack ASCII frames (INTERFACES §6): the UDP output existing DTrack clients read as is.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string_view>
#include <vector>

#include "core/geometry.hpp"
#include "core/result.hpp"
#include "core/rigid_transform.hpp"
#include "firmware_app/formats/named_model.hpp"

namespace edgetrack::app {

/// \brief One body in a DTrack `6d` line.
struct DtrackBody {
    std::uint32_t id = 0;
    /// DTrack's quality, 0 to 1.
    double quality = 1.0;
    /// Model to rig (mm).
    RigidTransform T_rig_from_model;
};

/// \brief One single marker in a DTrack `3d` line.
struct DtrackMarker {
    std::uint32_t id = 0;
    double quality = 1.0;
    /// Rig frame (mm).
    Vec3 position_mm = Vec3::Zero();
};

/// \brief Everything one DTrack datagram says.
struct DtrackFrame {
    std::uint64_t frame = 0;
    /// Mid-exposure, UTC (ns since 1970-01-01). `ts` says it in seconds since UTC midnight,
    /// `ts2` in whole seconds and microseconds since 1970.
    std::int64_t midExposureUtc_ns = 0;
    /// `6dcal`: the highest body id + 1, as receivers drop bodies of an id at or above it.
    std::uint32_t calibrated = 0;
    std::span<const DtrackBody> bodies;
    /// Single markers: the `3d` line, sent in every frame (`3d 0` when empty), because DTrack
    /// clients replace their marker list only when a `3d` line arrives.
    std::span<const DtrackMarker> markers;
    /// Mid-exposure to send (s): the third field of the `ts2` line (in microseconds), where
    /// DTrackSDK reads the latency; no `ts2` line when unset.
    std::optional<double> latency_s;
};

/// \brief A `ts2` line: DTrack's timestamp with the latency beside it.
struct DtrackTs2 {
    /// Mid-exposure, UTC: whole seconds since 1970-01-01 and the microseconds after them.
    std::uint64_t seconds = 0;
    std::uint32_t microseconds = 0;
    /// Mid-exposure to send (us).
    std::uint32_t latency_us = 0;
};

/**
 * \brief DTrack's `6dcal` for \a models: the highest id + 1. DTrack receivers (DTrackSDK, VRPN's
 * driver) keep only bodies whose id is below it, so with ids that do not run from 0 (models 2 and
 * 3 alone) the number of models would hide them.
 */
std::uint32_t dtrackCalibratedCount(std::span<const NamedModel> models);

/**
 * \brief Write \a frame as one DTrack ASCII datagram into \a out, CRLF line ends:
 * `fr`, `ts` (seconds since UTC midnight), `ts2 SECONDS MICROSECONDS LATENCY_US` when the latency
 * is set, `6dcal`, `6d N [id q][x y z][r0 ... r8]` with the rotation column-wise and positions in
 * mm (`6d 0` when no body is found), and `3d N [id q][x y z]` (`3d 0` when there are no markers).
 * \return the datagram's length, or 0 when it does not fit \a out (nothing partial is sent).
 * Allocates nothing: it runs in the frame loop.
 */
std::size_t formatDtrack(const DtrackFrame& frame, std::span<char> out);

/// \brief A parsed datagram (for tests and tools; allocates).
struct ParsedDtrack {
    std::uint64_t frame = 0;
    double timestamp_s = 0.0;
    std::uint32_t calibrated = 0;
    std::vector<DtrackBody> bodies;
    /// Whether the datagram had a `3d` line: a DTrack client keeps its previous markers if not.
    bool hasMarkerLine = false;
    std::vector<DtrackMarker> markers;
    std::optional<DtrackTs2> ts2;
};

/// \brief Parse a datagram as DTrackSDK does: the lines above, CRLF ends, unknown lines skipped;
/// a rotation that is not orthonormal (to 1e-4) is an error.
Result<ParsedDtrack> parseDtrack(std::string_view datagram);

} // namespace edgetrack::app
