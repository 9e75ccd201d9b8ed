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
    /// Seconds since UTC midnight, at mid-exposure.
    double timestamp_s = 0.0;
    /// Number of calibrated bodies (`6dcal`).
    std::uint32_t calibrated = 0;
    std::span<const DtrackBody> bodies;
    /// Single markers (`3d` line), left out when empty.
    std::span<const DtrackMarker> markers;
    /// Mid-exposure to send (s); written as the extension line `etlat` when set. DTrack clients
    /// skip labels they do not know (DTrackSDK, VRPN's driver), so the frame stays readable.
    std::optional<double> latency_s;
};

/**
 * \brief Write \a frame as one DTrack ASCII datagram into \a out, CRLF line ends:
 * `fr`, `ts`, `6dcal`, and `6d N [id q][x y z][r0 ... r8]` with the rotation column-wise and
 * positions in mm (`6d 0` when no body is found); then `3d N [id q][x y z]` when there are
 * markers and `etlat SECONDS` when the latency is set.
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
    std::vector<DtrackMarker> markers;
    std::optional<double> latency_s;
};

/// \brief Parse a datagram as a DTrack client does: the lines above, CRLF ends, unknown lines
/// skipped; a rotation that is not orthonormal (to 1e-4) is an error.
Result<ParsedDtrack> parseDtrack(std::string_view datagram);

} // namespace edgetrack::app
