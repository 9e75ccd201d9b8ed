// Completion of a calibration session: the provisional models tracked through all its frames.
// The rounds and the tracking live here; each step has its own calibration_completion_*.cpp.
#include "core/calibration_completion.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <numbers>
#include <numeric>
#include <optional>

#include "core/completion_geometry.hpp"
#include "core/marker_set.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

using namespace completion_detail;

CalibrationCompletion::CalibrationCompletion(const CompletionConfig& config)
    : config_(config) {
    valid_ = config.maxModels > 0 && config.maxMarkersPerModel >= 4 &&
             config.maxMarkersPerModel <= MarkerSet::kCapacity && config.siteRadius_mm > 0.0 &&
             config.maxSites > 0 && config.minModelMarkers >= 4 && config.maxRounds > 0 &&
             config.minSeenShare >= 0.0 && config.minSeenShare <= 1.0 &&
             config.triangleTolerance_mm > 0.0 && config.triangleUniqueness >= 2.0 &&
             config.minTriangleRun >= 2 && config.minModelSeen_s >= 0.0 &&
             config.maxResidualRatio >= 1.0 && config.maxFrameResidualRatio >= 1.0;
    if (!valid_)
        return;
    sites_.reserve(config.maxSites);
    cellHead_.assign(kSiteCells, -1);
}

