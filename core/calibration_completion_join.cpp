// Completion, join step: pieces of one body found as one by motion, by point tracks or by layout.
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

/// Relative poses tried as the consensus of two objects' motion.
constexpr std::size_t kConsensusCandidates = 32;
/// A piece leaving and another coming into view within this many frames is a handover whose
/// motion two pieces tied by a triangle must explain.
constexpr std::size_t kSmoothGap_frames = 10;
/// How much faster than either piece was ever seen to move a body may seem to move across a
/// handover.
constexpr double kSpeedMargin = 1.5;
/// Two bodies found together are two objects when the one's centre lies, in most of those
/// frames, farther than this many same-body tolerances from where it lies in the other's frame
/// (component-wise median).
constexpr double kWanderFactor = 2.0;

/// Markers and glimpses of one body, as one list of places (its frame, mm): markers first.
struct SeenPlaces {
    std::vector<Vec3> places_mm;
    std::size_t markers = 0;

    SeenPlaces(std::span<const Vec3> markers_mm, std::span<const Vec3> glimpses_mm)
        : places_mm(markers_mm.begin(), markers_mm.end())
        , markers(markers_mm.size()) {
        places_mm.insert(places_mm.end(), glimpses_mm.begin(), glimpses_mm.end());
    }
    /// Whether \a part placed by \a T_whole_from_part puts one or more of its markers on markers
    /// and one or more on glimpses: a tie that the glimpses made. One on a marker anchors the tie
    /// to the body (a car's side seen beside its roof, sharing the corner marker: random_object
    /// seed 279); glimpses alone may be another object that rested against it for a while (four
    /// objects of the random_objects sweep were joined to another that way).
    bool tiedByGlimpses(std::span<const Vec3> part, const RigidTransform& T_whole_from_part) const {
        std::size_t onMarkers = 0, onGlimpses = 0;
        for (const Vec3& m : part) {
            const Vec3* hit =
                nearestPoint(places_mm, T_whole_from_part.apply(m), kRegistrationTolerance_mm);
            if (hit && hit < places_mm.data() + markers)
                ++onMarkers;
            else if (hit)
                ++onGlimpses;
        }
        return onMarkers >= 1 && onGlimpses > 0;
    }
};

/// The placement of \a part (its markers, mm) on another body's markers and glimpses that puts at
/// least four of its markers on them, one or more on markers and one or more on glimpses, and no
/// other placement as many; or, with \a triangle, that puts three on them by a triangle like no
/// other of either; none when there is no such placement.
std::optional<RigidTransform> placeOnGlimpses(std::span<const Vec3> part, const SeenPlaces& seen,
                                              double sideTolerance_mm, bool triangle) {
    if (seen.places_mm.size() == seen.markers)
        return std::nullopt;
    std::optional<RigidTransform> placed;
    if (triangle) {
        placed = soleSharedTriangle(part, seen.places_mm, kTriangleTie);
    } else {
        const Registration r =
            registerLayout(part, seen.places_mm, sideTolerance_mm, kRegistrationTolerance_mm);
        if (r.matched >= 4 && r.matched > r.runnerUp)
            placed = r.T_whole_from_part;
    }
    if (!placed || !seen.tiedByGlimpses(part, *placed))
        return std::nullopt;
    return placed;
}

/// Whether \a a and \a b track alike: one layout (sameLayout), with the same S_min.
bool tracksAlike(const MarkerModel& a, const MarkerModel& b) {
    return a.sMin == b.sMin && a.sameShapeAs == b.sameShapeAs && sameLayout(a, b);
}

} // namespace

// ---------------------------------------------------------------------------------------------
// Joining the pieces of one body

