// Object calibration, step 2: each object's graph and pose from its visible members, elastic
// edges, and the pose that predicts occluded markers.
#include <algorithm>
#include <array>
#include <cmath>

#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

// --- Step 2 and the pose of step 5. ------------------------------------------------------------

void ObjectCalibrator::updateObject(Object& o) {
    for (Member& member : o.members)
        member.visible = markers_[member.marker].visible;
    fitPose(o);

    // Where each member is now: seen, or predicted by the pose when it was reliable the last
    // time it was seen. A visible marker that moves against an occluded one's prediction breaks
    // their edge too; without this, edges to occluded markers would never break and would hold
    // objects together that have long moved apart.
    const std::size_t n = o.members.size();
    positionNow_.clear();
    whereabouts_.clear();
    for (const Member& m : o.members) {
        positionNow_.push_back(m.visible ? markers_[m.marker].position_rig_mm
                                         : o.T_rig_from_object.apply(m.model_mm));
        whereabouts_.push_back(m.visible           ? Whereabouts::Seen
                               : predictable(o, m) ? Whereabouts::Predicted
                                                   : Whereabouts::Unknown);
    }
    // A member that has been out of track long enough leaves the clustering (see
    // clusterObject); if it held together members whose edge broke, the object clusters again
    // now, as no edge may break any more to make it.
    for (std::size_t i = 0; i < n; ++i)
        if (whereabouts_[i] == Whereabouts::Unknown &&
            counters_.frames - o.members[i].lastSeenFrame == config_.untrackedHidden_frames &&
            bridgesABreak(o, i))
            o.dirty = true;
    for (std::size_t i = 0; i < n; ++i) {
        if (whereabouts_[i] == Whereabouts::Unknown)
            continue;
        for (std::size_t j = i + 1; j < n; ++j) {
            // Unknown, or both predicted: nothing measured.
            if (whereabouts_[j] == Whereabouts::Unknown ||
                (whereabouts_[i] == Whereabouts::Predicted &&
                 whereabouts_[j] == Whereabouts::Predicted))
                continue;
            Edge& e = edge(o, i, j);
            if (whereabouts_[i] == Whereabouts::Seen && whereabouts_[j] == Whereabouts::Seen &&
                o.posed && o.members[i].inlier && o.members[j].inlier)
                e.coVisible = true;
            if (e.state != EdgeState::Active)
                continue;
            const double d = (positionNow_[i] - positionNow_[j]).norm();
            e.recent_mm += edgeAlpha_ * (d - e.recent_mm);
            if (std::abs(e.recent_mm - e.mean_mm) > config_.edgeBreak_mm) {
                e.state = EdgeState::Broken;
                e.brokenUnseen =
                    whereabouts_[i] != Whereabouts::Seen || whereabouts_[j] != Whereabouts::Seen;
                o.dirty = true;
                ++counters_.edgesBroken;
            } else {
                e.samples = std::min(e.samples + 1, config_.modelAverage_frames);
                e.mean_mm += (d - e.mean_mm) / e.samples;
            }
        }
    }
    for (Member& m : o.members)
        if (m.visible) {
            m.partnersLeftUnseen = 0;
            m.lastSeenFrame = counters_.frames;
            m.wasInlier = o.posed && m.inlier;
            if (o.posed)
                m.recentAgreement += edgeAlpha_ * ((m.inlier ? 1.0 : 0.0) - m.recentAgreement);
        }

    if (!o.posed)
        return;
    removeGhosts(o);
    const RigidTransform T_object_from_rig = o.T_rig_from_object.inverse();
    for (Member& member : o.members) {
        if (!member.visible || !member.inlier)
            continue;
        member.samples = std::min(member.samples + 1, config_.modelAverage_frames);
        member.model_mm +=
            (T_object_from_rig.apply(markers_[member.marker].position_rig_mm) - member.model_mm) /
            member.samples;
        member.seenFromSamples = std::min(member.seenFromSamples + 1, config_.modelAverage_frames);
        const Vec3 towardsCameras_object =
            T_object_from_rig.rotation * (-markers_[member.marker].position_rig_mm.normalized());
        member.seenFrom_object +=
            (towardsCameras_object - member.seenFrom_object) / member.seenFromSamples;
        ++member.framesReliable;
    }
}

