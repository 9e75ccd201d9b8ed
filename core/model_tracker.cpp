// Model-based tracking (paper section 5): prediction first, then the hashtable subgraph search.
#include "core/model_tracker.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <numeric>

#include <Eigen/Eigenvalues>

#include "core/disjoint_sets.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

namespace {

// A hypothesis (its fit, the matching and refitting of refine(), the trimming of outliers) costs
// about as much as this many candidate pair checks: 5 to 15 us against a few ns on this machine,
// timed on searches of a 500-reflection burst. The search budget counts both, so that it bounds
// time and not only one kind of work (at 64, a burst frame searched 1,880 hypotheses in 21 ms).
constexpr std::uint64_t kHypothesisCost = 1024;

// Match-and-fit passes at most: a wide first association after a prediction settles in two more;
// a pass that matches the same points as the last fit ends the refinement early.
constexpr int kMaxPasses = 3;
// Outlying matches dropped at most per pose (a spurious point or two beside hidden markers).
constexpr int kMaxTrims = 2;
// Weight of a new frame in a body's typical residual (a time constant of 20 frames).
constexpr double kRmsSmoothing = 0.05;

} // namespace

ModelTracker::ModelTracker(std::span<const MarkerModel> models, const ModelTrackingConfig& config)
    : config_(config) {
    valid_ =
        config.distanceTolerance_mm > 0.0 && config.matchRadius_mm > 0.0 &&
        config.maxRms_mm > 0.0 && config.predictionRadius_mm >= config.matchRadius_mm &&
        config.maxPoints > 0 &&
        config.maxPoints <= static_cast<std::size_t>(std::numeric_limits<std::int16_t>::max()) &&
        config.maxCandidatesPerMarker > 0 && config.minTrackedMarkers >= 3 &&
        models.size() < static_cast<std::size_t>(std::numeric_limits<std::int16_t>::max());
    for (const MarkerModel& m : models)
        valid_ = valid_ && m.markers_model_mm.size() <= MarkerSet::kCapacity;
    if (!valid_)
        return;

    const double binWidth = config.distanceTolerance_mm;
    std::vector<std::uint32_t> binCounts;
    for (const MarkerModel& m : models) {
        ModelSlot slot;
        slot.firstMarker = models_.markers_model_mm.size();
        slot.markerCount = m.markers_model_mm.size();
        slot.sMin = std::max<std::uint32_t>(m.sMin, 3);
        models_.maxMarkers = std::max(models_.maxMarkers, slot.markerCount);
        Vec3 centroid = Vec3::Zero();
        for (const Vec3& p : m.markers_model_mm) {
            models_.markers_model_mm.push_back(p);
            models_.adjacency.emplace_back();
            centroid += p;
        }
        if (slot.markerCount > 0)
            centroid /= static_cast<double>(slot.markerCount);
        slot.centroid_model_mm = centroid;
        for (const Vec3& p : m.markers_model_mm)
            slot.radius_mm = std::max(slot.radius_mm, (p - centroid).norm());

        double longest = 0.0;
        for (const ModelEdge& e : m.edges) {
            models_.adjacency[slot.firstMarker + e.from].insert(e.to);
            models_.adjacency[slot.firstMarker + e.to].insert(e.from);
            longest = std::max(longest, e.distance_mm);
        }
        slot.firstDistance = models_.distance_mm.size();
        for (const Vec3& a : m.markers_model_mm)
            for (const Vec3& b : m.markers_model_mm)
                models_.distance_mm.push_back(static_cast<float>((a - b).norm()));
        slot.firstBin = binCounts.size();
        slot.binCount = static_cast<std::size_t>(longest / binWidth) + 2;
        binCounts.resize(slot.firstBin + slot.binCount, 0);
        for (const ModelEdge& e : m.edges)
            ++binCounts[slot.firstBin + static_cast<std::size_t>(e.distance_mm / binWidth)];
        models_.slots.push_back(slot);
    }

    // Copies of one layout are found from the models themselves: model files do not say it.
    DisjointSets copiesOf(models.size());
    copiesOf.reset(models.size());
    const SminConfig copies{2.0 * config.distanceTolerance_mm, 0.8, 4};
    for (std::size_t i = 0; i < models.size(); ++i)
        for (std::size_t j = i + 1; j < models.size(); ++j)
            if (sameShape(models[i], models[j], copies))
                copiesOf.unite(i, j);
    for (std::size_t i = 0; i < models_.slots.size(); ++i)
        models_.slots[i].shapeGroup = copiesOf.find(i);

    table_.binStart.assign(binCounts.size() + 1, 0);
    for (std::size_t b = 0; b < binCounts.size(); ++b)
        table_.binStart[b + 1] = table_.binStart[b] + binCounts[b];
    table_.entries.resize(table_.binStart.back());
    std::vector<std::uint32_t> fill(table_.binStart.begin(), table_.binStart.end() - 1);
    for (std::size_t i = 0; i < models.size(); ++i)
        for (const ModelEdge& e : models[i].edges) {
            const std::size_t bin =
                models_.slots[i].firstBin + static_cast<std::size_t>(e.distance_mm / binWidth);
            table_.entries[fill[bin]++] = HashEntry{e.from, e.to, e.distance_mm};
        }

    bodies_.resize(models.size());
    for (std::size_t i = 0; i < models.size(); ++i)
        bodies_[i].modelId = models[i].id;
    history_.resize(models.size());
    searched_.assign(models.size(), 0);

    frame_.owner.assign(config.maxPoints, -1);
    frame_.explained.assign(config.maxPoints, 0);
    frame_.seeded.assign(config.maxPoints, 0);
    match_.claimant.assign(config.maxPoints, -1);
    match_.claimDistance.assign(config.maxPoints, 0.0);
    frame_.nearby.assign(config.maxPoints, 0);
    frame_.candidateCount.assign(models_.maxMarkers, 0);
    frame_.candidates.resize(models_.maxMarkers * config.maxCandidatesPerMarker);
    match_.agreement.assign(config.maxCandidatesPerMarker, 0);
    frame_.distance_mm.assign(config.maxPoints * config.maxPoints, 0.0F);
    match_.ofMarker.assign(models_.maxMarkers, -1);
    match_.bestOfMarker.assign(models_.maxMarkers, -1);
    match_.fitted.assign(models_.maxMarkers, -1);
    match_.fitFrom = BoundedVector<Vec3>(models_.maxMarkers);
    match_.fitTo = BoundedVector<Vec3>(models_.maxMarkers);
    match_.leftOutRms.assign(models_.maxMarkers, 0.0);
    match_.fitOrder.assign(models_.maxMarkers, 0);
    match_.fitMarker.assign(models_.maxMarkers, 0);
    match_.firstMatches.assign(models_.maxMarkers, -1);
    match_.refused.assign(kRememberedRefusals * models_.maxMarkers, -1);
}

