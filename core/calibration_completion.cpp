// Completion of a calibration session: the provisional models tracked through all its frames.
#include "core/calibration_completion.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <numeric>
#include <optional>

#include "core/marker_set.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

namespace {

constexpr std::size_t kCellBits = 16;
constexpr std::size_t kCells = std::size_t{1} << kCellBits;
/// Relative poses tried as the consensus of two objects' motion.
constexpr std::size_t kConsensusCandidates = 32;
constexpr double kDegree = std::numbers::pi / 180.0;
/// Directions a place was seen from that are kept (thinned to half the same-view angle).
constexpr std::size_t kMaxViewDirections = 256;
/// Points within this many site radii of a marker's place are that marker when refining.
constexpr double kRefineRadiusFactor = 1.5;
/// A body's pose is carried on across at most this many frames without either piece.
constexpr std::size_t kHandoverGap_frames = 10;
/// Frames over which a piece's speed and turn rate are measured before it leaves.
constexpr std::size_t kSpeedBaseline_frames = 3;
/// Handovers that must agree before two pieces that are never seen together are joined.
constexpr std::size_t kMinHandovers = 3;
/// Frames before a lost pose whose points a chain that follows the body on starts with.
constexpr std::size_t kFollowWarmUp_frames = 10;
/// A point that sat in one place of a body's frame in this many frames carries its pose on.
constexpr std::uint32_t kFollowAnchorHits = 5;
/// Points no body explains are followed this long, from a frame this often, for rigid sets...
constexpr std::size_t kDiscoveryWindow_frames = 30;
constexpr std::size_t kDiscoveryStride_frames = 25;
/// ...found frame to frame within this of where their speed puts them (mm)...
constexpr double kDiscoveryGate_mm = 4.0;
/// ...that move at least this far in that time (mm); such a set is a body if the tracker then
/// finds it in this much of the session (s).
constexpr double kDiscoveryMotion_mm = 3.0;
constexpr double kDiscoveredMinFound_s = 1.0;
/// Two models' markers are the same marker when one model registered onto the other puts them
/// this close (mm): models are measured over hundreds of frames to well under 0.1 mm, and at 1 mm
/// four markers of one random layout already land on four of another by chance.
constexpr double kRegistrationTolerance_mm = 0.5;
/// Congruent triangle pairs a registration tries at most: a self-similar layout (a sphere of many
/// markers) has thousands, and the first few hundred already show that it registers several ways.
constexpr std::size_t kRegistrationCandidates = 20000;

struct Extent {
    Vec3 centre = Vec3::Zero();
    double radius_mm = 0.0;
};

Extent extentOf(std::span<const Vec3> markers_mm) {
    Extent e;
    if (markers_mm.empty())
        return e;
    for (const Vec3& m : markers_mm)
        e.centre += m;
    e.centre /= static_cast<double>(markers_mm.size());
    for (const Vec3& m : markers_mm)
        e.radius_mm = std::max(e.radius_mm, (m - e.centre).norm());
    return e;
}

/// How far apart two transforms put the points of a ball (centre, radius): an upper bound (mm).
double disagreement_mm(const RigidTransform& a, const RigidTransform& b, const Extent& ball) {
    return (a.apply(ball.centre) - b.apply(ball.centre)).norm() +
           ball.radius_mm * rotationAngleBetween_rad(a.rotation, b.rotation);
}

/// The mean of transforms that agree closely: mean rotation (sign-aligned quaternions) about the
/// ball's centre, and the mean place of that centre.
RigidTransform meanTransform(std::span<const RigidTransform> transforms, const Extent& ball) {
    Eigen::Vector4d q = Eigen::Vector4d::Zero();
    Vec3 centre = Vec3::Zero();
    const Quat& reference = transforms.front().rotation;
    for (const RigidTransform& t : transforms) {
        Eigen::Vector4d c = t.rotation.coeffs();
        if (c.dot(reference.coeffs()) < 0.0)
            c = -c;
        q += c;
        centre += t.apply(ball.centre);
    }
    RigidTransform mean;
    mean.rotation = Quat(q.normalized());
    centre /= static_cast<double>(transforms.size());
    mean.translation_mm = centre - mean.rotation * ball.centre;
    return mean;
}

/// The transform that puts the most markers of \a part onto markers of \a whole (within
/// \a tolerance_mm), from congruent triangles; how many it puts there; and how many the best
/// transform that differs from it puts there (a self-similar layout registers in several ways).
struct Registration {
    RigidTransform wholeFromPart;
    std::size_t matched = 0;
    std::size_t runnerUp = 0;
};
Registration registerLayout(std::span<const Vec3> part, std::span<const Vec3> whole,
                            double tolerance_mm, double matchTolerance_mm) {
    Registration best;
    const std::size_t n = part.size();
    const std::size_t m = whole.size();
    if (n < 3 || m < 3)
        return best;
    const double tol2 = matchTolerance_mm * matchTolerance_mm;
    std::vector<Vec3> from, to;
    std::vector<std::uint32_t> onto(n);
    constexpr std::uint32_t kNone = ~0U;
    auto matchOn = [&](const RigidTransform& t) {
        from.clear();
        to.clear();
        for (std::size_t i = 0; i < n; ++i) {
            const Vec3 moved = t.apply(part[i]);
            onto[i] = kNone;
            for (std::uint32_t w = 0; w < m; ++w)
                if ((moved - whole[w]).squaredNorm() <= tol2) {
                    from.push_back(part[i]);
                    to.push_back(whole[w]);
                    onto[i] = w;
                    break;
                }
        }
        return from.size();
    };
    // The whole's pairs by distance, so that each side of a part's triangle finds its
    // counterparts by a binary search rather than by trying every pair.
    struct Pair {
        double d_mm;
        std::uint32_t x, y;
    };
    std::vector<Pair> pairs;
    pairs.reserve(m * (m - 1));
    for (std::uint32_t x = 0; x < m; ++x)
        for (std::uint32_t y = 0; y < m; ++y)
            if (x != y)
                pairs.push_back({(whole[x] - whole[y]).norm(), x, y});
    std::sort(pairs.begin(), pairs.end(),
              [](const Pair& l, const Pair& r) { return l.d_mm < r.d_mm; });
    auto near = [&](double d_mm) {
        const auto lo = std::lower_bound(pairs.begin(), pairs.end(), d_mm - tolerance_mm,
                                         [](const Pair& p, double v) { return p.d_mm < v; });
        const auto hi = std::upper_bound(lo, pairs.end(), d_mm + tolerance_mm,
                                         [](double v, const Pair& p) { return v < p.d_mm; });
        return std::span<const Pair>(lo, hi);
    };
    // Each registration found, as which part marker lies on which whole one.
    std::vector<std::vector<std::uint32_t>> found;
    std::vector<std::uint32_t> bestOnto;
    // Every well-spread triangle of the part against every congruent one of the whole: the
    // answer must not depend on the order in which either layout lists its markers.
    std::size_t candidates = 0;
    for (std::size_t i = 0; i < n && candidates < kRegistrationCandidates; ++i)
        for (std::size_t j = i + 1; j < n && candidates < kRegistrationCandidates; ++j) {
            const std::span<const Pair> sidesAB = near((part[i] - part[j]).norm());
            if (sidesAB.empty())
                continue;
            for (std::size_t k = j + 1; k < n; ++k) {
                const Vec3 &a = part[i], &b = part[j], &c = part[k];
                const double twiceArea = (b - a).cross(c - a).norm();
                const double longest = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()});
                if (longest <= 0.0 || twiceArea / longest < 8.0)
                    continue;
                const double dac = (a - c).norm(), dbc = (b - c).norm();
                for (const Pair& xy : sidesAB)
                    for (std::uint32_t z = 0; z < m; ++z) {
                        if (z == xy.x || z == xy.y ||
                            std::abs((whole[xy.x] - whole[z]).norm() - dac) > tolerance_mm ||
                            std::abs((whole[xy.y] - whole[z]).norm() - dbc) > tolerance_mm)
                            continue;
                        ++candidates;
                        const Vec3 tri[3] = {a, b, c};
                        const Vec3 target[3] = {whole[xy.x], whole[xy.y], whole[z]};
                        const std::optional<RigidFit> seed = fitRigid(tri, target);
                        if (!seed || matchOn(seed->transform) < 3)
                            continue;
                        // Every marker it matches, fitted at once, then matched again.
                        const std::optional<RigidFit> all = fitRigid(from, to);
                        const RigidTransform t = all ? all->transform : seed->transform;
                        const std::size_t count = matchOn(t);
                        if (std::find(found.begin(), found.end(), onto) == found.end())
                            found.push_back(onto);
                        if (count > best.matched) {
                            best.matched = count;
                            best.wholeFromPart = t;
                            bestOnto = onto;
                        }
                    }
            }
        }
    if (best.matched == 0)
        return best;
    // Another registration is one that shares fewer than three of the best's pairs: one that
    // shares three is the same placement, matched a little differently.
    for (const std::vector<std::uint32_t>& other : found) {
        std::size_t count = 0, common = 0;
        for (std::size_t i = 0; i < n; ++i) {
            count += other[i] != kNone ? 1U : 0U;
            common += other[i] != kNone && other[i] == bestOnto[i] ? 1U : 0U;
        }
        if (common < 3)
            best.runnerUp = std::max(best.runnerUp, count);
    }
    return best;
}

} // namespace