void ObjectCalibrator::fitPose(Object& o, Remeasure remeasure) {
    const bool wasPosed = o.posed;
    o.posed = false;
    fitFrom_.clear();
    fitTo_.clear();
    votes_.clear();
    std::size_t visible = 0;
    for (std::size_t i = 0; i < o.members.size(); ++i) {
        Member& member = o.members[i];
        member.inlier = false;
        if (!member.visible)
            continue;
        ++visible;
        if (!member.verified)
            continue;
        fitFrom_.push_back(member.model_mm);
        fitTo_.push_back(markers_[member.marker].position_rig_mm);
        // Established markers outvote new ones: a group of markers that just joined the object
        // (new markers go to every object) must not take its pose over.
        votes_.push_back(established(member) ? kEstablishedVote : 1.0);
    }
    const std::optional<ConsensusPose> consensus = consensusPose();
    if (!consensus) {
        if (visible >= config_.minModelMarkers)
            rebase(o);
        // Every loss counts, the one in a split too: a merge takes a fragment's markers for a
        // lost body's only when the fragment was born after the body was lost.
        if (wasPosed && !o.posed)
            o.lostAtFrame = counters_.frames;
        return;
    }
    const RigidTransform& pose = consensus->T_rig_from_object;
    const RigidTransform T_object_from_rig = pose.inverse();
    for (Member& member : o.members) {
        if (!member.visible)
            continue;
        const Vec3& p = markers_[member.marker].position_rig_mm;
        const bool again = remeasure == Remeasure::All ||
                           (remeasure == Remeasure::NewMembers && !established(member));
        if (!member.verified ||
            (again && (pose.apply(member.model_mm) - p).norm() > config_.poseInlier_mm)) {
            // Measured under another frame (a re-based object, or a part that split off): it is
            // measured again in this one, and has to earn its place in the model again.
            member.model_mm = T_object_from_rig.apply(p);
            member.samples = 1;
            member.framesReliable = 0;
            member.verified = true;
            member.recentResidual_mm = 0.0;
            member.seenFrom_object = Vec3::Zero();
            member.seenFromSamples = 0;
        }
        const double residual = (pose.apply(member.model_mm) - p).norm();
        member.inlier = residual <= config_.poseInlier_mm;
        member.recentResidual_mm += edgeAlpha_ * (residual - member.recentResidual_mm);
    }
    o.posed = true;
    o.T_rig_from_object = pose;
    if (remeasure == Remeasure::All)
        for (Member& member : o.members)
            if (!member.visible)
                member.framesReliable = 0; // it may belong to the other part; seen again, it shows
    // A marker that keeps away from where the object's pose puts it is not rigid with the markers
    // that agree with the pose: its edges to them break. This sees a marker drift from the whole
    // object at once, sooner than any single distance shows it.
    for (std::size_t i = 0; i < o.members.size(); ++i) {
        Member& member = o.members[i];
        if (!member.visible || member.recentResidual_mm <= config_.edgeBreak_mm)
            continue;
        member.recentResidual_mm = 0.0;
        for (std::size_t j = 0; j < o.members.size(); ++j) {
            // Only the members that made the pose are known to be rigid with it: two new
            // members of another body drift from it alike, and their edge must hold.
            if (j == i || !o.members[j].inlier ||
                (consensus->fromEstablished && !established(o.members[j])))
                continue;
            Edge& e = edge(o, i, j);
            if (e.state == EdgeState::Active) {
                e.state = EdgeState::Broken;
                o.dirty = true;
                ++counters_.edgesBroken;
            }
        }
    }
}