void ModelTracker::reset() {
    for (std::size_t i = 0; i < bodies_.size(); ++i) {
        const std::uint32_t id = bodies_[i].modelId;
        bodies_[i] = TrackedBody{};
        bodies_[i].modelId = id;
        history_[i] = History{};
    }
}

void ModelTracker::continueBody(std::size_t body, const ModelTracker& from, std::size_t fromBody) {
    if (body >= bodies_.size() || fromBody >= from.bodies_.size())
        return;
    const std::uint32_t id = bodies_[body].modelId;
    bodies_[body] = from.bodies_[fromBody];
    bodies_[body].modelId = id;
    history_[body] = from.history_[fromBody];
}

void ModelTracker::update(double time_s, std::span<const Vec3> points_rig_mm, bool searchLost) {
    if (!valid_)
        return;
    ++counters_.frames;
    frameChecks_ = 0;
    frame_.count = std::min(points_rig_mm.size(), config_.maxPoints);
    counters_.pointOverflow += points_rig_mm.size() - frame_.count;
    frame_.points = points_rig_mm.first(frame_.count);
    std::fill_n(frame_.owner.begin(), frame_.count, std::int16_t{-1});
    std::fill(searched_.begin(), searched_.end(), std::uint8_t{0});
    frame_.distancesReady = false;

    for (std::size_t b = 0; b < bodies_.size(); ++b) {
        bodies_[b].source = PoseSource::None;
        bodies_[b].markers = 0;
        bodies_[b].rms_mm = 0.0;
        RigidTransform predicted;
        if (!predict(b, time_s, predicted))
            continue;
        if (confirmPrediction(b, predicted))
            ++counters_.predictedHits;
        else
            ++counters_.predictionFailures;
    }

    for (std::size_t b = 0; b < bodies_.size(); ++b) {
        if (bodies_[b].found() || models_.slots[b].markerCount < 4 || !searchLost)
            continue;
        if (!budgetLeft()) {
            ++counters_.searchesSkipped;
            continue;
        }
        search(b, time_s);
        searched_[b] = 1;
    }
    if (!budgetLeft())
        ++counters_.budgetExhausted;
    counters_.pairChecks += frameChecks_;

    for (std::size_t b = 0; b < bodies_.size(); ++b) {
        if (!bodies_[b].found())
            continue;
        History& h = history_[b];
        h.hasPrevious = h.hasLast && time_s - h.last_s <= config_.predictionHorizon_s;
        h.previous = h.last;
        h.previous_s = h.last_s;
        h.last = bodies_[b].T_rig_from_model;
        h.last_s = time_s;
        h.hasLast = true;
        h.typicalRms_mm =
            h.hasRms ? h.typicalRms_mm + kRmsSmoothing * (bodies_[b].rms_mm - h.typicalRms_mm)
                     : bodies_[b].rms_mm;
        h.hasRms = true;
        bodies_[b].lastFound_s = time_s;
    }
}

