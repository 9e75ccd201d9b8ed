// Object calibration, steps 5 and 6: reappearing markers recognised at their predicted places,
// new markers added to posed objects or starting new ones, lost objects found again.
#include <algorithm>
#include <cmath>

#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

// --- Step 5: new markers near an occluded marker's predicted place are that marker. -----------

void ObjectCalibrator::recogniseReappearing(std::span<const TrackedMarker> tracked) {
    const double radius2 = config_.reappearRadius_mm * config_.reappearRadius_mm;
    for (std::size_t t = 0; t < tracked.size(); ++t) {
        if (knownOfTracked_[t] != kNone)
            continue;
        const Vec3& p = tracked[t].position_rig_mm;
        std::size_t best = kNone;
        double bestDistance2 = radius2;
        for (const Object& o : objects_) {
            if (!o.active || !o.posed)
                continue;
            for (const Member& member : o.members) {
                if (markers_[member.marker].visible)
                    continue;
                const double d2 = (o.T_rig_from_object.apply(member.model_mm) - p).squaredNorm();
                if (d2 <= bestDistance2) {
                    bestDistance2 = d2;
                    best = member.marker;
                }
            }
        }
        if (best == kNone)
            continue;
        KnownMarker& m = markers_[best];
        m.visible = true;
        m.trackerId = tracked[t].id;
        m.position_rig_mm = p;
        ++m.framesSeen;
        knownOfTracked_[t] = best;
        ++counters_.markersReappeared;
    }
}

// --- Step 6: other new markers join every posed object, or start one. --------------------------

void ObjectCalibrator::insertNewMarkers(std::span<const TrackedMarker> tracked) {
    for (std::size_t t = 0; t < tracked.size(); ++t) {
        if (knownOfTracked_[t] != kNone)
            continue;
        const std::size_t k = newMarker(tracked[t].id, tracked[t].position_rig_mm);
        if (k == kNone)
            continue;
        knownOfTracked_[t] = k;
        ++counters_.markersBorn;
    }
    // Markers in no object: this frame's new ones and any still waiting for an object.
    candidates_.clear();
    for (std::size_t k = 0; k < markers_.size(); ++k) {
        const KnownMarker& m = markers_[k];
        if (m.used && m.visible && m.objectCount == 0 &&
            (!m.rejected || counters_.frames - m.rejectedAtFrame >= kRetryRejected_frames))
            candidates_.push_back(k);
    }
    if (candidates_.empty())
        return;
    // The paper's future work: an object that was lost (out of view, or too few markers) is found
    // again among the new markers with its partial model, and they take back their identities.
    for (Object& o : objects_)
        if (o.active && !o.posed && candidates_.size() >= kRefindMinMarkers)
            refind(o);
    if (candidates_.empty())
        return;

    auto connectToVisible = [&](Object& o, std::size_t newMember) {
        const Vec3& p = markers_[o.members[newMember].marker].position_rig_mm;
        for (std::size_t i = 0; i < o.members.size(); ++i) {
            if (i == newMember || !markers_[o.members[i].marker].visible)
                continue;
            const double d = (p - markers_[o.members[i].marker].position_rig_mm).norm();
            edge(o, i, newMember) = Edge{EdgeState::Active, false, 1, d, d};
        }
    };

    bool inserted = false;
    for (Object& o : objects_) {
        if (!o.active || !o.posed)
            continue;
        const RigidTransform T_object_from_rig = o.T_rig_from_object.inverse();
        for (std::size_t k : candidates_) {
            if (!addMember(o, k, T_object_from_rig.apply(markers_[k].position_rig_mm)))
                continue;
            o.members.back().visible = true;
            connectToVisible(o, o.members.size() - 1);
            inserted = true;
        }
    }
    if (inserted || candidates_.size() < config_.minModelMarkers)
        return;
    // Nothing in view to join: these markers start an object in the rig's frame, as all visible
    // markers do at the start of a calibration.
    Object* o = newObject();
    if (o == nullptr) {
        ++counters_.objectOverflow;
        return;
    }
    for (std::size_t k : candidates_) {
        if (!addMember(*o, k, markers_[k].position_rig_mm))
            continue;
        o->members.back().visible = true;
        connectToVisible(*o, o->members.size() - 1);
    }
    o->posed = true;
    o->T_rig_from_object = RigidTransform::identity();
}