bool CalibrationCompletion::joinBodies(const SessionBuffer& session) {
    bool joined = false;
    const std::size_t frames = session.frames();
    std::size_t alive = 0;
    for (std::size_t b = 0; b < bodies_.size(); ++b)
        alive += bodies_[b].alive ? 1u : 0u;
    if (alive < 2)
        return false;
    // Each body tracked alone, with S_min as the joint tracker has it: the bodies that are alive
    // come first (trackAll sorted them), so their models are those of the joint tracking.
    // Tracked alone only when a pair needs it: most pairs are told apart by the joint tracking,
    // and each lone pass costs as much as the joint one.
    // The models of this round's tracking: following has moved no marker since (S_min, computed
    // for every pair of bodies, is the costly part).
    const std::vector<MarkerModel>& models = roundModels_;
    if (models.size() != alive)
        return false;
    // Pieces are registered by their layouts, which must then be as exact as the poses allow:
    // markers measured as means of points placed by poses of three or four markers lie up to a
    // millimetre off (a ring's two pieces sharing five markers put two of them beyond the 0.5 mm
    // of a layout match: random_objects seed 6).
    // Only pairs the joint tracking did not tell apart need them: each body's are made at the
    // first such pair, or before a join changes it, from its poses as the round found them.
    std::vector<char> prepared(alive, 0);
    auto prepare = [&](std::size_t b) {
        if (prepared[b])
            return;
        prepared[b] = 1;
        bodies_[b].refined_mm = refinedMarkers(session, bodies_[b]);
        placeTracks(session, bodies_[b]);
    };
    std::vector<char> trackedAlone(alive, 0);
    auto trackAlone = [&](std::size_t b) {
        if (trackedAlone[b])
            return;
        trackedAlone[b] = 1;
        // Its lone poses depend on its model alone: unchanged since a round before, they stand.
        Body& body = bodies_[b];
        if (body.trackedAloneAs && tracksAlike(*body.trackedAloneAs, models[b]))
            return;
        body.trackedAloneAs.emplace(config_.maxMarkersPerModel).assign(models[b]);
        std::vector<MarkerModel> alone;
        alone.emplace_back(config_.maxMarkersPerModel).assign(models[b]);
        alone.back().id = 0;
        const PoseTrack track{&bodies_[b].posedAlone, &bodies_[b].T_rig_from_body_alone};
        trackBothWays(session, alone, std::span(&track, 1));
    };
    std::vector<RigidTransform> relative;
    std::vector<std::size_t> sharedFrames;
    for (std::size_t a = 0; a < bodies_.size(); ++a) {
        for (std::size_t b = a + 1; b < bodies_.size(); ++b) {
            Body& into = bodies_[a];
            Body& from = bodies_[b];
            if (!into.alive || !from.alive)
                continue;
            const Extent ball = extentOf(from.markers_mm);
            // b's frame to a's in every frame both were found (jointly, or each alone), and the
            // relative pose most of them agree with: one body keeps one relative pose.
            struct Consensus {
                std::size_t shared = 0;
                std::optional<RigidTransform> T_into_from_from;
            };
            auto consensus = [&](bool alone) {
                Consensus c;
                relative.clear();
                sharedFrames.clear();
                for (std::size_t f = 0; f < frames; ++f) {
                    if (alone ? into.posedAlone[f] && from.posedAlone[f]
                              : into.posed[f] && from.posed[f]) {
                        relative.push_back(alone ? into.T_rig_from_body_alone[f].inverse() *
                                                       from.T_rig_from_body_alone[f]
                                                 : into.T_rig_from_body[f].inverse() *
                                                       from.T_rig_from_body[f]);
                        sharedFrames.push_back(f);
                    }
                }
                c.shared = relative.size();
                if (c.shared < config_.minSharedFrames)
                    return c;
                // The relative pose most frames come near is only a start: a pose from three or
                // four markers turns by a degree or two, which moves a far marker by millimetres.
                // The judgement is the fit of both layouts as one to every shared frame's points.
                const Agreement most = mostAgreed(relative, ball, config_.sameBodyTolerance_mm,
                                                  relative.size() / kConsensusCandidates);
                // Most frames must come near one relative pose at all: a piece of a self-similar
                // layout found alone on the other's points fits there too, but by a relative pose
                // that changes from frame to frame.
                if (2 * most.agree < c.shared)
                    return c;
                const OneBodyFit fit =
                    fitAsOneBody(session, sharedFrames, into, from, alone, relative[most.index]);
                if (static_cast<double>(fit.framesFitting) >=
                    config_.sameBodyShare * static_cast<double>(c.shared))
                    c.T_into_from_from = fit.T_into_from_from;
                return c;
            };
            // Found together often by the joint tracker, they are one body only if they move as
            // one; two alike objects would each be found alone on the same points.
            const Consensus joint = consensus(false);
            std::optional<RigidTransform> T_into_from_from = joint.T_into_from_from;
            if (T_into_from_from) {
                ++counters_.joinedByMotion;
            } else if (joint.shared >= config_.minSharedFrames) {
                // Found together often, and not as one body. Two objects, when the one's centre
                // wanders about in the other's frame: a piece of one body found now in one
                // attitude, now in another (a square of four markers) turns about its own centre.
                if (wandersApart(into, from) && !into.isApartFrom(from.id)) {
                    into.apartFrom.push_back(from.id);
                    from.apartFrom.push_back(into.id);
                }
            } else {
                // Seldom found at once jointly: pieces that share markers, whose shared points the
                // joint tracker gives to one of them. Each found alone, they move as one.
                trackAlone(a);
                trackAlone(b);
                prepare(a);
                prepare(b);
                // Or one may be a piece of the other that the tracker gave the other's points to,
                // or the two may share markers but never be in view together. Four or more
                // markers in one place of the other's layout tie them, unless a self-similar
                // layout lets them lie as well in another place.
                auto layoutPlacement = [&]() -> std::optional<RigidTransform> {
                    const Registration r =
                        registerLayout(from.refined_mm, into.refined_mm,
                                       config_.sameBodyTolerance_mm, kRegistrationTolerance_mm);
                    if (r.matched >= 4 && r.matched > r.runnerUp)
                        return r.T_whole_from_part;
                    return std::nullopt;
                };
                const Consensus lone = consensus(true);
                // Found alone at once, in many frames, apart and not where the tie puts them:
                // two objects in view together, whose layouts only look alike. (sharedFrames
                // holds the frames consensus(true) just listed; nothing below refills it.)
                auto seenApartFrom = [&](const RigidTransform& tie) {
                    return framesSeenApart(into.T_rig_from_body_alone, from.T_rig_from_body_alone,
                                           sharedFrames, extentOf(into.markers_mm), ball, tie,
                                           config_.sameBodyTolerance_mm) >= config_.minSharedFrames;
                };
                // The ties below are likenesses of layout, with no frame that poses both pieces.
                // One is taken only for pieces not found alone together often (those found so
                // that did not move as one are not tied by a likeness), and only when the body the
                // two would make moves on smoothly wherever one piece leaves view and the other
                // comes in: a likeness between two objects puts the one body in two places at once.
                auto tieByLikeness = [&](auto&& place) -> std::optional<RigidTransform> {
                    if (lone.shared >= config_.minSharedFrames)
                        return std::nullopt;
                    const std::optional<RigidTransform> tied = place();
                    if (!tied || !movesOnSmoothly(session, into, from, *tied))
                        return std::nullopt;
                    return tied;
                };
                // Or one piece's markers lie on the other's markers and on places where the
                // other glimpsed points for a few frames: the markers it holds that the other
                // saw too briefly to learn (a body seen still against another for a moment is
                // glimpsed so too).
                auto glimpsedPlacement = [&](bool triangle) -> std::optional<RigidTransform> {
                    if (const std::optional<RigidTransform> onInto = placeOnGlimpses(
                            from.refined_mm, SeenPlaces(into.refined_mm, into.glimpsed_mm),
                            config_.sameBodyTolerance_mm, triangle))
                        return onInto;
                    if (const std::optional<RigidTransform> onFrom = placeOnGlimpses(
                            into.refined_mm, SeenPlaces(from.refined_mm, from.glimpsed_mm),
                            config_.sameBodyTolerance_mm, triangle))
                        return onFrom->inverse();
                    return std::nullopt;
                };
                // Or they share exactly three markers and are never in view together beyond
                // them: the triangle is their only tie, taken only when no other triangle of
                // either is like it.
                auto sharedTriangle = [&]() -> std::optional<RigidTransform> {
                    return soleSharedTriangle(from.refined_mm, into.refined_mm, kTriangleTie);
                };
                if ((T_into_from_from = lone.T_into_from_from))
                    ++counters_.joinedByMotion;
                else if ((T_into_from_from = tiedByTracks(into, from)) &&
                         movesOnSmoothly(session, into, from, *T_into_from_from))
                    ++counters_.joinedByTracks;
                else if ((T_into_from_from = layoutPlacement()) &&
                         !seenApartFrom(*T_into_from_from))
                    ++counters_.joinedByLayout;
                else if ((T_into_from_from =
                              tieByLikeness([&] { return glimpsedPlacement(false); })))
                    ++counters_.joinedByLayout;
                else if ((T_into_from_from = tieByLikeness(sharedTriangle)))
                    ++counters_.joinedByLayout;
                else if ((T_into_from_from =
                              tieByLikeness([&] { return glimpsedPlacement(true); })))
                    ++counters_.joinedByLayout;
            }
            if (!T_into_from_from)
                continue;
            prepare(a);
            prepare(b);
            const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
            // The piece's markers it does not have yet; its refined layout grows alike, for the
            // pairs still to come this round.
            const auto addNew = [&](std::vector<Vec3>& to, std::span<const Vec3> added) {
                for (const Vec3& m : added) {
                    const Vec3 moved = T_into_from_from->apply(m);
                    const bool known = std::any_of(to.begin(), to.end(), [&](const Vec3& n) {
                        return (n - moved).squaredNorm() < spacing2;
                    });
                    if (known)
                        continue;
                    if (to.size() == config_.maxMarkersPerModel)
                        return false;
                    to.push_back(moved);
                }
                return true;
            };
            if (!addNew(into.markers_mm, from.markers_mm))
                ++counters_.markerOverflow;
            addNew(into.refined_mm, from.refined_mm);
            // Its co-visibility is measured again from the poses.
            into.edges.clear();
            const RigidTransform fromFromInto = T_into_from_from->inverse();
            into.posedByJoin.resize(frames, 0);
            for (std::size_t f = 0; f < frames; ++f)
                if (!into.posed[f] && from.posed[f]) {
                    into.posed[f] = 1;
                    into.posedByJoin[f] = 1;
                    into.T_rig_from_body[f] = from.T_rig_from_body[f] * fromFromInto;
                }
            from.alive = false;
            joined = true;
        }
    }
    return joined;
}