bool ModelTracker::predict(std::size_t body, double time_s,
                           RigidTransform& T_rig_from_model) const {
    const History& h = history_[body];
    if (!h.hasLast || time_s - h.last_s > config_.predictionHorizon_s || time_s < h.last_s)
        return false;
    T_rig_from_model = h.last;
    const double interval_s = h.last_s - h.previous_s;
    if (!h.hasPrevious || !(interval_s > 0.0))
        return true;
    // Constant velocity and turn rate of the model's centroid, so that turning does not swing
    // the prediction about a far-away model origin.
    const double ahead = (time_s - h.last_s) / interval_s;
    const Vec3& c = models_.slots[body].centroid_model_mm;
    const Vec3 lastCentre = h.last.apply(c);
    const Vec3 centre = lastCentre + ahead * (lastCentre - h.previous.apply(c));
    const Eigen::AngleAxisd turn(h.last.rotation * h.previous.rotation.inverse());
    const Quat rotation =
        (Quat(Eigen::AngleAxisd(ahead * turn.angle(), turn.axis())) * h.last.rotation).normalized();
    T_rig_from_model.rotation = rotation;
    T_rig_from_model.translation_mm = centre - rotation * c;
    return true;
}

bool ModelTracker::confirmPrediction(std::size_t body, const RigidTransform& predicted) {
    Hypothesis h;
    RigidTransform pose = predicted;
    if (!refine(body, pose, config_.predictionRadius_mm, config_.minTrackedMarkers, h))
        return false;
    accept(body, PoseSource::Predicted, h);
    return true;
}

void ModelTracker::accept(std::size_t body, PoseSource source, const Hypothesis& h) {
    TrackedBody& out = bodies_[body];
    out.source = source;
    out.T_rig_from_model = h.T_rig_from_model;
    out.markers = h.markers;
    out.rms_mm = h.rms_mm;
    for (std::size_t i = 0; i < models_.slots[body].markerCount; ++i)
        if (match_.ofMarker[i] >= 0)
            frame_.owner[static_cast<std::size_t>(match_.ofMarker[i])] =
                static_cast<std::int16_t>(body);
}

std::optional<RigidFit> ModelTracker::fitMatches(std::size_t body, std::size_t leftOut) {
    gatherMatches(body, leftOut);
    return fitRigid(match_.fitFrom.span(), match_.fitTo.span());
}

void ModelTracker::gatherMatches(std::size_t body, std::size_t leftOut) {
    const std::span<const Vec3> model = modelMarkers(body);
    match_.fitFrom.clear();
    match_.fitTo.clear();
    for (std::size_t i = 0; i < model.size(); ++i)
        if (i != leftOut && match_.ofMarker[i] >= 0) {
            match_.fitMarker[match_.fitFrom.size()] = static_cast<std::uint32_t>(i);
            match_.fitFrom.push_back(model[i]);
            match_.fitTo.push_back(frame_.points[static_cast<std::size_t>(match_.ofMarker[i])]);
        }
}