CalibrationCompletion::CalibrationCompletion(const CompletionConfig& config)
    : config_(config) {
    valid_ = config.maxModels > 0 && config.maxMarkersPerModel >= 4 &&
             config.maxMarkersPerModel <= MarkerSet::kCapacity && config.siteRadius_mm > 0.0 &&
             config.maxSites > 0 && config.minModelMarkers >= 4 && config.maxRounds > 0 &&
             config.minSeenShare >= 0.0 && config.minSeenShare <= 1.0;
    if (!valid_)
        return;
    sites_.reserve(config.maxSites);
    cellHead_.assign(kCells, -1);
}

std::size_t CalibrationCompletion::run(const SessionBuffer& session,
                                       std::span<const MarkerModel> seeds,
                                       std::span<MarkerModel> out) {
    counters_ = {};
    bodies_.clear();
    const std::size_t frames = session.frames();
    if (!valid_ || frames < 2)
        return 0;
    const double span_s = session.time_s(frames - 1) - session.time_s(0);
    frameRate_hz_ = span_s > 0.0 ? static_cast<double>(frames - 1) / span_s : 100.0;

    // Largest seeds first: the tracker serves the bodies in order, and a body's markers are best
    // claimed by its largest model.
    std::vector<std::size_t> order(seeds.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
        return seeds[a].markers_model_mm.size() > seeds[b].markers_model_mm.size();
    });
    for (const std::size_t s : order) {
        const MarkerModel& seed = seeds[s];
        if (seed.markers_model_mm.size() < 4)
            continue;
        if (bodies_.size() == config_.maxModels) {
            ++counters_.modelOverflow;
            continue;
        }
        Body& body = bodies_.emplace_back();
        for (const Vec3& m : seed.markers_model_mm) {
            if (body.markers_mm.size() == config_.maxMarkersPerModel) {
                ++counters_.markerOverflow;
                break;
            }
            body.markers_mm.push_back(m);
        }
        for (const ModelEdge& e : seed.edges)
            if (e.from < body.markers_mm.size() && e.to < body.markers_mm.size())
                body.edges.emplace_back(e.from, e.to);
        body.T_rig_from_body.resize(frames);
        body.posed.assign(frames, 0);
        ++counters_.seeds;
    }

    // Bodies the online stage never made a model of: moving rigid sets of points no seed explains.
    trackAll(session);
    discoverBodies(session);

    bool changed = true;
    for (int round = 0; round < config_.maxRounds && changed; ++round) {
        ++counters_.rounds;
        trackAll(session);
        for (Body& body : bodies_)
            if (body.alive)
                follow(session, body);
        changed = joinBodies(session);
        for (Body& body : bodies_) {
            if (!body.alive)
                continue;
            if (measure(session, body))
                changed = true;
            if (body.markers_mm.size() < config_.minModelMarkers) {
                body.alive = false;
                ++counters_.dropped;
                changed = true;
            }
        }
    }
    // The poses must come from the models as they now are.
    if (changed) {
        trackAll(session);
        for (Body& body : bodies_)
            if (body.alive)
                follow(session, body);
    }
    for (Body& body : bodies_)
        if (body.alive)
            refine(session, body);

    std::vector<const Body*> done;
    for (const Body& body : bodies_)
        if (body.alive && body.markers_mm.size() >= config_.minModelMarkers)
            done.push_back(&body);
    std::stable_sort(done.begin(), done.end(), [](const Body* a, const Body* b) {
        return a->markers_mm.size() > b->markers_mm.size();
    });
    std::size_t count = 0;
    for (const Body* body : done) {
        if (count == out.size()) {
            ++counters_.modelOverflow;
            continue;
        }
        MarkerModel& model = out[count];
        model.clear();
        model.id = static_cast<std::uint32_t>(count);
        const RigidTransform canonicalFromBody = canonicalFrame(body->markers_mm).inverse();
        for (const Vec3& m : body->markers_mm)
            if (!model.markers_model_mm.push_back(canonicalFromBody.apply(m)))
                ++counters_.markerOverflow;
        for (const auto& [a, b] : body->edges)
            if (a < model.markers_model_mm.size() && b < model.markers_model_mm.size())
                model.edges.push_back(
                    {a, b, (model.markers_model_mm[a] - model.markers_model_mm[b]).norm()});
        ++count;
    }
    computeSmin(out.first(count), config_.smin);
    return count;
}