std::optional<ObjectCalibrator::ConsensusPose> ObjectCalibrator::consensusPose() {
    const std::size_t n = fitFrom_.size();
    if (n < 3)
        return std::nullopt;
    const std::span<const double> votes = votes_.span();
    auto countInliers = [&](const RigidTransform& t) {
        double count = 0.0;
        for (std::size_t i = 0; i < n; ++i)
            if ((t.apply(fitFrom_[i]) - fitTo_[i]).norm() <= config_.poseInlier_mm)
                count += votes[i];
        return count;
    };
    double allVotes = 0.0;
    for (double v : votes)
        allVotes += v;
    std::optional<RigidFit> all = fitRigid(fitFrom_.span(), fitTo_.span());
    std::optional<RigidTransform> best;
    double bestCount = 0.0;
    if (all) {
        best = all->transform;
        bestCount = countInliers(all->transform);
        if (bestCount == allVotes)
            return refit(n);
    }
    // Some members disagree (an object splitting, stale positions): the pose that most members
    // agree with wins, tried from spread-out triples (deterministic, so runs repeat).
    const std::size_t tries = std::min<std::size_t>(kConsensusTries, n * (n - 1) * (n - 2) / 6);
    for (std::size_t t = 0; t < tries; ++t) {
        const std::size_t a = t % n;
        const std::size_t b = (a + 1 + (t / n) % (n - 1)) % n;
        std::size_t c = (a + n / 3 + t / 7) % n;
        if (c == a || c == b)
            c = (std::max(a, b) + 1) % n;
        if (c == a || c == b)
            continue;
        const std::array<Vec3, 3> from = {fitFrom_[a], fitFrom_[b], fitFrom_[c]};
        const std::array<Vec3, 3> to = {fitTo_[a], fitTo_[b], fitTo_[c]};
        const std::optional<RigidTransform> fit = fitTriangle(from, to);
        if (!fit)
            continue;
        double squares = 0.0;
        for (std::size_t k = 0; k < 3; ++k)
            squares += (to[k] - fit->apply(from[k])).squaredNorm();
        if (std::sqrt(squares / 3.0) > config_.poseInlier_mm)
            continue;
        const double count = countInliers(*fit);
        if (count > bestCount) {
            bestCount = count;
            best = *fit;
        }
    }
    if (!best)
        return std::nullopt;
    // Refit on the agreeing members only.
    std::size_t kept = 0;
    for (std::size_t i = 0; i < n; ++i)
        if ((best->apply(fitFrom_[i]) - fitTo_[i]).norm() <= config_.poseInlier_mm) {
            fitFrom_[kept] = fitFrom_[i];
            fitTo_[kept] = fitTo_[i];
            votes_[kept] = votes_[i];
            ++kept;
        }
    return refit(kept);
}

std::optional<ObjectCalibrator::ConsensusPose> ObjectCalibrator::refit(std::size_t count) {
    // The pose comes from the reliable (established) members when three of them fix it, as the
    // paper's step 5 has it. New members agree within the pose threshold but are not yet known to
    // be rigid with the object: markers of another body passing close agree for a while, and in
    // an unweighted fit they drag the pose by up to that threshold; every new marker placed
    // through that pose then joins the model that far out of place.
    std::size_t reliable = 0;
    for (std::size_t i = 0; i < count; ++i)
        if (votes_[i] == kEstablishedVote) {
            std::swap(fitFrom_[reliable], fitFrom_[i]);
            std::swap(fitTo_[reliable], fitTo_[i]);
            std::swap(votes_[reliable], votes_[i]);
            ++reliable;
        }
    if (reliable >= 3)
        if (const std::optional<RigidFit> fit =
                fitRigid(std::span(fitFrom_.data(), reliable), std::span(fitTo_.data(), reliable)))
            return ConsensusPose{fit->transform, true};
    const std::optional<RigidFit> fit =
        fitRigid(std::span(fitFrom_.data(), count), std::span(fitTo_.data(), count));
    if (!fit)
        return std::nullopt;
    return ConsensusPose{fit->transform, false};
}

void ObjectCalibrator::rebase(Object& o) {
    // No pose agrees with three members: start the object's frame afresh at the rig's frame from
    // what is visible; occluded members wait to be seen again (their positions belong to the old
    // frame).
    for (Member& member : o.members) {
        if (member.visible) {
            member.model_mm = markers_[member.marker].position_rig_mm;
            member.samples = 1;
            member.framesReliable = 0;
            member.verified = true;
            member.seenFrom_object = Vec3::Zero();
            member.seenFromSamples = 0;
        } else {
            member.verified = false;
        }
    }
    o.posed = true;
    o.T_rig_from_object = RigidTransform::identity();
    ++counters_.rebased;
}

} // namespace edgetrack