std::size_t ModelTracker::matchMarkers(std::size_t body, const RigidTransform& T_rig_from_model,
                                       double radius_mm) {
    const ModelSlot& slot = models_.slots[body];
    const std::span<const Vec3> model = modelMarkers(body);
    // Only points within the model's reach of its placed centroid can match any marker.
    const Vec3 centre = T_rig_from_model.apply(slot.centroid_model_mm);
    const double reach = slot.radius_mm + radius_mm;
    std::size_t nearbyCount = 0;
    for (std::size_t j = 0; j < frame_.count; ++j) {
        match_.claimant[j] = -1;
        if (frame_.owner[j] < 0 && (frame_.points[j] - centre).squaredNorm() <= reach * reach)
            frame_.nearby[nearbyCount++] = static_cast<std::uint16_t>(j);
    }
    const double radius2 = radius_mm * radius_mm;
    const Mat3 rotation = T_rig_from_model.rotationMatrix();
    std::size_t matches = 0;
    for (std::size_t i = 0; i < model.size(); ++i) {
        match_.ofMarker[i] = -1;
        const Vec3 placed = rotation * model[i] + T_rig_from_model.translation_mm;
        std::int32_t nearest = -1;
        double nearest2 = radius2;
        for (std::size_t n = 0; n < nearbyCount; ++n) {
            const double d2 = (frame_.points[frame_.nearby[n]] - placed).squaredNorm();
            if (d2 < nearest2) {
                nearest2 = d2;
                nearest = frame_.nearby[n];
            }
        }
        if (nearest < 0)
            continue;
        const auto j = static_cast<std::size_t>(nearest);
        // A point near two placed markers belongs to the nearer one.
        if (match_.claimant[j] >= 0) {
            if (match_.claimDistance[j] <= nearest2)
                continue;
            match_.ofMarker[static_cast<std::size_t>(match_.claimant[j])] = -1;
            --matches;
        }
        match_.claimant[j] = static_cast<std::int32_t>(i);
        match_.claimDistance[j] = nearest2;
        match_.ofMarker[i] = nearest;
        ++matches;
    }
    return matches;
}

bool ModelTracker::refine(std::size_t body, RigidTransform& T_rig_from_model, double firstRadius_mm,
                          std::size_t minMatches, Hypothesis& out, bool rememberRefusals) {
    const std::span<const Vec3> model = modelMarkers(body);
    const std::span<std::int32_t> firstMatches = std::span(match_.firstMatches).first(model.size());
    // Everything after the first matching follows from its matches alone (each fit from the
    // matches, each matching from the fit, the gate and the trim from the body's history, which
    // is fixed within a frame), so a search remembers the first matches it refused, and a clique
    // that matches as one of those is refused at once. A body whose layout is a little off is
    // matched whole by most of its cliques and refused by the gate each time: half a million
    // times in one completion pass (random_objects seed 100).
    auto refuse = [&] {
        if (rememberRefusals) {
            std::copy(firstMatches.begin(), firstMatches.end(),
                      match_.refused.begin() +
                          static_cast<std::ptrdiff_t>(match_.refusedNext * model.size()));
            match_.refusedNext = (match_.refusedNext + 1) % kRememberedRefusals;
            match_.refusedCount = std::min(match_.refusedCount + 1, kRememberedRefusals);
        }
        return false;
    };
    double radius = firstRadius_mm;
    std::size_t matches = 0;
    bool fitted = false;
    for (int pass = 0; pass < kMaxPasses; ++pass) {
        matches = matchMarkers(body, T_rig_from_model, radius);
        if (matches < std::max<std::size_t>(minMatches, 3))
            return pass == 0 ? false : refuse();
        if (pass == 0 && rememberRefusals) {
            std::copy_n(match_.ofMarker.begin(), model.size(), firstMatches.begin());
            for (std::size_t r = 0; r < match_.refusedCount; ++r)
                if (std::equal(firstMatches.begin(), firstMatches.end(),
                               match_.refused.begin() +
                                   static_cast<std::ptrdiff_t>(r * model.size()))) {
                    ++counters_.repeatedRefusals;
                    return false;
                }
        }
        // The same matches as the last fit: that fit is the answer.
        if (fitted &&
            std::equal(match_.ofMarker.begin(),
                       match_.ofMarker.begin() + static_cast<std::ptrdiff_t>(model.size()),
                       match_.fitted.begin()))
            break;
        const std::optional<RigidFit> fit = fitMatches(body);
        if (!fit)
            return refuse();
        T_rig_from_model = fit->transform;
        out.rms_mm = fit->rms_mm;
        std::copy_n(match_.ofMarker.begin(), model.size(), match_.fitted.begin());
        fitted = true;
        radius = config_.matchRadius_mm;
    }
    // The matches must be those the final pose was fitted to.
    std::copy_n(match_.fitted.begin(), model.size(), match_.ofMarker.begin());
    matches = trimOutliers(body, T_rig_from_model, matches, std::max<std::size_t>(minMatches, 3),
                           out.rms_mm);
    out.T_rig_from_model = T_rig_from_model;
    out.markers = static_cast<std::uint32_t>(matches);
    if (out.rms_mm > rmsGate(body))
        return refuse();
    if (!spreadOffOneLine(body)) {
        ++counters_.degeneratePoses;
        return refuse();
    }
    return true;
}