// ---------------------------------------------------------------------------------------------
// Tracking every body through the session

std::vector<MarkerModel> CalibrationCompletion::trackingModels(std::size_t count) const {
    std::vector<MarkerModel> models;
    models.reserve(count);
    for (std::size_t b = 0; b < count; ++b) {
        const Body& body = bodies_[b];
        MarkerModel& model = models.emplace_back(config_.maxMarkersPerModel);
        model.id = static_cast<std::uint32_t>(b);
        for (const Vec3& m : body.markers_mm)
            model.markers_model_mm.push_back(m);
        if (body.edges.empty()) {
            // Nothing known of co-visibility yet: every pair may be seen together.
            for (std::size_t i = 0; i < body.markers_mm.size(); ++i)
                for (std::size_t j = i + 1; j < body.markers_mm.size(); ++j)
                    model.edges.push_back({static_cast<std::uint16_t>(i),
                                           static_cast<std::uint16_t>(j),
                                           (body.markers_mm[i] - body.markers_mm[j]).norm()});
        } else {
            for (const auto& [i, j] : body.edges)
                model.edges.push_back({i, j, (body.markers_mm[i] - body.markers_mm[j]).norm()});
        }
    }
    // S_min as this tracker tells distances apart: a self-similar layout (a sphere) needs fewer
    // markers to be told from itself at the tracker's tolerance than at the export's safe one.
    SminConfig smin = config_.smin;
    smin.tolerance_mm = std::min(smin.tolerance_mm, config_.tracking.distanceTolerance_mm);
    computeSmin(models, smin);
    // A layout that is nearly the same seen from several sides (a sphere) may need more markers
    // to be told from itself than are ever in view at once. The session does not need that
    // certainty: of all hypotheses the tracker takes the best (most markers, then least residual),
    // and a rare wrong pose scatters its points, which no marker's place collects.
    for (MarkerModel& m : models)
        m.sMin =
            std::min<std::uint32_t>(m.sMin, static_cast<std::uint32_t>(config_.maxAcquireMarkers));
    return models;
}

void CalibrationCompletion::trackAll(const SessionBuffer& session) {
    std::stable_sort(bodies_.begin(), bodies_.end(), [](const Body& a, const Body& b) {
        if (a.alive != b.alive)
            return a.alive;
        return a.markers_mm.size() > b.markers_mm.size();
    });
    std::size_t alive = 0;
    while (alive < bodies_.size() && bodies_[alive].alive)
        ++alive;
    if (alive == 0)
        return;
    std::vector<PoseTrack> tracks;
    for (std::size_t b = 0; b < alive; ++b)
        tracks.push_back({&bodies_[b].posed, &bodies_[b].T_rig_from_body});
    trackBothWays(session, trackingModels(alive), tracks);
}

