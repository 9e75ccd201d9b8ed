// Completion, follow step: a body's poses carried frame by frame into frames the tracker lost it
// in.
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

/// Frames before a lost pose whose points a chain that follows the body on starts with.
constexpr std::size_t kFollowWarmUp_frames = 10;
/// A point that sat in one place of a body's frame in this many frames carries its pose on.
constexpr std::uint32_t kFollowAnchorHits = 5;

} // namespace

// ---------------------------------------------------------------------------------------------
// Following a body frame to frame where the tracker lost it

void CalibrationCompletion::follow(const SessionBuffer& session, Body& body) {
    const std::size_t frames = session.frames();
    if (frames < 3 || body.markers_mm.size() < 3)
        return;
    // A place the chain matches: a marker of the model, or a point that has sat at one place in
    // the body's frame since the chain (or the frames before it) saw it first.
    struct Anchor {
        Vec3 sum_mm = Vec3::Zero();
        std::uint32_t hits = 0;
        bool marker = false;
        Vec3 place() const { return marker ? sum_mm : sum_mm / static_cast<double>(hits); }
    };
    std::vector<Anchor> anchors;
    std::vector<const Vec3*> taken;
    std::vector<Vec3> from, to;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    const double reach2 = config_.reach_mm * config_.reach_mm;
    std::vector<std::uint8_t> followed(frames, 0);
    std::vector<std::uint8_t> carried(frames, 0); // posed by a chain, from three points or two
    const Vec3 centre = extentOf(body.markers_mm).centre;

    // Where the other bodies found in frame f have their markers (rig frame): a point there is
    // theirs, as the joint tracker gives no point to two bodies.
    std::vector<Vec3> claimed;
    auto claim = [&](std::size_t f) { markersOfOthersAt(f, body, OtherBodies::All, claimed); };
    auto isClaimed = [&](const Vec3& p) { return nearAny(claimed, p, radius * radius); };
    // Points of frame f near the body and off every anchor become anchors; those on one count.
    auto collect = [&](std::size_t f, const RigidTransform& T_rig_from_body) {
        const RigidTransform T_body_from_rig = T_rig_from_body.inverse();
        claim(f);
        for (const Vec3& p : session.points(f)) {
            if (isClaimed(p))
                continue;
            const Vec3 q = T_body_from_rig.apply(p);
            const bool inReach =
                std::any_of(body.markers_mm.begin(), body.markers_mm.end(),
                            [&](const Vec3& m) { return (m - q).squaredNorm() <= reach2; });
            if (!inReach)
                continue;
            Anchor* nearest = nullptr;
            double best2 = spacing2;
            for (Anchor& a : anchors) {
                const double d2 = (a.place() - q).squaredNorm();
                if (d2 < best2) {
                    best2 = d2;
                    nearest = &a;
                }
            }
            if (nearest == nullptr) {
                if (anchors.size() < 2 * config_.maxMarkersPerModel)
                    anchors.push_back({q, 1, false});
                continue;
            }
            if (!nearest->marker && best2 <= radius * radius) {
                nearest->sum_mm += q;
                ++nearest->hits;
            }
        }
    };

    for (const int direction : {1, -1}) {
        auto next = [&](std::size_t f) {
            return direction > 0 ? f + 1 : f - 1; // wraps past 0 to SIZE_MAX: out of range
        };
        for (std::size_t step = 0; step + 1 < frames; ++step) {
            const std::size_t f = direction > 0 ? step : frames - 1 - step;
            const std::size_t g = next(f);
            if (!body.posed[f] || body.posed[g] || g >= frames)
                continue;
            // Warm up on the frames that led here, so that points which were already there count.
            anchors.clear();
            for (const Vec3& m : body.markers_mm)
                anchors.push_back({m, 0, true});
            std::size_t warm = f;
            for (std::size_t k = 0; k < kFollowWarmUp_frames; ++k) {
                const std::size_t before = direction > 0 ? warm - 1 : warm + 1;
                if (before >= frames || !body.posed[before])
                    break;
                warm = before;
            }
            for (std::size_t w = warm;; w = next(w)) {
                collect(w, body.T_rig_from_body[w]);
                if (w == f)
                    break;
            }
            // Then frame by frame on: the pose carried on at its speed, matched, fitted.
            std::size_t prev = f;
            std::size_t twoPointFrames = 0;
            for (std::size_t h = g; h < frames && !body.posed[h]; h = next(h)) {
                const std::size_t prevprev = direction > 0 ? prev - 1 : prev + 1;
                const bool speed = prevprev < frames && (body.posed[prevprev] || carried[prevprev]);
                const RigidTransform predicted =
                    speed ? extrapolate(body.T_rig_from_body[prevprev], session.time_s(prevprev),
                                        body.T_rig_from_body[prev], session.time_s(prev),
                                        session.time_s(h), centre)
                          : body.T_rig_from_body[prev];
                const std::span<const Vec3> points = session.points(h);
                from.clear();
                to.clear();
                taken.clear();
                claim(h);
                for (std::size_t k = 0; k < anchors.size(); ++k) {
                    const Anchor& a = anchors[k];
                    if (!a.marker && a.hits < kFollowAnchorHits)
                        continue;
                    const Vec3 there = predicted.apply(a.place());
                    const Vec3* match = nearestPoint(points, there, radius);
                    if (match == nullptr ||
                        std::find(taken.begin(), taken.end(), match) != taken.end() ||
                        isClaimed(*match))
                        continue;
                    taken.push_back(match);
                    from.push_back(a.place());
                    to.push_back(*match);
                }
                // The worst point out while any lies off the fit: a point of something passing
                // by that sat still against the body for a while.
                std::optional<RigidFit> fit =
                    fitDroppingWorst(from, to, config_.tracking.maxRms_mm);
                // Two points leave the turn about their line open: a marker leaving as another
                // comes into view. For a few frames the turn is taken from the pose carried on
                // (one frame's extrapolation is off by hundredths of a millimetre), so that the
                // marker coming into view is placed and can carry the pose on itself.
                if (fit) {
                    twoPointFrames = 0;
                } else if (from.size() == 2 && twoPointFrames < 2 * kFollowAnchorHits) {
                    const Vec3 line = from[1] - from[0];
                    Vec3 across = line.cross(Vec3::UnitX());
                    if (across.squaredNorm() < 0.1 * line.squaredNorm())
                        across = line.cross(Vec3::UnitY());
                    const Vec3 off = 0.5 * (from[0] + from[1]) + across.normalized() * line.norm();
                    from.push_back(off);
                    to.push_back(predicted.apply(off));
                    fit = fitRigid(from, to);
                    if (fit && ((fit->transform.apply(from[0]) - to[0]).norm() >
                                    config_.tracking.maxRms_mm ||
                                (fit->transform.apply(from[1]) - to[1]).norm() >
                                    config_.tracking.maxRms_mm))
                        fit.reset();
                    ++twoPointFrames;
                }
                if (!fit)
                    break;
                body.T_rig_from_body[h] = fit->transform;
                // Frames whose turn came from the extrapolation carry the chain on but measure
                // nothing.
                followed[h] = twoPointFrames == 0 ? 1 : 0;
                carried[h] = 1;
                collect(h, fit->transform);
                prev = h;
            }
        }
        // Frames followed one way are posed for the other way's chains too.
        for (std::size_t f = 0; f < frames; ++f)
            if (followed[f] && !body.posed[f]) {
                body.posed[f] = 1;
                ++counters_.framesFollowed;
            }
    }
}

} // namespace edgetrack