CalibrationCompletion::OneBodyFit CalibrationCompletion::fitAsOneBody(
    const SessionBuffer& session, std::span<const std::size_t> sharedFrames, const Body& a,
    const Body& b, bool alone, const RigidTransform& T_a_from_b) const {
    OneBodyFit result;
    result.T_into_from_from = T_a_from_b;
    const auto& posesA = alone ? a.T_rig_from_body_alone : a.T_rig_from_body;
    const auto& posesB = alone ? b.T_rig_from_body_alone : b.T_rig_from_body;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    const std::size_t nA = a.markers_mm.size();
    const std::size_t nB = b.markers_mm.size();
    std::vector<Vec3> layout_a_mm(nA + nB);
    // b's markers that are a's too (under T_a_from_b): the index of a's, or -1 for b's own.
    std::vector<std::int32_t> sameAs(nB);
    std::vector<Vec3> from, to, sums(nB);
    std::vector<std::size_t> which, ownAt;
    std::vector<std::uint32_t> counts(nB);
    std::vector<const Vec3*> matchedA(nA);
    auto nearest = [&](std::span<const Vec3> points, const Vec3& there) {
        return nearestPoint(points, there, radius);
    };
    // Alternating least squares, as refine() does for one body: the union fitted to each frame,
    // then b's markers placed in a's frame by those fits.
    constexpr int kIterations = 3;
    for (int iteration = 0; iteration < kIterations; ++iteration) {
        for (std::size_t k = 0; k < nA; ++k)
            layout_a_mm[k] = a.markers_mm[k];
        for (std::size_t k = 0; k < nB; ++k) {
            layout_a_mm[nA + k] = result.T_into_from_from.apply(b.markers_mm[k]);
            sameAs[k] = -1;
            for (std::size_t m = 0; m < nA; ++m)
                if ((a.markers_mm[m] - layout_a_mm[nA + k]).squaredNorm() < spacing2)
                    sameAs[k] = static_cast<std::int32_t>(m);
        }
        std::fill(sums.begin(), sums.end(), Vec3::Zero());
        std::fill(counts.begin(), counts.end(), 0U);
        result.framesFitting = 0;
        for (const std::size_t f : sharedFrames) {
            const std::span<const Vec3> points = session.points(f);
            from.clear();
            to.clear();
            which.clear();
            ownAt.clear();
            for (std::size_t k = 0; k < nA; ++k) {
                matchedA[k] = nearest(points, posesA[f].apply(a.markers_mm[k]));
                if (matchedA[k]) {
                    from.push_back(layout_a_mm[k]);
                    to.push_back(*matchedA[k]);
                }
            }
            const std::size_t ofA = from.size();
            // b's markers where b's pose puts them: its own join the fit, a shared one must be
            // the point a's pose found for it.
            std::size_t ofB = 0;
            bool consistent = true;
            for (std::size_t k = 0; k < nB && consistent; ++k) {
                const Vec3* p = nearest(points, posesB[f].apply(b.markers_mm[k]));
                if (!p)
                    continue;
                if (sameAs[k] >= 0) {
                    const Vec3* pa = matchedA[static_cast<std::size_t>(sameAs[k])];
                    if (pa && pa != p)
                        consistent = false;
                    if (!pa) {
                        from.push_back(a.markers_mm[static_cast<std::size_t>(sameAs[k])]);
                        to.push_back(*p);
                    }
                    ++ofB;
                    continue;
                }
                if (std::any_of(matchedA.begin(), matchedA.end(),
                                [p](const Vec3* q) { return q == p; })) {
                    consistent = false; // a point of one of a's markers, not where b's own is
                    continue;
                }
                which.push_back(k);
                ownAt.push_back(from.size());
                from.push_back(layout_a_mm[nA + k]);
                to.push_back(*p);
                ++ofB;
            }
            if (!consistent || ofA < 2 || ofB < 2)
                continue;
            const std::optional<RigidFit> fit = fitRigid(from, to);
            if (!fit)
                continue;
            bool fits = true;
            for (std::size_t i = 0; i < from.size() && fits; ++i)
                fits =
                    (fit->transform.apply(from[i]) - to[i]).norm() <= config_.sameBodyTolerance_mm;
            if (!fits)
                continue;
            ++result.framesFitting;
            const RigidTransform aFromRig = fit->transform.inverse();
            for (std::size_t i = 0; i < which.size(); ++i) {
                sums[which[i]] += aFromRig.apply(to[ownAt[i]]);
                ++counts[which[i]];
            }
        }
        // b's own markers, and its shared ones where a has them, place b in a's frame.
        from.clear();
        to.clear();
        for (std::size_t k = 0; k < nB; ++k) {
            if (counts[k] > 0) {
                from.push_back(b.markers_mm[k]);
                to.push_back(sums[k] / static_cast<double>(counts[k]));
            } else if (sameAs[k] >= 0) {
                from.push_back(b.markers_mm[k]);
                to.push_back(a.markers_mm[static_cast<std::size_t>(sameAs[k])]);
            }
        }
        const std::optional<RigidFit> placed = fitRigid(from, to);
        if (!placed || iteration + 1 == kIterations)
            break;
        result.T_into_from_from = placed->transform;
    }
    return result;
}