bool ModelTracker::spreadOffOneLine(std::size_t body) const {
    const std::span<const Vec3> model = modelMarkers(body);
    Vec3 centroid = Vec3::Zero();
    std::size_t n = 0;
    for (std::size_t i = 0; i < model.size(); ++i)
        if (match_.ofMarker[i] >= 0) {
            centroid += model[i];
            ++n;
        }
    if (n < 3)
        return false;
    centroid /= static_cast<double>(n);
    Mat3 scatter = Mat3::Zero();
    for (std::size_t i = 0; i < model.size(); ++i)
        if (match_.ofMarker[i] >= 0)
            scatter += (model[i] - centroid) * (model[i] - centroid).transpose();
    // The eigenvector of the largest eigenvalue is the line that fits the markers best.
    const Eigen::SelfAdjointEigenSolver<Mat3> eigen(scatter);
    const Vec3 axis = eigen.eigenvectors().col(2);
    const double spread2 = config_.minPoseSpread_mm * config_.minPoseSpread_mm;
    for (std::size_t i = 0; i < model.size(); ++i)
        if (match_.ofMarker[i] >= 0) {
            const Vec3 offset = model[i] - centroid;
            if ((offset - offset.dot(axis) * axis).squaredNorm() >= spread2)
                return true;
        }
    return false;
}

std::size_t ModelTracker::trimOutliers(std::size_t body, RigidTransform& T_rig_from_model,
                                       std::size_t matches, std::size_t minMatches,
                                       double& rms_mm) {
    const std::span<const Vec3> model = modelMarkers(body);
    // An outlier pulls the fit towards itself, so it is judged against the fit of the others:
    // each match is left out in turn, and the one whose absence fits best is the suspect.
    // The RMS of every leave-one-out fit comes from leaveOneOutRms, and only the suspect is
    // fitted: a fit per match made trimming most of the tracker's time on large noisy layouts.
    const double suspicious_mm = 0.5 * rmsGate(body);
    for (int trim = 0; trim < kMaxTrims && matches > minMatches && rms_mm > suspicious_mm; ++trim) {
        double bestRms = rms_mm;
        std::size_t suspect = model.size();
        RigidTransform suspectFit;
        gatherMatches(body);
        const std::size_t pairs = match_.fitFrom.size();
        const std::span<double> leftOutRms = std::span(match_.leftOutRms).first(pairs);
        if (leaveOneOutRms(match_.fitFrom.span(), match_.fitTo.span(), leftOutRms)) {
            // Markers by their leave-one-out RMS (in marker order where equal); the first whose
            // own fit exists (it is not collinear) and betters the current one is the suspect,
            // as with a fit of each.
            const std::span<std::uint32_t> order = std::span(match_.fitOrder).first(pairs);
            std::iota(order.begin(), order.end(), 0U);
            std::sort(order.begin(), order.end(), [&](std::uint32_t x, std::uint32_t y) {
                return leftOutRms[x] < leftOutRms[y] || (leftOutRms[x] == leftOutRms[y] && x < y);
            });
            // The candidates that could better the current fit, as markers, before any refit:
            // fitMatches() gathers the pairs again without the one left out, which renumbers them.
            std::size_t candidates = 0;
            for (; candidates < pairs && leftOutRms[order[candidates]] < rms_mm; ++candidates)
                order[candidates] = match_.fitMarker[order[candidates]];
            for (const std::uint32_t left : order.first(candidates)) {
                const std::optional<RigidFit> fit = fitMatches(body, left);
                if (fit && fit->rms_mm < bestRms) {
                    bestRms = fit->rms_mm;
                    suspect = left;
                    suspectFit = fit->transform;
                    break;
                }
            }
        } else {
            for (std::size_t left = 0; left < model.size(); ++left) {
                if (match_.ofMarker[left] < 0)
                    continue;
                const std::optional<RigidFit> fit = fitMatches(body, left);
                if (fit && fit->rms_mm < bestRms) {
                    bestRms = fit->rms_mm;
                    suspect = left;
                    suspectFit = fit->transform;
                }
            }
        }
        if (suspect == model.size())
            break;
        const double residual = (frame_.points[static_cast<std::size_t>(match_.ofMarker[suspect])] -
                                 suspectFit.apply(model[suspect]))
                                    .norm();
        if (residual <= std::max(config_.outlierFloor_mm, config_.outlierFactor * bestRms))
            break;
        match_.ofMarker[suspect] = -1;
        --matches;
        T_rig_from_model = suspectFit;
        rms_mm = bestRms;
    }
    return matches;
}

