// Completion, point tracks: the session's points linked frame to frame, and pieces tied by them.
#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <vector>

#include "core/calibration_completion.hpp"
#include "core/completion_geometry.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

using namespace completion_detail;

namespace {

/// A point continues a point of the frame before when it lies within this of where that point's
/// speed puts it (mm): a hand-held object moves a few millimetres a frame at 100 Hz.
constexpr double kTrackGate_mm = 10.0;
/// ...and every other candidate, on either side, lies at least this many times as far, and this
/// much farther (mm): markers are 12 mm apart or more, so a link that is not plain is not made.
constexpr double kTrackAmbiguityRatio = 2.0;
constexpr double kTrackAmbiguityMargin_mm = 3.0;
/// A track missing from fewer than this many frames in a row goes on where it reappears: a
/// marker behind a passing finger, for longer than the tracker predicts a lost body.
constexpr std::size_t kMaxTrackGap_frames = 11;
/// A track sits at one place in a body's frame when the body was posed in this many of its
/// frames and it lay within kTrackPlaceSpread_mm of its mean in each.
constexpr std::size_t kMinPlaceFrames = 5;
constexpr double kTrackPlaceSpread_mm = 1.0;
/// Markers of two pieces tied by tracks lie, once the pieces are registered, within this of
/// each other (mm): the layouts are refined over hundreds of poses.
constexpr double kTrackTieTolerance_mm = 1.0;
/// The markers that tie two pieces must fix the turn about any line through them: their widest
/// triangle is at least this tall over its longest side (mm).
constexpr double kMinTieHeight_mm = 5.0;

/// Calls \a both(place in a, place in b) for each track with a place in both \a a and \a b
/// (each sorted by track): one physical point, seen from both bodies' poses.
template <typename Places, typename Both>
void forEachSharedTrack(const Places& a, const Places& b, Both both) {
    for (std::size_t i = 0, j = 0; i < a.size() && j < b.size();) {
        if (a[i].track < b[j].track)
            ++i;
        else if (b[j].track < a[i].track)
            ++j;
        else
            both(a[i++].place_mm, b[j++].place_mm);
    }
}

/// The height (mm) of the tallest triangle of \a points over its longest side.
double widestTriangleHeight_mm(std::span<const Vec3> points) {
    double best = 0.0;
    for (std::size_t i = 0; i < points.size(); ++i)
        for (std::size_t j = i + 1; j < points.size(); ++j)
            for (std::size_t k = j + 1; k < points.size(); ++k) {
                const Vec3 ab = points[j] - points[i];
                const Vec3 ac = points[k] - points[i];
                const Vec3 bc = points[k] - points[j];
                const double longest = std::max({ab.norm(), ac.norm(), bc.norm()});
                if (longest <= 0.0)
                    continue;
                best = std::max(best, ab.cross(ac).norm() / longest);
            }
    return best;
}

} // namespace

void CalibrationCompletion::linkPointTracks(const SessionBuffer& session) {
    const std::size_t frames = session.frames();
    trackOf_.assign(session.points(), 0);
    // Where each track was last seen, and how far it moved a frame then.
    struct TrackEnd {
        Vec3 at_mm;
        Vec3 step_mm;
        std::size_t frame;
        std::uint32_t track;
    };
    std::vector<TrackEnd> ends, kept;
    // The nearest candidate and how far the next lies.
    struct TwoNearest {
        double best = std::numeric_limits<double>::infinity();
        double second = std::numeric_limits<double>::infinity();
        std::int32_t index = -1;
        void offer(double d, std::size_t i) {
            if (d < best) {
                second = best;
                best = d;
                index = static_cast<std::int32_t>(i);
            } else if (d < second) {
                second = d;
            }
        }
        bool plain() const {
            return best <= kTrackGate_mm && second >= kTrackAmbiguityRatio * best &&
                   second >= best + kTrackAmbiguityMargin_mm;
        }
    };
    std::vector<Vec3> predicted;
    std::vector<TwoNearest> ofEnd, ofPoint;
    std::vector<char> continued;
    std::uint32_t nextTrack = 0;
    for (std::size_t f = 0; f < frames; ++f) {
        const std::span<const Vec3> points = session.points(f);
        predicted.resize(ends.size());
        for (std::size_t e = 0; e < ends.size(); ++e)
            predicted[e] = ends[e].at_mm + ends[e].step_mm * static_cast<double>(f - ends[e].frame);
        // Mutual nearest, plainly nearer than every other candidate on both sides.
        ofEnd.assign(ends.size(), TwoNearest{});
        ofPoint.assign(points.size(), TwoNearest{});
        for (std::size_t j = 0; j < points.size(); ++j)
            for (std::size_t e = 0; e < ends.size(); ++e) {
                const double d = (points[j] - predicted[e]).norm();
                ofPoint[j].offer(d, e);
                ofEnd[e].offer(d, j);
            }
        kept.clear();
        continued.assign(ends.size(), 0);
        for (std::size_t j = 0; j < points.size(); ++j) {
            const std::int32_t e = ofPoint[j].index;
            const auto ue = static_cast<std::size_t>(e);
            TrackEnd next{points[j], Vec3::Zero(), f, 0};
            if (e >= 0 && ofEnd[ue].index == static_cast<std::int32_t>(j) && ofPoint[j].plain() &&
                ofEnd[ue].plain()) {
                next.track = ends[ue].track;
                next.step_mm =
                    (points[j] - ends[ue].at_mm) / static_cast<double>(f - ends[ue].frame);
                continued[ue] = 1;
            } else {
                next.track = nextTrack++;
            }
            trackOf_[session.firstPoint(f) + j] = next.track;
            kept.push_back(next);
        }
        // A track missing from a few frames may still be continued (a marker behind a finger).
        for (std::size_t e = 0; e < ends.size(); ++e)
            if (!continued[e] && f + 1 - ends[e].frame < kMaxTrackGap_frames)
                kept.push_back(ends[e]);
        ends.swap(kept);
    }
}