void CalibrationCompletion::trackBothWays(const SessionBuffer& session,
                                          const std::vector<MarkerModel>& models,
                                          std::span<const PoseTrack> tracks) {
    const std::size_t frames = session.frames();
    for (const PoseTrack& track : tracks) {
        track.posed->assign(frames, 0);
        track.T_rig_from_body->resize(frames);
    }
    // Forwards, then backwards in time; each frame takes whichever pass matched more markers over
    // all models, as a whole, so that no point serves two bodies in one frame.
    std::vector<std::uint32_t> forwardMarkers(frames, 0);
    {
        ModelTracker tracker(models, config_.tracking);
        if (!tracker.isValid())
            return;
        for (std::size_t f = 0; f < frames; ++f) {
            tracker.update(session.time_s(f), session.points(f));
            for (std::size_t b = 0; b < tracks.size(); ++b) {
                const TrackedBody& tracked = tracker.bodies()[b];
                if (!tracked.found())
                    continue;
                (*tracks[b].posed)[f] = 1;
                (*tracks[b].T_rig_from_body)[f] = tracked.T_rig_from_model;
                forwardMarkers[f] += tracked.markers;
            }
        }
    }
    ModelTracker tracker(models, config_.tracking);
    for (std::size_t step = 0; step < frames; ++step) {
        const std::size_t f = frames - 1 - step;
        tracker.update(-session.time_s(f), session.points(f));
        std::uint32_t total = 0;
        for (const TrackedBody& tracked : tracker.bodies())
            if (tracked.found())
                total += tracked.markers;
        if (total <= forwardMarkers[f])
            continue;
        for (std::size_t b = 0; b < tracks.size(); ++b) {
            const TrackedBody& tracked = tracker.bodies()[b];
            (*tracks[b].posed)[f] = tracked.found() ? 1 : 0;
            if (tracked.found())
                (*tracks[b].T_rig_from_body)[f] = tracked.T_rig_from_model;
        }
    }
    counters_.framesTracked += 2 * frames;
}

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
    const std::vector<MarkerModel> models = trackingModels(alive);
    std::vector<char> trackedAlone(alive, 0);
    auto trackAlone = [&](std::size_t b) {
        if (trackedAlone[b])
            return;
        trackedAlone[b] = 1;
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
                std::optional<RigidTransform> intoFromFrom;
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
                std::size_t bestAgree = 0;
                std::size_t bestCandidate = 0;
                const std::size_t step =
                    std::max<std::size_t>(1, relative.size() / kConsensusCandidates);
                for (std::size_t k = 0; k < relative.size(); k += step) {
                    std::size_t agree = 0;
                    for (const RigidTransform& r : relative)
                        if (disagreement_mm(r, relative[k], ball) <= config_.sameBodyTolerance_mm)
                            ++agree;
                    if (agree > bestAgree) {
                        bestAgree = agree;
                        bestCandidate = k;
                    }
                }
                // Most frames must come near one relative pose at all: a piece of a self-similar
                // layout found alone on the other's points fits there too, but by a relative pose
                // that changes from frame to frame.
                if (2 * bestAgree < c.shared)
                    return c;
                const OneBodyFit fit =
                    fitAsOneBody(session, sharedFrames, into, from, alone, relative[bestCandidate]);
                if (static_cast<double>(fit.framesFitting) >=
                    config_.sameBodyShare * static_cast<double>(c.shared))
                    c.intoFromFrom = fit.intoFromFrom;
                return c;
            };
            // Found together often by the joint tracker, they are one body only if they move as
            // one; two alike objects would each be found alone on the same points.
            const Consensus joint = consensus(false);
            std::optional<RigidTransform> intoFromFrom = joint.intoFromFrom;
            bool byLayout = false;
            if (!intoFromFrom && joint.shared < config_.minSharedFrames) {
                // Seldom found at once jointly: pieces that share markers, whose shared points the
                // joint tracker gives to one of them. Each found alone, they move as one.
                trackAlone(a);
                trackAlone(b);
                intoFromFrom = consensus(true).intoFromFrom;
                if (!intoFromFrom) {
                    // One may be a piece of the other that the tracker gave the other's points to,
                    // or the two may share markers but never be in view together. Four or more
                    // markers in one place of the other's layout tie them, unless a self-similar
                    // layout lets them lie as well in another place.
                    const Registration r =
                        registerLayout(from.markers_mm, into.markers_mm,
                                       config_.sameBodyTolerance_mm, kRegistrationTolerance_mm);
                    if (r.matched >= 4 && r.matched > r.runnerUp) {
                        intoFromFrom = r.wholeFromPart;
                        byLayout = true;
                    }
                }
            }
            if (intoFromFrom)
                ++(byLayout ? counters_.joinedByLayout : counters_.joinedByMotion);
            if (!intoFromFrom && joint.shared < config_.minSharedFrames) {
                // Never in view together: one piece of a turning body may come into view just as
                // the other leaves. The pose of the one, carried on at its speed, then lands on
                // the other's pose by one relative pose, every time it happens.
                intoFromFrom = relativePoseAcrossHandovers(session, into, from);
                if (intoFromFrom)
                    ++counters_.joinedByHandover;
            }
            if (!intoFromFrom)
                continue;
            const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
            for (const Vec3& m : from.markers_mm) {
                const Vec3 moved = intoFromFrom->apply(m);
                const bool known =
                    std::any_of(into.markers_mm.begin(), into.markers_mm.end(), [&](const Vec3& n) {
                        return (n - moved).squaredNorm() < spacing2;
                    });
                if (known)
                    continue;
                if (into.markers_mm.size() == config_.maxMarkersPerModel) {
                    ++counters_.markerOverflow;
                    break;
                }
                into.markers_mm.push_back(moved);
            }
            // Its co-visibility is measured again from the poses.
            into.edges.clear();
            const RigidTransform fromFromInto = intoFromFrom->inverse();
            for (std::size_t f = 0; f < frames; ++f)
                if (!into.posed[f] && from.posed[f]) {
                    into.posed[f] = 1;
                    into.T_rig_from_body[f] = from.T_rig_from_body[f] * fromFromInto;
                }
            from.alive = false;
            joined = true;
        }
    }
    return joined;
}