std::size_t CalibrationCompletion::run(const SessionBuffer& session,
                                       std::span<const MarkerModel> seeds,
                                       std::span<MarkerModel> out) {
    counters_ = {};
    precision_.clear();
    mostSeenTogether_.clear();
    untiedPieces_.clear();
    bodies_.clear();
    nextBodyId_ = 0;
    sminLayoutOf_.clear();
    sminLargest_.clear();
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
        body.id = nextBodyId_++;
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

    linkPointTracks(session);
    // Bodies the online stage never made a model of: moving rigid sets of points no seed explains.
    trackAll(session);
    discoverBodies(session);
    // Tracking depends on the bodies alone: with none discovered, the first round's would repeat
    // the one above.
    bool posesCurrent = counters_.discovered == 0;

    bool changed = true;
    for (int round = 0; round < config_.maxRounds && changed; ++round) {
        ++counters_.rounds;
        if (!posesCurrent)
            trackAll(session);
        posesCurrent = false;
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
    settleLayouts(session);

    const auto minFramesInFour =
        static_cast<std::uint32_t>(std::ceil(config_.minModelSeen_s * frameRate_hz_ - 1e-6));
    std::vector<Body*> done;
    for (Body& body : bodies_) {
        if (!body.alive || body.markers_mm.size() < config_.minModelMarkers)
            continue;
        if (!body.seenInFour(config_.minModelMarkers, minFramesInFour)) {
            ++counters_.droppedSeenBriefly;
            continue;
        }
        done.push_back(&body);
    }
    std::stable_sort(done.begin(), done.end(), [](const Body* a, const Body* b) {
        return a->markers_mm.size() > b->markers_mm.size();
    });
    if (done.size() > out.size()) {
        counters_.modelOverflow += done.size() - out.size();
        done.resize(out.size());
    }
    std::size_t count = 0;
    for (const Body* body : done) {
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
        precision_.push_back(body->precision);
        mostSeenTogether_.push_back(body->mostSeenTogether);
        ++count;
    }
    computeSmin(out.first(count), config_.smin);

    // Pieces of one object that nothing tied: the user is told, as the session cannot mend it.
    for (Body* body : done)
        placeTracks(session, *body);
    for (std::size_t i = 0; i < count; ++i)
        for (std::size_t j = i + 1; j < count; ++j)
            if (const std::size_t shared = sharedMarkers(*done[i], *done[j]);
                shared >= 2 && !done[i]->isApartFrom(done[j]->id)) {
                untiedPieces_.push_back({i, j, shared});
                ++counters_.untiedPieces;
            }
    return count;
}

void CalibrationCompletion::markersOfOthersAt(std::size_t f, const Body& body, OtherBodies which,
                                              std::vector<Vec3>& out) const {
    out.clear();
    for (const Body& other : bodies_)
        if (&other != &body && other.alive && other.posed[f] &&
            (which == OtherBodies::All || body.isApartFrom(other.id)))
            for (const Vec3& m : other.markers_mm)
                out.push_back(other.T_rig_from_body[f].apply(m));
}

// ---------------------------------------------------------------------------------------------
// Tracking every body through the session

namespace {

/// S_min's pairs kept by body id across the rounds.
class SminPairsById final : public SminPairMemory {
public:
    SminPairsById(std::span<const std::uint32_t> ids,
                  std::map<std::pair<std::uint32_t, std::uint32_t>, std::size_t>& largest)
        : ids_(ids)
        , largest_(largest) {}
    std::optional<std::size_t> recall(std::size_t a, std::size_t b) const override {
        const auto it = largest_.find({ids_[a], ids_[b]});
        if (it == largest_.end())
            return std::nullopt;
        return it->second;
    }
    void remember(std::size_t a, std::size_t b, std::size_t largest) override {
        largest_[{ids_[a], ids_[b]}] = largest;
    }

private:
    std::span<const std::uint32_t> ids_;
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::size_t>& largest_;
};

} // namespace

std::vector<MarkerModel> CalibrationCompletion::trackingModels(std::size_t count) {
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
    // A body whose layout changed forgets its pairs.
    std::vector<std::uint32_t> ids(count);
    for (std::size_t b = 0; b < count; ++b) {
        const std::uint32_t id = ids[b] = bodies_[b].id;
        auto known = sminLayoutOf_.find(id);
        if (known != sminLayoutOf_.end() && sameLayout(known->second, models[b]))
            continue;
        if (known == sminLayoutOf_.end())
            known = sminLayoutOf_.emplace(id, MarkerModel(config_.maxMarkersPerModel)).first;
        known->second.assign(models[b]);
        std::erase_if(sminLargest_, [&](const auto& pair) {
            return pair.first.first == id || pair.first.second == id;
        });
    }
    SminWorkspace workspace;
    SminPairsById memory(ids, sminLargest_);
    computeSmin(models, smin, workspace, &memory);
    // A layout that is nearly the same seen from several sides (a sphere) may need more markers
    // to be told from itself than are ever in view at once. The session does not need that
    // certainty: of all hypotheses the tracker takes the best (most markers, then least residual),
    // and a rare wrong pose scatters its points, which no marker's place collects.
    // Nor more than were ever seen together: a body that needs more is never found again (a
    // ring of five seen four at a time, whose four-marker subsets look alike).
    for (std::size_t b = 0; b < count; ++b) {
        std::size_t most = config_.maxAcquireMarkers;
        if (bodies_[b].mostSeenTogether > 0)
            most = std::min(most, std::max(bodies_[b].mostSeenTogether, config_.minModelMarkers));
        models[b].sMin = std::min<std::uint32_t>(models[b].sMin, static_cast<std::uint32_t>(most));
    }
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
    // The poses a body took from a piece joined to it: the joined body may need more of its
    // markers to be found afresh than the piece shows (its S_min), though the piece's poses hold.
    std::vector<std::vector<RigidTransform>> was(alive);
    for (std::size_t b = 0; b < alive; ++b)
        if (!bodies_[b].posedByJoin.empty())
            was[b] = bodies_[b].T_rig_from_body;
    std::vector<PoseTrack> tracks;
    for (std::size_t b = 0; b < alive; ++b)
        tracks.push_back({&bodies_[b].posed, &bodies_[b].T_rig_from_body});
    roundModels_ = trackingModels(alive);
    trackBothWays(session, roundModels_, tracks);
    poseFromTriangles(session);
    for (std::size_t b = 0; b < alive; ++b)
        if (!bodies_[b].posedByJoin.empty())
            keepJoinedPosesThatStillFit(session, bodies_[b], was[b]);
}

void CalibrationCompletion::settleLayouts(const SessionBuffer& session) {
    for (Body& body : bodies_)
        if (body.alive) {
            refine(session, body, config_.refineIterations, true);
            if (mergeCrowdedMarkers(body))
                refine(session, body, config_.refineIterations, true);
        }
    // The rig's noise, as the most rigid body shows it: the median over its markers of their
    // typical squared residual. A marker whose points lie off its body's poses several times
    // farther did not move with it (a point that rode along, a marker of another object), and
    // a body all of whose markers do so is no rigid object (markers on skin).
    double typical_mm2 = std::numeric_limits<double>::infinity();
    for (const Body& body : bodies_) {
        if (!body.alive)
            continue;
        std::vector<double> seen;
        for (const double r2 : body.markerResidual_mm2)
            if (r2 > 0.0)
                seen.push_back(r2);
        if (seen.size() >= config_.minModelMarkers)
            typical_mm2 = std::min(typical_mm2, medianOf(seen));
    }
    if (!std::isfinite(typical_mm2))
        return;
    // Then the layout from the frames that fit as well as the rig measures: a frame posed
    // wrongly (a near-likeness of the layout taken for it, a piece's pose kept through a join)
    // pulls the layout by as much as it is off. Last, only the markers frames fix to the rest.
    const double frameGate_mm2 = config_.maxFrameResidualRatio * typical_mm2;
    for (Body& body : bodies_) {
        if (!body.alive)
            continue;
        const bool dropped = dropMarkersThatDoNotMoveWithTheBody(body, typical_mm2);
        if (body.alive && (dropped || body.worstFrameResidual_mm2 > frameGate_mm2))
            refine(session, body, config_.refineIterations, true, frameGate_mm2);
        if (body.alive && keepTheLargestRigidGroup(body))
            refine(session, body, config_.refineIterations, true, frameGate_mm2);
    }
}

namespace {

/// Keeps the markers of \a markers_mm whose index \a keep holds for; how many went.
template <typename Keep>
std::size_t keepMarkers(std::vector<Vec3>& markers_mm, Keep keep) {
    std::vector<Vec3> kept;
    for (std::size_t k = 0; k < markers_mm.size(); ++k)
        if (keep(k))
            kept.push_back(markers_mm[k]);
    const std::size_t dropped = markers_mm.size() - kept.size();
    markers_mm = std::move(kept);
    return dropped;
}

} // namespace

bool CalibrationCompletion::dropMarkersThatDoNotMoveWithTheBody(Body& body, double typical_mm2) {
    const std::size_t dropped = keepMarkers(body.markers_mm, [&](std::size_t k) {
        return body.markerResidual_mm2[k] <= config_.maxResidualRatio * typical_mm2;
    });
    counters_.markersNotRigid += dropped;
    if (dropped > 0 && body.markers_mm.size() < config_.minModelMarkers) {
        body.alive = false;
        ++counters_.droppedNotRigid;
    }
    return dropped > 0;
}

bool CalibrationCompletion::keepTheLargestRigidGroup(Body& body) {
    if (body.rigidGroups.size() < 2)
        return false;
    const auto seenOf = [&](const MarkerBits& group) {
        std::uint64_t seen = 0;
        for (std::size_t k = 0; k < body.markers_mm.size(); ++k)
            if (holds(group, k))
                seen += body.markerFrames[k];
        return seen;
    };
    const MarkerBits* largest = &body.rigidGroups.front();
    for (const MarkerBits& group : body.rigidGroups)
        if (seenOf(group) > seenOf(*largest))
            largest = &group;
    const std::size_t dropped =
        keepMarkers(body.markers_mm, [&](std::size_t k) { return holds(*largest, k); });
    counters_.markersNotFixed += dropped;
    return dropped > 0;
}

bool CalibrationCompletion::mergeCrowdedMarkers(Body& body) {
    const std::size_t n = body.markers_mm.size();
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    std::vector<bool> drop(n, false);
    for (std::size_t a = 0; a < n; ++a)
        for (std::size_t b = a + 1; b < n; ++b) {
            if (drop[a] || drop[b] ||
                (body.markers_mm[a] - body.markers_mm[b]).squaredNorm() >= spacing2)
                continue;
            drop[body.markerFrames[a] >= body.markerFrames[b] ? b : a] = true;
        }
    const std::size_t dropped =
        keepMarkers(body.markers_mm, [&](std::size_t k) { return !drop[k]; });
    counters_.markersRemoved += dropped;
    return dropped > 0;
}

void CalibrationCompletion::keepJoinedPosesThatStillFit(const SessionBuffer& session, Body& body,
                                                        std::span<const RigidTransform> was) {
    const double radius = kRefineRadiusFactor * config_.siteRadius_mm;
    std::vector<Vec3> others, from, to;
    const std::vector<std::uint8_t>& joined = body.posedByJoin;
    for (std::size_t f = 0; f < session.frames() && f < joined.size() && f < was.size(); ++f) {
        if (body.posed[f] || !joined[f])
            continue;
        // Points another body was found on in this frame are not this one's.
        markersOfOthersAt(f, body, OtherBodies::All, others);
        const std::span<const Vec3> points = session.points(f);
        from.clear();
        to.clear();
        for (const Vec3& m : body.markers_mm) {
            const Vec3* match = nearestPoint(points, was[f].apply(m), radius);
            if (match && !nearAny(others, *match, radius * radius)) {
                from.push_back(m);
                to.push_back(*match);
            }
        }
        if (from.size() < config_.tracking.minTrackedMarkers)
            continue;
        const std::optional<RigidFit> fit = fitRigid(from, to);
        if (!fit || fit->rms_mm > config_.tracking.maxRms_mm)
            continue;
        body.posed[f] = 1;
        body.T_rig_from_body[f] = fit->transform;
        ++counters_.framesKept;
    }
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
    // A body tracked alone has every point of a frame to itself, so whether the frame holds any
    // four points its layout could stand for does not depend on what came before: where the
    // forward pass searched it in full and found no such four, the backward pass need not look.
    const bool alone = models.size() == 1;
    std::vector<std::uint8_t> nothingToFind(alone ? frames : 0, 0);
    {
        ModelTracker tracker(models, config_.tracking);
        if (!tracker.isValid())
            return;
        for (std::size_t f = 0; f < frames; ++f) {
            const ModelTrackingCounters before = tracker.counters();
            tracker.update(session.time_s(f), session.points(f));
            const ModelTrackingCounters& after = tracker.counters();
            if (alone)
                nothingToFind[f] = after.searches == before.searches + 1 &&
                                   after.hypotheses == before.hypotheses &&
                                   after.searchesSkipped == before.searchesSkipped &&
                                   after.budgetExhausted == before.budgetExhausted;
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
        tracker.update(-session.time_s(f), session.points(f), !(alone && nothingToFind[f]));
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

} // namespace edgetrack
