// Which learnt model is which known body: where both were in the calibration session's frames.
#include "firmware_app/firmware/known_in_session.hpp"

#include <algorithm>

#include "core/rigid_fit.hpp"

namespace edgetrack::app {

namespace {

/// How long before a sighting the learnt models are followed (s): long enough for the tracker to
/// find a body from scratch and follow it into the sighting's frame through a few frames in which
/// fewer than its S_min markers show.
constexpr double kFollow_s = 0.5;

/// The index of the session frame taken at \a time_s, if the buffer kept it. The board passes the
/// same time to the session and to its tracker, so the match is exact.
std::optional<std::size_t> frameAt(const SessionBuffer& frames, double time_s) {
    std::size_t low = 0;
    std::size_t high = frames.frames();
    while (low < high) {
        const std::size_t middle = (low + high) / 2;
        if (frames.time_s(middle) < time_s)
            low = middle + 1;
        else
            high = middle;
    }
    if (low < frames.frames() && frames.time_s(low) == time_s)
        return low;
    return std::nullopt;
}

/// The learnt model \a learnt placed at \a T_rig_from_learnt against the known body \a known at
/// \a T_rig_from_known: the markers that coincide, and the registration fitted over them.
std::optional<SameObject> coincide(const MarkerModel& known, const RigidTransform& T_rig_from_known,
                                   const MarkerModel& learnt,
                                   const RigidTransform& T_rig_from_learnt, double tolerance_mm) {
    const MarkerPairs pairs = coincidingMarkers(
        learnt, known, T_rig_from_known.inverse() * T_rig_from_learnt, tolerance_mm);
    if (pairs.learnt_mm.size() < 3 || !offOneLine(pairs.known_mm, 2.0 * tolerance_mm))
        return std::nullopt;
    const std::optional<RigidFit> fit = fitRigid(pairs.learnt_mm, pairs.known_mm);
    if (!fit || fit->rms_mm > tolerance_mm)
        return std::nullopt;
    SameObject same;
    same.T_known_from_learnt = fit->transform;
    same.sharedMarkers = pairs.learnt_mm.size();
    return same;
}

} // namespace

MarkerPairs coincidingMarkers(const MarkerModel& learnt, const MarkerModel& known,
                              const RigidTransform& T_known_from_learnt, double tolerance_mm) {
    MarkerPairs pairs;
    std::vector<bool> taken(known.markers_model_mm.size(), false);
    for (const Vec3& n : learnt.markers_model_mm) {
        const Vec3 at = T_known_from_learnt.apply(n);
        std::size_t best = taken.size();
        double bestDistance2 = tolerance_mm * tolerance_mm;
        for (std::size_t m = 0; m < known.markers_model_mm.size(); ++m)
            if (const double d2 = (known.markers_model_mm[m] - at).squaredNorm();
                !taken[m] && d2 <= bestDistance2) {
                best = m;
                bestDistance2 = d2;
            }
        if (best == taken.size())
            continue;
        taken[best] = true;
        pairs.learnt_mm.push_back(n);
        pairs.known_mm.push_back(known.markers_model_mm[best]);
    }
    return pairs;
}

std::vector<SameObject>
findKnownInSession(const SessionBuffer& frames, std::span<const MarkerModel> known,
                   std::span<const KnownSighting> sightings, std::span<const MarkerModel> learnt,
                   const ModelTrackingConfig& tracking, double tolerance_mm) {
    if (sightings.empty() || learnt.empty() || frames.frames() == 0)
        return {};
    ModelTracker tracker(learnt, tracking);
    if (!tracker.isValid())
        return {};
    std::vector<double> times;
    for (const KnownSighting& s : sightings)
        times.push_back(s.time_s);
    std::sort(times.begin(), times.end());
    times.erase(std::unique(times.begin(), times.end()), times.end());

    std::vector<SameObject> candidates;
    for (const double time_s : times) {
        const std::optional<std::size_t> last = frameAt(frames, time_s);
        if (!last)
            continue;
        std::size_t first = *last;
        while (first > 0 && frames.time_s(first - 1) >= time_s - kFollow_s)
            --first;
        tracker.reset();
        for (std::size_t f = first; f <= *last; ++f)
            tracker.update(frames.time_s(f), frames.points(f));
        for (const KnownSighting& s : sightings) {
            if (s.time_s != time_s || s.known >= known.size())
                continue;
            for (std::size_t l = 0; l < learnt.size(); ++l) {
                const TrackedBody& body = tracker.bodies()[l];
                if (!body.found())
                    continue;
                std::optional<SameObject> same =
                    coincide(known[s.known], s.T_rig_from_model, learnt[l], body.T_rig_from_model,
                             tolerance_mm);
                if (!same)
                    continue;
                same->known = s.known;
                same->learnt = l;
                candidates.push_back(*same);
            }
        }
    }
    // Each object once, the pairs that share the most markers first.
    std::stable_sort(
        candidates.begin(), candidates.end(),
        [](const SameObject& a, const SameObject& b) { return a.sharedMarkers > b.sharedMarkers; });
    std::vector<SameObject> pairs;
    for (const SameObject& c : candidates)
        if (std::none_of(pairs.begin(), pairs.end(), [&](const SameObject& p) {
                return p.known == c.known || p.learnt == c.learnt;
            }))
            pairs.push_back(c);
    return pairs;
}

} // namespace edgetrack::app