void ModelTracker::search(std::size_t body, double time_s) {
    std::size_t freePoints = 0;
    for (std::size_t p = 0; p < frame_.count; ++p)
        freePoints += frame_.owner[p] < 0;
    if (freePoints < models_.slots[body].sMin)
        return;
    ++counters_.searches;
    if (!frame_.distancesReady) {
        // Every search of the frame looks up the same pairs; their distances are computed once.
        for (std::size_t i = 0; i < frame_.count; ++i) {
            frame_.distance_mm[i * frame_.count + i] = 0.0F;
            for (std::size_t j = i + 1; j < frame_.count; ++j) {
                const auto d = static_cast<float>((frame_.points[i] - frame_.points[j]).norm());
                frame_.distance_mm[i * frame_.count + j] = d;
                frame_.distance_mm[j * frame_.count + i] = d;
            }
        }
        frame_.distancesReady = true;
    }
    std::fill_n(frame_.explained.begin(), frame_.count, std::uint8_t{0});
    std::fill_n(frame_.seeded.begin(), frame_.count, std::uint8_t{0});
    match_.refusedCount = 0;
    match_.refusedNext = 0;
    Hypothesis best;
    bool haveBest = false;
    for (std::size_t p = 0; p < frame_.count; ++p) {
        if (frame_.owner[p] >= 0 || frame_.explained[p])
            continue;
        if (!budgetLeft()) {
            ++counters_.searchesSkipped;
            break;
        }
        // Once every clique holding p was looked at from p, a later seed's clique with p in it
        // would be one of those.
        frame_.seeded[p] = searchFrom(body, p, time_s, best, haveBest);
    }
    if (!haveBest)
        return;
    ++counters_.searchHits;
    std::copy_n(match_.bestOfMarker.begin(), models_.slots[body].markerCount,
                match_.ofMarker.begin());
    accept(body, PoseSource::Searched, best);
}