bool ObjectCalibrator::indexMemberPairs(const Object& o, Members which) {
    auto searched = [this, which](const Member& m) { return selects(which, m); };
    // Member pairs sorted by distance, so a candidate pair's distance finds its model pairs fast.
    memberPairs_.clear();
    const std::size_t n = o.members.size();
    for (std::size_t i = 0; i < n; ++i) {
        if (!searched(o.members[i]))
            continue;
        for (std::size_t j = 0; j < n; ++j)
            if (j != i && searched(o.members[j]))
                memberPairs_.push_back(
                    {(o.members[i].model_mm - o.members[j].model_mm).norm(), i, j});
    }
    if (memberPairs_.size() < 6)
        return false;
    std::sort(
        memberPairs_.begin(), memberPairs_.end(),
        [](const MemberPair& a, const MemberPair& b) { return a.distance_mm < b.distance_mm; });
    // The same pairs grouped by first member (a counting sort, so each member's stay by
    // distance): a triangle's third corner is then looked up by its distance from the first,
    // not sought among all members.
    pairsOfMemberStart_.clear();
    pairsOfMemberStart_.resize(n + 1);
    std::fill(pairsOfMemberStart_.begin(), pairsOfMemberStart_.end(), std::size_t{0});
    for (const MemberPair& pair : memberPairs_)
        ++pairsOfMemberStart_[pair.i + 1];
    for (std::size_t i = 0; i < n; ++i)
        pairsOfMemberStart_[i + 1] += pairsOfMemberStart_[i];
    pairsByMember_.clear();
    pairsByMember_.resize(memberPairs_.size());
    for (const MemberPair& pair : memberPairs_)
        pairsByMember_[pairsOfMemberStart_[pair.i]++] = pair;
    for (std::size_t i = n; i > 0; --i)
        pairsOfMemberStart_[i] = pairsOfMemberStart_[i - 1];
    pairsOfMemberStart_[0] = 0;
    searchedMembers_.clear();
    for (const Member& m : o.members)
        if (searched(m))
            searchedMembers_.push_back(m.model_mm);
    return true;
}