CalibrationCompletion::OneBodyFit
CalibrationCompletion::fitAsOneBody(const SessionBuffer& session,
                                    std::span<const std::size_t> sharedFrames, const Body& a,
                                    const Body& b, bool alone, const RigidTransform& aFromB) const {
    OneBodyFit result;
    result.intoFromFrom = aFromB;
    const auto& posesA = alone ? a.T_rig_from_body_alone : a.T_rig_from_body;
    const auto& posesB = alone ? b.T_rig_from_body_alone : b.T_rig_from_body;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    const std::size_t nA = a.markers_mm.size();
    const std::size_t nB = b.markers_mm.size();
    std::vector<Vec3> layout_a_mm(nA + nB);
    // b's markers that are a's too (under aFromB): the index of a's, or -1 for b's own.
    std::vector<std::int32_t> sameAs(nB);
    std::vector<Vec3> from, to, sums(nB);
    std::vector<std::size_t> which, ownAt;
    std::vector<std::uint32_t> counts(nB);
    std::vector<const Vec3*> matchedA(nA);
    auto nearest = [&](std::span<const Vec3> points, const Vec3& there) -> const Vec3* {
        double best2 = radius * radius;
        const Vec3* match = nullptr;
        for (const Vec3& p : points) {
            const double d2 = (p - there).squaredNorm();
            if (d2 <= best2) {
                best2 = d2;
                match = &p;
            }
        }
        return match;
    };
    // Alternating least squares, as refine() does for one body: the union fitted to each frame,
    // then b's markers placed in a's frame by those fits.
    constexpr int kIterations = 3;
    for (int iteration = 0; iteration < kIterations; ++iteration) {
        for (std::size_t k = 0; k < nA; ++k)
            layout_a_mm[k] = a.markers_mm[k];
        for (std::size_t k = 0; k < nB; ++k) {
            layout_a_mm[nA + k] = result.intoFromFrom.apply(b.markers_mm[k]);
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
        result.intoFromFrom = placed->transform;
    }
    return result;
}

namespace {

/// \a body's pose at \a t_s carried on from its poses at \a t0_s and \a t1_s (t0 < t1): its
/// centre \a centre_body (body frame) moves on at its speed, and it turns on at its turn rate.
RigidTransform extrapolate(const RigidTransform& at0, double t0_s, const RigidTransform& at1,
                           double t1_s, double t_s, const Vec3& centre_body) {
    const double s = (t_s - t1_s) / (t1_s - t0_s);
    const Vec3 c0 = at0.apply(centre_body), c1 = at1.apply(centre_body);
    const Eigen::AngleAxisd turn(at1.rotation * at0.rotation.inverse());
    RigidTransform out;
    out.rotation = Quat(Eigen::AngleAxisd(turn.angle() * s, turn.axis())) * at1.rotation;
    out.rotation.normalize();
    out.translation_mm = c1 + s * (c1 - c0) - out.rotation * centre_body;
    return out;
}

} // namespace

std::optional<RigidTransform>
CalibrationCompletion::relativePoseAcrossHandovers(const SessionBuffer& session, const Body& a,
                                                   const Body& b) const {
    const std::size_t frames = session.frames();
    const Extent ballA = extentOf(a.markers_mm);
    const Extent ballB = extentOf(b.markers_mm);
    std::vector<RigidTransform> estimates; // b's frame to a's
    // The first pose of one body's stretch, and the other's last poses just before it.
    auto handover = [&](const Body& first, const Body& second, const Extent& firstBall,
                        bool firstIsA) {
        for (std::size_t f = 1; f < frames; ++f) {
            if (!second.posedAlone[f] || second.posedAlone[f - 1] || first.posedAlone[f])
                continue;
            std::size_t end = f; // the earlier body's last posed frame before f
            for (std::size_t back = 1; back <= kHandoverGap_frames && back <= f; ++back)
                if (first.posedAlone[f - back]) {
                    end = f - back;
                    break;
                }
            if (end == f || end < kSpeedBaseline_frames)
                continue;
            const std::size_t start = end - kSpeedBaseline_frames;
            bool steady = true;
            for (std::size_t g = start; g <= end; ++g)
                steady = steady && first.posedAlone[g] != 0;
            if (!steady)
                continue;
            const RigidTransform carried =
                extrapolate(first.T_rig_from_body_alone[start], session.time_s(start),
                            first.T_rig_from_body_alone[end], session.time_s(end),
                            session.time_s(f), firstBall.centre);
            const RigidTransform firstFromSecond =
                carried.inverse() * second.T_rig_from_body_alone[f];
            estimates.push_back(firstIsA ? firstFromSecond : firstFromSecond.inverse());
        }
    };
    handover(a, b, ballA, true);
    handover(b, a, ballB, false);
    if (estimates.size() < kMinHandovers)
        return std::nullopt;
    std::size_t bestAgree = 0, best = 0;
    for (std::size_t c = 0; c < estimates.size(); ++c) {
        std::size_t agree = 0;
        for (const RigidTransform& e : estimates)
            if (disagreement_mm(e, estimates[c], ballB) <= config_.handoverTolerance_mm)
                ++agree;
        if (agree > bestAgree) {
            bestAgree = agree;
            best = c;
        }
    }
    if (bestAgree < kMinHandovers ||
        static_cast<double>(bestAgree) <
            config_.sameBodyShare * static_cast<double>(estimates.size()))
        return std::nullopt;
    std::vector<RigidTransform> agreeing;
    for (const RigidTransform& e : estimates)
        if (disagreement_mm(e, estimates[best], ballB) <= config_.handoverTolerance_mm)
            agreeing.push_back(e);
    return meanTransform(agreeing, ballB);
}

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
            const RigidTransform bodyFromRig = body.T_rig_from_body[f].inverse();
            const Vec3 q = bodyFromRig.apply(p);
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
                double best2 = kDiscoveryGate_mm * kDiscoveryGate_mm;
                const Vec3* match = nullptr;
                for (const Vec3& p : points) {
                    const double d2 = (p - predicted).squaredNorm();
                    if (d2 <= best2) {
                        best2 = d2;
                        match = &p;
                    }
                }
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
    std::vector<std::size_t> which;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    const double reach2 = config_.reach_mm * config_.reach_mm;
    std::vector<std::uint8_t> followed(frames, 0);
    std::vector<std::uint8_t> carried(frames, 0); // posed by a chain, from three points or two
    const Vec3 centre = extentOf(body.markers_mm).centre;

    // Where the other bodies found in frame f have their markers (rig frame): a point there is
    // theirs, as the joint tracker gives no point to two bodies.
    std::vector<Vec3> claimed;
    auto claim = [&](std::size_t f) {
        claimed.clear();
        for (const Body& other : bodies_)
            if (&other != &body && other.alive && other.posed[f])
                for (const Vec3& m : other.markers_mm)
                    claimed.push_back(other.T_rig_from_body[f].apply(m));
    };
    auto isClaimed = [&](const Vec3& p) {
        return std::any_of(claimed.begin(), claimed.end(),
                           [&](const Vec3& c) { return (c - p).squaredNorm() <= radius * radius; });
    };
    // Points of frame f near the body and off every anchor become anchors; those on one count.
    auto collect = [&](std::size_t f, const RigidTransform& rigFromBody) {
        const RigidTransform bodyFromRig = rigFromBody.inverse();
        claim(f);
        for (const Vec3& p : session.points(f)) {
            if (isClaimed(p))
                continue;
            const Vec3 q = bodyFromRig.apply(p);
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
                which.clear();
                taken.clear();
                claim(h);
                for (std::size_t k = 0; k < anchors.size(); ++k) {
                    const Anchor& a = anchors[k];
                    if (!a.marker && a.hits < kFollowAnchorHits)
                        continue;
                    const Vec3 there = predicted.apply(a.place());
                    double best2 = radius * radius;
                    const Vec3* match = nullptr;
                    for (const Vec3& p : points) {
                        const double d2 = (p - there).squaredNorm();
                        if (d2 <= best2) {
                            best2 = d2;
                            match = &p;
                        }
                    }
                    if (match == nullptr ||
                        std::find(taken.begin(), taken.end(), match) != taken.end() ||
                        isClaimed(*match))
                        continue;
                    taken.push_back(match);
                    from.push_back(a.place());
                    to.push_back(*match);
                    which.push_back(k);
                }
                // The worst point out while any lies off the fit: a point of something passing
                // by that sat still against the body for a while.
                std::optional<RigidFit> fit;
                while (from.size() >= 3) {
                    fit = fitRigid(from, to);
                    if (!fit)
                        break;
                    std::size_t worst = 0;
                    double worstResidual = 0.0;
                    for (std::size_t i = 0; i < from.size(); ++i) {
                        const double r = (fit->transform.apply(from[i]) - to[i]).norm();
                        if (r > worstResidual) {
                            worstResidual = r;
                            worst = i;
                        }
                    }
                    if (worstResidual <= config_.tracking.maxRms_mm)
                        break;
                    fit.reset();
                    from.erase(from.begin() + static_cast<std::ptrdiff_t>(worst));
                    to.erase(to.begin() + static_cast<std::ptrdiff_t>(worst));
                    which.erase(which.begin() + static_cast<std::ptrdiff_t>(worst));
                }
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

// ---------------------------------------------------------------------------------------------
// Measuring a body's markers from every frame it was found in

std::size_t CalibrationCompletion::cellOf(const Vec3& q_mm) const {
    const double cell = 2.0 * config_.siteRadius_mm;
    const auto ix = static_cast<std::int64_t>(std::floor(q_mm.x() / cell));
    const auto iy = static_cast<std::int64_t>(std::floor(q_mm.y() / cell));
    const auto iz = static_cast<std::int64_t>(std::floor(q_mm.z() / cell));
    const auto h = static_cast<std::uint64_t>(ix * 73856093 ^ iy * 19349663 ^ iz * 83492791);
    return static_cast<std::size_t>(h & (kCells - 1));
}

std::int32_t CalibrationCompletion::siteNear(const Vec3& q_mm) const {
    const double cell = 2.0 * config_.siteRadius_mm;
    const double radius2 = config_.siteRadius_mm * config_.siteRadius_mm;
    std::int32_t best = -1;
    double bestDistance2 = radius2;
    for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dz = -1; dz <= 1; ++dz) {
                const Vec3 probe = q_mm + cell * Vec3(dx, dy, dz);
                for (std::int32_t s = cellHead_[cellOf(probe)]; s >= 0;
                     s = sites_[static_cast<std::size_t>(s)].next) {
                    const Site& site = sites_[static_cast<std::size_t>(s)];
                    const double d2 =
                        (site.sum_mm / static_cast<double>(site.hits) - q_mm).squaredNorm();
                    if (d2 <= bestDistance2) {
                        bestDistance2 = d2;
                        best = s;
                    }
                }
            }
    return best;
}

std::int32_t CalibrationCompletion::addSite(const Vec3& q_mm) {
    if (sites_.size() == config_.maxSites) {
        ++counters_.siteOverflow;
        return -1;
    }
    const std::size_t cell = cellOf(q_mm);
    Site& site = sites_.emplace_back();
    site.sum_mm = q_mm;
    site.hits = 1;
    site.next = cellHead_[cell];
    cellHead_[cell] = static_cast<std::int32_t>(sites_.size() - 1);
    return cellHead_[cell];
}

bool CalibrationCompletion::measure(const SessionBuffer& session, Body& body) {
    const std::size_t frames = session.frames();
    sites_.clear();
    std::fill(cellHead_.begin(), cellHead_.end(), -1);

    const Extent extent = extentOf(body.markers_mm);
    const double reach = extent.radius_mm + config_.reach_mm;
    const double reach2 = reach * reach;
    for (std::size_t f = 0; f < frames; ++f) {
        if (!body.posed[f])
            continue;
        const RigidTransform bodyFromRig = body.T_rig_from_body[f].inverse();
        for (const Vec3& p : session.points(f)) {
            const Vec3 q = bodyFromRig.apply(p);
            if ((q - extent.centre).squaredNorm() > reach2)
                continue;
            std::int32_t s = siteNear(q);
            if (s < 0) {
                s = addSite(q);
                if (s < 0)
                    continue;
                Site& fresh = sites_[static_cast<std::size_t>(s)];
                fresh.lastFrame = static_cast<std::uint32_t>(f);
                continue;
            }
            Site& site = sites_[static_cast<std::size_t>(s)];
            if (site.lastFrame == f)
                continue;
            site.lastFrame = static_cast<std::uint32_t>(f);
            ++site.hits;
            site.sum_mm += q;
        }
    }

    // Places seen long enough, strongest first; of two closer than a marker's size, the stronger.
    const auto minHits = static_cast<std::uint32_t>(std::ceil(config_.minSeen_s * frameRate_hz_));
    std::vector<std::size_t> candidates;
    for (std::size_t s = 0; s < sites_.size(); ++s)
        if (sites_[s].hits >= std::max<std::uint32_t>(minHits, 2))
            candidates.push_back(s);
    std::sort(candidates.begin(), candidates.end(), [&](std::size_t a, std::size_t b) {
        if (sites_[a].hits != sites_[b].hits)
            return sites_[a].hits > sites_[b].hits;
        return canonicallyBefore(sites_[a].sum_mm, sites_[b].sum_mm);
    });
    std::vector<Vec3> place;
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    for (const std::size_t s : candidates) {
        const Vec3 mean = sites_[s].sum_mm / static_cast<double>(sites_[s].hits);
        const bool near = std::any_of(place.begin(), place.end(), [&](const Vec3& p) {
            return (p - mean).squaredNorm() < spacing2;
        });
        if (near)
            continue;
        if (place.size() == 2 * config_.maxMarkersPerModel) {
            ++counters_.markerOverflow;
            break;
        }
        place.push_back(mean);
    }

    // Seen again whenever the cameras look at it as they once saw it? First the directions each
    // place was seen from (body frame, thinned), then, in every frame, whether the cameras look
    // from one of them and it is there.
    const std::size_t n = place.size();
    std::vector<std::uint32_t> expected(n, 0), seenWhenExpected(n, 0), seen(n, 0);
    std::vector<std::uint32_t> together(n * n, 0);
    std::vector<std::vector<Vec3>> seenFrom(n);
    std::vector<std::uint8_t> hit(n);
    std::vector<std::size_t> hitNow;
    const double sameView = std::cos(config_.sameViewAngle_deg * kDegree);
    const double thinning = std::cos(0.5 * config_.sameViewAngle_deg * kDegree);
    const double radius2 = config_.siteRadius_mm * config_.siteRadius_mm;
    for (int pass = 0; pass < 2; ++pass) {
        for (std::size_t f = 0; f < frames; ++f) {
            if (!body.posed[f])
                continue;
            const RigidTransform& rigFromBody = body.T_rig_from_body[f];
            const Vec3 viewpoint = rigFromBody.inverse().apply(config_.viewpoint_rig_mm);
            const std::span<const Vec3> points = session.points(f);
            hitNow.clear();
            for (std::size_t k = 0; k < n; ++k) {
                const Vec3 there = rigFromBody.apply(place[k]);
                const bool isHit = std::any_of(points.begin(), points.end(), [&](const Vec3& p) {
                    return (p - there).squaredNorm() <= radius2;
                });
                const Vec3 view = (viewpoint - place[k]).normalized();
                std::vector<Vec3>& directions = seenFrom[k];
                if (pass == 0) {
                    if (!isHit)
                        continue;
                    ++seen[k];
                    hitNow.push_back(k);
                    const bool known =
                        std::any_of(directions.begin(), directions.end(),
                                    [&](const Vec3& d) { return d.dot(view) >= thinning; });
                    if (!known && directions.size() < kMaxViewDirections)
                        directions.push_back(view);
                    continue;
                }
                const bool seenFromHere =
                    std::any_of(directions.begin(), directions.end(),
                                [&](const Vec3& d) { return d.dot(view) >= sameView; });
                if (seenFromHere) {
                    ++expected[k];
                    seenWhenExpected[k] += isHit ? 1U : 0U;
                }
            }
            for (std::size_t i = 0; i < hitNow.size(); ++i)
                for (std::size_t j = i + 1; j < hitNow.size(); ++j)
                    ++together[hitNow[i] * n + hitNow[j]];
        }
    }
    std::vector<std::size_t> accepted;
    for (std::size_t k = 0; k < n; ++k) {
        if (seen[k] < minHits)
            continue;
        if (expected[k] > 0 && static_cast<double>(seenWhenExpected[k]) <
                                   config_.minSeenShare * static_cast<double>(expected[k]))
            continue;
        if (accepted.size() == config_.maxMarkersPerModel) {
            ++counters_.markerOverflow;
            break;
        }
        accepted.push_back(k);
    }

    std::vector<Vec3> markers;
    for (const std::size_t k : accepted)
        markers.push_back(place[k]);
    auto covered = [](std::span<const Vec3> set, const Vec3& p) {
        return std::any_of(set.begin(), set.end(),
                           [&](const Vec3& q) { return (q - p).squaredNorm() < 0.25; });
    };
    std::size_t added = 0, removed = 0;
    for (const Vec3& m : markers)
        added += covered(body.markers_mm, m) ? 0U : 1U;
    for (const Vec3& m : body.markers_mm)
        removed += covered(markers, m) ? 0U : 1U;
    counters_.markersAdded += added;
    counters_.markersRemoved += removed;
    body.markers_mm = std::move(markers);
    body.edges.clear();
    for (std::size_t a = 0; a < accepted.size(); ++a)
        for (std::size_t b = a + 1; b < accepted.size(); ++b) {
            const std::size_t i = std::min(accepted[a], accepted[b]);
            const std::size_t j = std::max(accepted[a], accepted[b]);
            if (together[i * n + j] >= 2)
                body.edges.emplace_back(static_cast<std::uint16_t>(a),
                                        static_cast<std::uint16_t>(b));
        }
    return added > 0 || removed > 0;
}

// ---------------------------------------------------------------------------------------------
// Least squares over every pose

void CalibrationCompletion::refine(const SessionBuffer& session, Body& body) {
    const std::size_t frames = session.frames();
    const std::size_t n = body.markers_mm.size();
    if (n < 3)
        return;
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    std::vector<Vec3> sums(n);
    std::vector<std::uint32_t> counts(n);
    std::vector<std::uint32_t> together(n * n, 0);
    std::vector<Vec3> from, to;
    std::vector<std::size_t> which;
    for (int iteration = 0; iteration < config_.refineIterations; ++iteration) {
        const bool last = iteration + 1 == config_.refineIterations;
        std::fill(sums.begin(), sums.end(), Vec3::Zero());
        std::fill(counts.begin(), counts.end(), 0U);
        for (std::size_t f = 0; f < frames; ++f) {
            if (!body.posed[f])
                continue;
            const std::span<const Vec3> points = session.points(f);
            from.clear();
            to.clear();
            which.clear();
            for (std::size_t k = 0; k < n; ++k) {
                const Vec3 there = body.T_rig_from_body[f].apply(body.markers_mm[k]);
                double best2 = radius * radius;
                const Vec3* match = nullptr;
                for (const Vec3& p : points) {
                    const double d2 = (p - there).squaredNorm();
                    if (d2 <= best2) {
                        best2 = d2;
                        match = &p;
                    }
                }
                if (match) {
                    from.push_back(body.markers_mm[k]);
                    to.push_back(*match);
                    which.push_back(k);
                }
            }
            const std::optional<RigidFit> fit = fitRigid(from, to);
            if (!fit || fit->rms_mm > config_.tracking.maxRms_mm) {
                body.posed[f] = 0;
                continue;
            }
            body.T_rig_from_body[f] = fit->transform;
            const RigidTransform bodyFromRig = fit->transform.inverse();
            for (std::size_t i = 0; i < which.size(); ++i) {
                sums[which[i]] += bodyFromRig.apply(to[i]);
                ++counts[which[i]];
            }
            if (last)
                for (std::size_t i = 0; i < which.size(); ++i)
                    for (std::size_t j = i + 1; j < which.size(); ++j)
                        ++together[which[i] * n + which[j]];
        }
        for (std::size_t k = 0; k < n; ++k)
            if (counts[k] > 0)
                body.markers_mm[k] = sums[k] / static_cast<double>(counts[k]);
    }
    body.edges.clear();
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = i + 1; j < n; ++j)
            if (together[i * n + j] >= 2)
                body.edges.emplace_back(static_cast<std::uint16_t>(i),
                                        static_cast<std::uint16_t>(j));
}

} // namespace edgetrack
