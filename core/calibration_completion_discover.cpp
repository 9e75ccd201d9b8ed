// Completion, discover step: bodies that no seed explains, found as moving rigid sets of points.
#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <numeric>
#include <optional>

#include "core/calibration_completion.hpp"
#include "core/completion_geometry.hpp"
#include "core/marker_set.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

using namespace completion_detail;

namespace {

/// Points no body explains are followed this long, from a frame this often, for rigid sets...
constexpr std::size_t kDiscoveryWindow_frames = 30;
constexpr std::size_t kDiscoveryStride_frames = 25;
/// ...found frame to frame within this of where their speed puts them (mm)...
constexpr double kDiscoveryGate_mm = 4.0;
/// ...that move at least this far in that time (mm); such a set is a body if the tracker then
/// finds it in this much of the session (s).
constexpr double kDiscoveryMotion_mm = 3.0;
constexpr double kDiscoveredMinFound_s = 1.0;

} // namespace

// ---------------------------------------------------------------------------------------------
// Bodies that no seed explains

void CalibrationCompletion::discoverBodies(const SessionBuffer& session) {
    const std::size_t frames = session.frames();
    const std::size_t window = kDiscoveryWindow_frames;
    if (frames <= window)
        return;
    // Points within reach of a body found in that frame are that body's to measure (its markers
    // not yet in its model among them); the rest are looked at for new bodies.
    const double reach2 = config_.reach_mm * config_.reach_mm;
    auto explained = [&](std::size_t f, const Vec3& p) {
        for (const Body& body : bodies_) {
            if (!body.alive || !body.posed[f])
                continue;
            const RigidTransform T_body_from_rig = body.T_rig_from_body[f].inverse();
            const Vec3 q = T_body_from_rig.apply(p);
            for (const Vec3& m : body.markers_mm)
                if ((m - q).squaredNorm() <= reach2)
                    return true;
        }
        return false;
    };
    std::vector<std::vector<Vec3>> tracks; // per candidate point, its place in each window frame
    std::vector<std::uint64_t> rigidWith;  // per track, a bit per track it keeps its distance to
    std::size_t tries = 0;
    for (std::size_t start = 0; start + window < frames; start += kDiscoveryStride_frames) {
        if (bodies_.size() >= config_.maxModels)
            return;
        // Points no body explains, followed frame to frame through the window.
        tracks.clear();
        for (const Vec3& p : session.points(start)) {
            if (tracks.size() == 64)
                break;
            if (!explained(start, p))
                tracks.push_back({p});
        }
        if (tracks.size() < 4)
            continue;
        for (std::size_t f = start + 1; f <= start + window; ++f) {
            const std::span<const Vec3> points = session.points(f);
            for (std::vector<Vec3>& track : tracks) {
                if (track.size() != f - start)
                    continue; // lost earlier
                const Vec3 predicted =
                    track.size() >= 2 ? 2.0 * track.back() - track[track.size() - 2] : track.back();
                const Vec3* match = nearestPoint(points, predicted, kDiscoveryGate_mm);
                if (match != nullptr)
                    track.push_back(*match);
            }
        }
        std::erase_if(tracks, [&](const std::vector<Vec3>& t) { return t.size() != window + 1; });
        const std::size_t n = tracks.size();
        if (n < 4)
            continue;
        // Pairs that keep their distance while the pair moves: a marker on a body held in a
        // hand moves; reflections of the room stand still, and every two of them keep theirs.
        rigidWith.assign(n, 0);
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t j = i + 1; j < n; ++j) {
                const double d0 = (tracks[i][0] - tracks[j][0]).norm();
                bool rigid = true;
                for (std::size_t k = 1; k <= window && rigid; ++k)
                    rigid = std::abs((tracks[i][k] - tracks[j][k]).norm() - d0) <=
                            config_.tracking.distanceTolerance_mm;
                const bool moved =
                    (tracks[i][window] - tracks[i][0]).norm() >= kDiscoveryMotion_mm ||
                    (tracks[j][window] - tracks[j][0]).norm() >= kDiscoveryMotion_mm;
                if (rigid && moved) {
                    rigidWith[i] |= std::uint64_t{1} << j;
                    rigidWith[j] |= std::uint64_t{1} << i;
                }
            }
        // The largest set of such points that all keep their distances (greedy: the point with
        // most partners first, then only partners of everyone taken).
        std::uint64_t candidates = 0;
        for (std::size_t i = 0; i < n; ++i)
            if (std::popcount(rigidWith[i]) >= 3)
                candidates |= std::uint64_t{1} << i;
        std::uint64_t clique = 0;
        while (candidates != 0) {
            std::size_t best = 0;
            int bestDegree = -1;
            for (std::size_t i = 0; i < n; ++i)
                if ((candidates >> i) & 1U) {
                    const int degree = std::popcount(rigidWith[i] & candidates);
                    if (degree > bestDegree) {
                        bestDegree = degree;
                        best = i;
                    }
                }
            clique |= std::uint64_t{1} << best;
            candidates &= rigidWith[best];
        }
        if (std::popcount(clique) < static_cast<int>(config_.minModelMarkers))
            continue;
        // Each try tracks through the whole session: a bound on what a scene of things that
        // move alike for moments can cost.
        if (++tries > config_.maxModels)
            return;
        // A new body, in the rig frame of the window's first frame; the tracker then finds it
        // wherever else it is, and the rounds that follow complete it like any seed.
        Body& body = bodies_.emplace_back();
        body.id = nextBodyId_++;
        for (std::size_t i = 0; i < n; ++i)
            if ((clique >> i) & 1U)
                body.markers_mm.push_back(tracks[i][0]);
        body.T_rig_from_body.resize(frames);
        body.posed.assign(frames, 0);
        ++counters_.discovered;
        const std::vector<MarkerModel> models = trackingModels(bodies_.size());
        std::vector<MarkerModel> alone;
        alone.emplace_back(config_.maxMarkersPerModel).assign(models.back());
        alone.back().id = 0;
        const PoseTrack track{&body.posed, &body.T_rig_from_body};
        trackBothWays(session, alone, std::span(&track, 1));
        // Points of things that moved alike for a moment are found only in that moment; a body
        // is found wherever enough of it is in view.
        const auto posedFrames =
            static_cast<double>(std::count(body.posed.begin(), body.posed.end(), 1));
        if (posedFrames < kDiscoveredMinFound_s * frameRate_hz_) {
            bodies_.pop_back();
            --counters_.discovered;
        }
    }
}

} // namespace edgetrack