void CalibrationCompletion::placeTracks(const SessionBuffer& session, Body& body) const {
    // Every point within reach of the body, in its frame, by track.
    std::vector<std::pair<std::uint32_t, Vec3>> seen;
    const Extent ball = extentOf(body.markers_mm);
    const double reach2 = (ball.radius_mm + config_.reach_mm) * (ball.radius_mm + config_.reach_mm);
    for (std::size_t f = 0; f < session.frames(); ++f) {
        if (!body.posed[f])
            continue;
        const std::span<const Vec3> points = session.points(f);
        const RigidTransform bodyFromRig = body.T_rig_from_body[f].inverse();
        for (std::size_t i = 0; i < points.size(); ++i) {
            const Vec3 q = bodyFromRig.apply(points[i]);
            if ((q - ball.centre).squaredNorm() <= reach2)
                seen.emplace_back(trackOf_[session.firstPoint(f) + i], q);
        }
    }
    std::stable_sort(seen.begin(), seen.end(),
                     [](const auto& x, const auto& y) { return x.first < y.first; });
    body.trackPlaces.clear();
    for (std::size_t i = 0; i < seen.size();) {
        std::size_t j = i;
        Vec3 sum = Vec3::Zero();
        for (; j < seen.size() && seen[j].first == seen[i].first; ++j)
            sum += seen[j].second;
        const std::size_t n = j - i;
        const Vec3 mean = sum / static_cast<double>(n);
        double worst2 = 0.0;
        for (std::size_t k = i; k < j; ++k)
            worst2 = std::max(worst2, (seen[k].second - mean).squaredNorm());
        // A track that sat at one place in the body's frame: one of its markers, or a point
        // riding on it for a while.
        if (n >= kMinPlaceFrames && worst2 <= kTrackPlaceSpread_mm * kTrackPlaceSpread_mm)
            body.trackPlaces.push_back({seen[i].first, mean});
        i = j;
    }
}

std::optional<RigidTransform> CalibrationCompletion::tiedByTracks(const Body& a,
                                                                  const Body& b) const {
    // Places of one track in both frames (b's, a's): one physical point, seen from both pieces'
    // poses.
    std::vector<Vec3> from, to;
    forEachSharedTrack(a.trackPlaces, b.trackPlaces, [&](const Vec3& inA, const Vec3& inB) {
        from.push_back(inB);
        to.push_back(inA);
    });
    // The worst tie dropped while any lies off the fit: a track that jumped to another marker
    // in a frame it was not plain.
    const std::optional<RigidFit> fit = fitDroppingWorst(from, to, kTrackTieTolerance_mm);
    if (!fit || widestTriangleHeight_mm(from) < kMinTieHeight_mm)
        return std::nullopt;
    // Three tracks fit whatever three places of like sides they are: a track that jumped to a
    // marker as far from the other two as the one it left ties the pieces turned about them.
    // With nothing to check it against, the tie must agree as closely as layouts are known.
    if (from.size() == 3 && fit->rms_mm > kTriangleTie.precision_mm)
        return std::nullopt;
    return fit->transform;
}

std::size_t CalibrationCompletion::sharedMarkers(const Body& a, const Body& b) const {
    // The marker of a body a track's place lies on, if any: a place off every marker is a
    // glimpse or a point that rode along, which says nothing of the two being one object.
    auto markerAt = [](const Body& body, const Vec3& place_mm) -> std::optional<std::size_t> {
        for (std::size_t m = 0; m < body.markers_mm.size(); ++m)
            if ((body.markers_mm[m] - place_mm).norm() <= kTrackTieTolerance_mm)
                return m;
        return std::nullopt;
    };
    struct Shared {
        std::size_t ofA, ofB;
    };
    std::vector<Shared> shared;
    forEachSharedTrack(a.trackPlaces, b.trackPlaces, [&](const Vec3& inA, const Vec3& inB) {
        const std::optional<std::size_t> ma = markerAt(a, inA);
        const std::optional<std::size_t> mb = markerAt(b, inB);
        const bool known = std::any_of(shared.begin(), shared.end(),
                                       [&](const Shared& s) { return s.ofA == ma || s.ofB == mb; });
        if (ma && mb && !known)
            shared.push_back({*ma, *mb});
    });
    // One marker on both is one track that jumped, as markers of two objects passing close can;
    // two or more, as far apart in both layouts, are the same points. The largest such set.
    std::size_t most = 0;
    for (std::size_t seed = 0; seed < shared.size(); ++seed) {
        std::vector<Shared> agreeing{shared[seed]};
        for (std::size_t k = 0; k < shared.size(); ++k) {
            if (k == seed)
                continue;
            const bool fits = std::all_of(agreeing.begin(), agreeing.end(), [&](const Shared& s) {
                const double inA = (a.markers_mm[s.ofA] - a.markers_mm[shared[k].ofA]).norm();
                const double inB = (b.markers_mm[s.ofB] - b.markers_mm[shared[k].ofB]).norm();
                return std::abs(inA - inB) <= kTrackTieTolerance_mm;
            });
            if (fits)
                agreeing.push_back(shared[k]);
        }
        most = std::max(most, agreeing.size());
    }
    return most;
}

} // namespace edgetrack