std::optional<RigidTransform> ObjectCalibrator::fitLayout(const Object& o,
                                                          std::span<const Vec3> points,
                                                          Members which, std::size_t minPoints,
                                                          double share) {
    if (points.size() < minPoints)
        return std::nullopt;
    if (!indexMemberPairs(o, which))
        return std::nullopt;
    const double radius2 = config_.reappearRadius_mm * config_.reappearRadius_mm;
    const double tol = config_.smin.tolerance_mm;
    const auto byDistance = [](const MemberPair& p, double d) { return p.distance_mm < d; };
    const std::size_t c = points.size();
    std::size_t budget = kRefindBudget;
    std::optional<RigidTransform> best;
    std::size_t bestCount = minPoints - 1;
    // Every point on a member: no later triangle can place more, and the search is done.
    auto searching = [&] { return budget > 0 && bestCount < c; };
    for (std::size_t a = 0; a < c && searching(); ++a)
        for (std::size_t b = a + 1; b < c && searching(); ++b) {
            const double dab = (points[a] - points[b]).norm();
            const auto* first =
                std::lower_bound(memberPairs_.begin(), memberPairs_.end(), dab - tol, byDistance);
            for (const auto* pair = first;
                 pair != memberPairs_.end() && pair->distance_mm <= dab + tol && searching();
                 ++pair) {
                const Vec3& mi = o.members[pair->i].model_mm;
                const Vec3& mj = o.members[pair->j].model_mm;
                for (std::size_t cc = b + 1; cc < c && searching(); ++cc) {
                    --budget;
                    const double dac = (points[a] - points[cc]).norm();
                    const double dbc = (points[b] - points[cc]).norm();
                    // Members dac from mi (its pairs by distance), and dbc from mj; tried in the
                    // order of their index, as a scan of all members would.
                    thirdCorners_.clear();
                    const MemberPair* fromI = pairsByMember_.begin() + pairsOfMemberStart_[pair->i];
                    const MemberPair* endI =
                        pairsByMember_.begin() + pairsOfMemberStart_[pair->i + 1];
                    for (const MemberPair* third =
                             std::lower_bound(fromI, endI, dac - tol, byDistance);
                         third != endI && third->distance_mm <= dac + tol && budget > 0; ++third) {
                        --budget;
                        if (third->j != pair->j &&
                            std::abs((mj - o.members[third->j].model_mm).norm() - dbc) <= tol)
                            thirdCorners_.push_back(third->j);
                    }
                    std::sort(thirdCorners_.begin(), thirdCorners_.end());
                    for (const std::size_t l : thirdCorners_) {
                        // A try counts the points on members: as many steps as points.
                        if (budget < c) {
                            budget = 0;
                            break;
                        }
                        budget -= c;
                        const Member& ml = o.members[l];
                        const std::optional<RigidTransform> fit =
                            fitTriangle({mi, mj, ml.model_mm}, {points[a], points[b], points[cc]});
                        if (!fit)
                            continue;
                        // The points on a member (as memberNear() finds them, with each
                        // member placed once), given up once they can no longer beat the best.
                        placedMembers_.clear();
                        for (const Vec3& m : searchedMembers_)
                            placedMembers_.push_back(fit->apply(m));
                        std::size_t count = 0;
                        for (std::size_t k = 0; k < c && count + (c - k) > bestCount; ++k)
                            count += std::any_of(placedMembers_.begin(), placedMembers_.end(),
                                                 [&](const Vec3& placed) {
                                                     return (placed - points[k]).squaredNorm() <=
                                                            radius2;
                                                 });
                        if (count > bestCount) {
                            bestCount = count;
                            best = *fit;
                        }
                    }
                }
            }
        }
    if (budget == 0)
        ++counters_.refindBudgetExhausted;
    // A few markers can fit a wrong place of a large model by chance; most of what is seen must
    // sit on the model, and all of it tightly once fitted together.
    if (!best || static_cast<double>(bestCount) < share * static_cast<double>(c))
        return std::nullopt;
    fitFrom_.clear();
    fitTo_.clear();
    for (std::size_t k = 0; k < c; ++k)
        if (const std::size_t m = memberNear(o, *best, points[k], which); m != kNone) {
            fitFrom_.push_back(o.members[m].model_mm);
            fitTo_.push_back(points[k]);
        }
    const std::optional<RigidFit> refit = fitRigid(fitFrom_.span(), fitTo_.span());
    if (!refit || refit->rms_mm > config_.poseInlier_mm)
        return std::nullopt;
    return refit->transform;
}

std::size_t ObjectCalibrator::memberNear(const Object& o, const RigidTransform& T_to_from_object,
                                         const Vec3& p_mm, Members which) const {
    const double radius2 = config_.reappearRadius_mm * config_.reappearRadius_mm;
    for (std::size_t i = 0; i < o.members.size(); ++i) {
        const Member& m = o.members[i];
        if (selects(which, m) &&
            (T_to_from_object.apply(m.model_mm) - p_mm).squaredNorm() <= radius2)
            return i;
    }
    return kNone;
}

void ObjectCalibrator::refind(Object& o) {
    searchPoints_.clear();
    for (const std::size_t k : candidates_)
        searchPoints_.push_back(markers_[k].position_rig_mm);
    const std::optional<RigidTransform> best =
        fitLayout(o, searchPoints_.span(), Members::Occluded);
    if (!best)
        return;
    // The candidates near a member's place are that member, seen again.
    for (std::size_t k = candidates_.size(); k-- > 0;) {
        const std::size_t fresh = candidates_[k];
        const std::size_t i =
            memberNear(o, *best, markers_[fresh].position_rig_mm, Members::Occluded);
        if (i == kNone)
            continue;
        KnownMarker& known = markers_[o.members[i].marker];
        known.visible = true;
        known.trackerId = markers_[fresh].trackerId;
        known.position_rig_mm = markers_[fresh].position_rig_mm;
        ++known.framesSeen;
        releaseMarker(fresh);
        o.members[i].visible = true;
        candidates_.swapRemove(k);
        ++counters_.markersReappeared;
    }
    o.posed = true;
    o.T_rig_from_object = *best;
    ++counters_.refound;
}

} // namespace edgetrack