bool ModelTracker::searchFrom(std::size_t body, std::size_t p, double time_s, Hypothesis& best,
                              bool& haveBest) {
    const ModelSlot& slot = models_.slots[body];
    const double tolerance = config_.distanceTolerance_mm;
    const std::size_t perMarker = config_.maxCandidatesPerMarker;
    std::fill_n(frame_.candidateCount.begin(), slot.markerCount, 0U);
    bool dropped = false;
    auto addCandidate = [&](std::size_t marker, std::size_t point, std::size_t other) {
        std::uint32_t& count = frame_.candidateCount[marker];
        if (count >= perMarker) {
            ++counters_.candidateOverflow;
            dropped = true;
            return;
        }
        frame_.candidates[marker * perMarker + count++] =
            Candidate{static_cast<std::uint16_t>(point), static_cast<std::uint16_t>(other)};
    };

    // The hashtable lookups: every free point q at a model edge's length from p.
    for (std::size_t q = 0; q < frame_.count; ++q) {
        if (q == p || frame_.owner[q] >= 0 || frame_.seeded[q])
            continue;
        ++frameChecks_;
        const double d = pointDistance(p, q);
        const auto bin = static_cast<std::size_t>(d / tolerance);
        const std::size_t firstBin = bin > 0 ? bin - 1 : 0;
        const std::size_t lastBin = std::min(bin + 1, slot.binCount - 1);
        for (std::size_t b = firstBin; b <= lastBin; ++b) {
            const std::size_t global = slot.firstBin + b;
            for (std::uint32_t e = table_.binStart[global]; e < table_.binStart[global + 1]; ++e) {
                const HashEntry& entry = table_.entries[e];
                if (std::abs(entry.distance_mm - d) > tolerance)
                    continue;
                addCandidate(entry.a, q, entry.b);
                addCandidate(entry.b, q, entry.a);
            }
        }
    }

    // Two candidates of one marker V (p's possible identity) agree when they are different
    // points and markers, co-visible, and as far apart as their markers (below).
    const float* modelDistance = &models_.distance_mm[slot.firstDistance];
    const auto toleranceF = static_cast<float>(tolerance);

    // A body found with m markers, p among them as marker v, shows m - 1 candidates of v that
    // agree pairwise (markers seen together are co-visible; their distances match). So only
    // candidates that agree with at least S_min - 2 others (the (S_min - 2)-core of the agreement
    // graph) can take part, and a 4-clique is three of them that agree with each other.
    const std::size_t degreeNeeded = std::max<std::size_t>(slot.sMin, 4) - 2;
    for (std::size_t v = 0; v < slot.markerCount; ++v) {
        const std::size_t count = frame_.candidateCount[v];
        if (count < degreeNeeded + 1)
            continue;
        if (!budgetLeft())
            return false;
        const Candidate* list = &frame_.candidates[v * perMarker];
        std::uint64_t* agreement = match_.agreement.data();
        for (std::size_t a = 0; a < count; ++a)
            agreement[a] = 0;
        // The row of a is gathered in a register: this pair walk is most of a search's time.
        for (std::size_t a = 0; a < count; ++a) {
            const Candidate x = list[a];
            const MarkerSet& coVisible = adjacency(body, x.marker);
            const float* frameRow = &frame_.distance_mm[x.point * frame_.count];
            const float* modelRow = &modelDistance[x.marker * slot.markerCount];
            std::uint64_t row = agreement[a];
            // Without branches: whether a pair agrees is as good as random to a predictor.
            for (std::size_t b = a + 1; b < count; ++b) {
                const Candidate y = list[b];
                const std::uint64_t agrees =
                    std::uint64_t{y.point != x.point} & std::uint64_t{y.marker != x.marker} &
                    std::uint64_t{coVisible.contains(y.marker)} &
                    std::uint64_t{std::abs(frameRow[y.point] - modelRow[y.marker]) <= toleranceF};
                row |= agrees << b;
                agreement[b] |= agrees << a;
            }
            agreement[a] = row;
        }
        frameChecks_ += count * (count - 1) / 2;
        std::uint64_t alive = count == 64 ? ~std::uint64_t{0} : (std::uint64_t{1} << count) - 1;
        for (bool pruned = true; pruned;) {
            pruned = false;
            for (std::uint64_t rest = alive; rest != 0; rest &= rest - 1) {
                const auto a = static_cast<std::size_t>(std::countr_zero(rest));
                if (static_cast<std::size_t>(std::popcount(match_.agreement[a] & alive)) <
                    degreeNeeded) {
                    alive &= ~(std::uint64_t{1} << a);
                    pruned = true;
                }
            }
        }
        for (std::uint64_t restA = alive; restA != 0; restA &= restA - 1) {
            const auto a = static_cast<std::size_t>(std::countr_zero(restA));
            const std::uint64_t withA =
                match_.agreement[a] & alive & ~((std::uint64_t{2} << a) - 1);
            for (std::uint64_t restB = withA; restB != 0; restB &= restB - 1) {
                const auto b = static_cast<std::size_t>(std::countr_zero(restB));
                const std::uint64_t withAB =
                    withA & match_.agreement[b] & ~((std::uint64_t{2} << b) - 1);
                for (std::uint64_t restC = withAB; restC != 0; restC &= restC - 1) {
                    const auto c = static_cast<std::size_t>(std::countr_zero(restC));
                    if (!budgetLeft())
                        return false;
                    const Candidate clique[4] = {
                        Candidate{static_cast<std::uint16_t>(p), static_cast<std::uint16_t>(v)},
                        list[a], list[b], list[c]};
                    evaluateClique(body, clique, time_s, best, haveBest);
                    // p is explained once one of its cliques gave a body: its other cliques
                    // would only find the same pose again.
                    if (frame_.explained[p])
                        return false;
                }
            }
        }
    }
    return !dropped;
}