bool CalibrationCompletion::wandersApart(const Body& a, const Body& b) const {
    const Vec3 centre_b = extentOf(b.markers_mm).centre;
    std::vector<Vec3> centres_a;
    for (std::size_t f = 0; f < a.posed.size() && f < b.posed.size(); ++f)
        if (a.posed[f] && b.posed[f])
            centres_a.push_back(
                a.T_rig_from_body[f].inverse().apply(b.T_rig_from_body[f].apply(centre_b)));
    if (centres_a.size() < config_.minSharedFrames)
        return false;
    std::vector<double> values(centres_a.size());
    Vec3 middle;
    for (Eigen::Index axis = 0; axis < 3; ++axis) {
        for (std::size_t i = 0; i < centres_a.size(); ++i)
            values[i] = centres_a[i][axis];
        middle[axis] = medianOf(values);
    }
    for (std::size_t i = 0; i < centres_a.size(); ++i)
        values[i] = (centres_a[i] - middle).norm();
    return medianOf(values) > kWanderFactor * config_.sameBodyTolerance_mm;
}

bool CalibrationCompletion::movesOnSmoothly(const SessionBuffer& session, const Body& a,
                                            const Body& b, const RigidTransform& T_a_from_b) const {
    const std::size_t frames = session.frames();
    const Extent ball = extentOf(a.markers_mm);
    const RigidTransform T_b_from_a = T_a_from_b.inverse();
    // a's pose in frame f, from whichever piece was found there alone.
    auto poseOfA = [&](std::size_t f) {
        return a.posedAlone[f] ? a.T_rig_from_body_alone[f]
                               : b.T_rig_from_body_alone[f] * T_b_from_a;
    };
    // The fastest either piece was seen to move between consecutive frames (mm/s at a's ball).
    double fastest_mm_per_s = 0.0;
    for (std::size_t f = 1; f < frames; ++f) {
        const double dt_s = session.time_s(f) - session.time_s(f - 1);
        if (dt_s <= 0.0)
            continue;
        for (const Body* piece : {&a, &b})
            if (piece->posedAlone[f] && piece->posedAlone[f - 1])
                fastest_mm_per_s = std::max(
                    fastest_mm_per_s, disagreement_mm(poseOfA(f - 1), poseOfA(f), ball) / dt_s);
    }
    // Each frame where one piece alone was found, and the next frame within kSmoothGap_frames
    // where only the other was: the one body must get there at no more than that speed.
    std::size_t handovers = 0, smooth = 0;
    auto only = [&](const Body& piece, const Body& other, std::size_t f) {
        return piece.posedAlone[f] && !other.posedAlone[f];
    };
    for (const auto& [leaving, coming] :
         {std::pair<const Body*, const Body*>{&a, &b}, std::pair<const Body*, const Body*>{&b, &a}})
        for (std::size_t f = 0; f < frames; ++f) {
            if (!only(*leaving, *coming, f))
                continue;
            for (std::size_t g = f + 1; g < frames && g <= f + kSmoothGap_frames; ++g) {
                if (only(*leaving, *coming, g))
                    break; // the leaving piece is still there: the handover is later
                if (!only(*coming, *leaving, g))
                    continue;
                ++handovers;
                const double limit_mm =
                    kSpeedMargin * fastest_mm_per_s * (session.time_s(g) - session.time_s(f)) +
                    2.0 * config_.sameBodyTolerance_mm;
                if (disagreement_mm(poseOfA(f), poseOfA(g), ball) <= limit_mm)
                    ++smooth;
                break;
            }
        }
    return static_cast<double>(smooth) >= config_.sameBodyShare * static_cast<double>(handovers);
}

} // namespace edgetrack