void ModelTracker::evaluateClique(std::size_t body, std::span<const Candidate> clique,
                                  double time_s, Hypothesis& best, bool& haveBest) {
    ++counters_.hypotheses;
    frameChecks_ += kHypothesisCost;
    const std::span<const Vec3> model = modelMarkers(body);
    Vec3 from[4];
    Vec3 to[4];
    for (std::size_t i = 0; i < 4; ++i) {
        from[i] = model[clique[i].marker];
        to[i] = frame_.points[clique[i].point];
    }
    // Most cliques of a search fail the gate; their residual alone tells so, without the SVD.
    // A margin of 1e-6 mm keeps the test fitRigid's wherever the two could differ.
    const double gate = rmsGate(body);
    const std::optional<double> rms = fitRms(from, to);
    if (rms && *rms > gate + 1e-6)
        return;
    const std::optional<RigidFit> fit = fitRigid(from, to);
    if (!fit || fit->rms_mm > gate)
        return;
    RigidTransform pose = fit->transform;
    Hypothesis h;
    if (!refine(body, pose, config_.matchRadius_mm, models_.slots[body].sMin, h,
                /*rememberRefusals=*/true))
        return;
    for (std::size_t i = 0; i < models_.slots[body].markerCount; ++i)
        if (match_.ofMarker[i] >= 0)
            frame_.explained[static_cast<std::size_t>(match_.ofMarker[i])] = 1;
    const Vec3 centre = h.T_rig_from_model.apply(models_.slots[body].centroid_model_mm);
    if (nearerCopyWants(body, centre, time_s)) {
        ++counters_.identityYields;
        return;
    }
    bool better = !haveBest;
    if (haveBest) {
        const History& history = history_[body];
        if (hasCopy(body) && remembers(body, time_s)) {
            // Copies keep their identity by position: the hypothesis nearest to where it was.
            const Vec3 last = history.last.apply(models_.slots[body].centroid_model_mm);
            const Vec3 bestCentre =
                best.T_rig_from_model.apply(models_.slots[body].centroid_model_mm);
            better = (centre - last).squaredNorm() < (bestCentre - last).squaredNorm();
        } else {
            better =
                h.markers > best.markers || (h.markers == best.markers && h.rms_mm < best.rms_mm);
        }
    }
    if (!better)
        return;
    best = h;
    haveBest = true;
    std::copy_n(match_.ofMarker.begin(), models_.slots[body].markerCount,
                match_.bestOfMarker.begin());
}

double ModelTracker::rmsGate(std::size_t body) const {
    const History& h = history_[body];
    if (!h.hasRms)
        return config_.maxRms_mm;
    return std::min(config_.maxRms_mm,
                    std::max(config_.rmsGateFloor_mm, config_.rmsGateFactor * h.typicalRms_mm));
}

bool ModelTracker::hasCopy(std::size_t body) const {
    for (std::size_t o = 0; o < models_.slots.size(); ++o)
        if (o != body && models_.slots[o].shapeGroup == models_.slots[body].shapeGroup)
            return true;
    return false;
}

bool ModelTracker::remembers(std::size_t body, double time_s) const {
    const History& h = history_[body];
    return h.hasLast && time_s - h.last_s <= config_.identityMemory_s;
}

bool ModelTracker::nearerCopyWants(std::size_t body, const Vec3& centre_rig_mm,
                                   double time_s) const {
    const double own =
        remembers(body, time_s)
            ? (history_[body].last.apply(models_.slots[body].centroid_model_mm) - centre_rig_mm)
                  .squaredNorm()
            : std::numeric_limits<double>::infinity();
    for (std::size_t o = 0; o < models_.slots.size(); ++o) {
        if (o == body || models_.slots[o].shapeGroup != models_.slots[body].shapeGroup ||
            bodies_[o].found() || searched_[o] || !remembers(o, time_s))
            continue;
        const double theirs =
            (history_[o].last.apply(models_.slots[o].centroid_model_mm) - centre_rig_mm)
                .squaredNorm();
        if (theirs < own)
            return true;
    }
    return false;
}

} // namespace edgetrack
