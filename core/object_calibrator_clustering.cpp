// Object calibration, step 4: pyramid (4-clique) clustering splits a graph that lost edges into
// the rigid bodies it holds.
#include <algorithm>
#include <cmath>

#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

// --- Step 4: pyramid clustering splits graphs that lost edges. ---------------------------------

bool ObjectCalibrator::bridgesABreak(const Object& o, std::size_t i) const {
    // Two members it holds mature edges to, whose own edge broke.
    const auto mature = static_cast<std::uint32_t>(config_.edgeWindow_frames);
    const std::size_t n = o.members.size();
    auto holds = [&](std::size_t a, std::size_t b) {
        const Edge& e = edge(o, a, b);
        return e.state == EdgeState::Active && e.samples >= mature;
    };
    for (std::size_t j = 0; j < n; ++j) {
        if (j == i || !holds(i, j))
            continue;
        for (std::size_t k = j + 1; k < n; ++k)
            if (k != i && holds(i, k) && edge(o, j, k).state == EdgeState::Broken)
                return true;
    }
    return false;
}

void ObjectCalibrator::clusterObject(std::size_t objectIndex) {
    Object& o = objects_[objectIndex];
    const std::size_t n = o.members.size();
    // Edges younger than the running window have not had the chance to break yet. A new marker
    // is joined to everything in view, so counting its edges would bridge objects that are moving
    // apart (with two new markers on each, they chain into pyramids across); its young edges are
    // left out, and a marker with only young edges goes with every part.
    const auto mature = static_cast<std::uint32_t>(config_.edgeWindow_frames);
    adjacency_.clear();
    adjacency_.resize(n);
    MarkerSet withEdges, withMatureEdges;
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = i + 1; j < n; ++j) {
            const Edge& e = edge(o, i, j);
            if (e.state != EdgeState::Active)
                continue;
            withEdges.insert(i);
            withEdges.insert(j);
            if (e.samples >= mature) {
                adjacency_[i].insert(j);
                adjacency_[j].insert(i);
                withMatureEdges.insert(i);
                withMatureEdges.insert(j);
            }
        }
    const MarkerSet pending = withEdges.minus(withMatureEdges);
    const MarkerSet all = MarkerSet::firstN(n);
    // A member hidden for long whose place no pose predicts has edges that were last measured
    // when it was seen and hold however the bodies moved since: in the clustering, its edges
    // chain into one cluster bodies that have long moved apart (a sphere can stay in a cube's
    // object until the object's members run out). It stays with the object, out of the
    // clustering, until it is seen. Not at once (untracked_hidden_frames, 3 s): a member hidden
    // for a moment is far more often still on its body, and leaving it out loses markers.
    MarkerSet untracked;
    for (std::size_t i = 0; i < n; ++i) {
        const Member& m = o.members[i];
        if (!m.visible && !predictable(o, m) &&
            counters_.frames - m.lastSeenFrame >= config_.untrackedHidden_frames)
            untracked.insert(i);
    }
    if (!clustering_.cluster(adjacency_.span(), all.minus(pending | untracked))) {
        ++counters_.clusteringDeferred;
        return; // still dirty: tried again next frame
    }
    o.dirty = false;
    joinClustersSharingATriangle(o, clustering_.clusters());
    const std::span<const MarkerSet> clusters = joinedClusters_.span();
    if (clusters.size() == 1 && (clusters[0] | pending | untracked) == all)
        return;
    structureChanged_ = true;
    if (clusters.size() > 1)
        ++counters_.splits;

    // The cluster with the most established markers stays this object; the others become new
    // objects with their part of the graph.
    std::size_t kept = 0, keptEstablished = 0, keptSize = 0;
    for (std::size_t c = 0; c < clusters.size(); ++c) {
        std::size_t established = 0;
        clusters[c].forEach(
            [&](std::size_t i) { established += this->established(o.members[i]) ? 1u : 0u; });
        if (c == 0 || established > keptEstablished ||
            (established == keptEstablished && clusters[c].size() > keptSize)) {
            kept = c;
            keptEstablished = established;
            keptSize = clusters[c].size();
        }
    }
    FixedVector<std::size_t, MarkerSet::kCapacity> newIndex;
    for (std::size_t c = 0; c < clusters.size(); ++c) {
        if (c == kept)
            continue;
        Object* part = newObject(&objects_[objectIndex]);
        if (part == nullptr) {
            ++counters_.objectOverflow;
            continue;
        }
        Object& whole = objects_[objectIndex]; // newObject() does not move objects
        newIndex.clear();
        newIndex.resize(n);
        std::fill(newIndex.begin(), newIndex.end(), kNone);
        (clusters[c] | pending).forEach([&](std::size_t i) {
            if (addMember(*part, whole.members[i].marker, whole.members[i].model_mm)) {
                Member& copy = part->members.back();
                copy = whole.members[i];
                newIndex[i] = part->members.size() - 1;
            }
        });
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t j = i + 1; j < n; ++j)
                if (newIndex[i] != kNone && newIndex[j] != kNone)
                    edge(*part, newIndex[i], newIndex[j]) = edge(whole, i, j);
        part->T_rig_from_object = whole.T_rig_from_object;
        fitPose(*part, Remeasure::All);
    }
    // Members of no cluster leave this object.
    const MarkerSet keep = (clusters.empty() ? MarkerSet{} : clusters[kept]) | pending | untracked;
    forgetAmbiguousHiddenMembers(o, clusters, keep);
    for (std::size_t i = n; i-- > 0;)
        if (!keep.contains(i))
            removeMember(o, i);
    if (o.members.empty())
        deactivate(o);
    else
        fitPose(o, clusters.size() > 1 ? Remeasure::NewMembers : Remeasure::None);
}

void ObjectCalibrator::forgetAmbiguousHiddenMembers(Object& o, std::span<const MarkerSet> clusters,
                                                    const MarkerSet& keep) {
    // A hidden member of the part that keeps the object, rigid before with an established
    // member that leaves now (a mature edge that holds, or broke only against the place this
    // object's pose predicts for it), was hidden while the two moved apart: which body it is on
    // is not known. Its predicted place follows this object's pose, so its edges to the leaving
    // members broke however it moved, and kept established it would be exported here though it
    // may be on the other body (markers of one cube in another's model, last seen in the first
    // seconds when all were one object). It has to be seen again to count, as the hidden members
    // of a part that splits off do.
    //
    // A body leaves as another cluster, or one member at a time as members of no cluster when
    // it turns as it goes: its far markers drift from the pose first and their drift breaks its
    // own edges (AMarkerHiddenWhileABodyTurnedAwayIsInNeitherModel). Members of no cluster count
    // once three have left since the hidden member was last seen: one or two are a noisy member
    // or a piece of something passing by, not a body (counting each at once can lose a marker
    // for good). Then the member only stays out of the models until it is seen (placeInDoubt):
    // forgetting it, as at a split, fires mostly for members of the body that stays, and many
    // members forgotten at once can change which part keeps the object.
    //
    // Only established members count: new markers of a body passing by join every object in
    // view and leave again, and edges to them say nothing of where a hidden member is (counting
    // them too only delays complete models).
    const auto mature = static_cast<std::uint32_t>(config_.edgeWindow_frames);
    MarkerSet clustered;
    for (const MarkerSet& c : clusters)
        clustered |= c;
    const MarkerSet otherClusters = clustered.minus(keep);
    const MarkerSet unclustered = MarkerSet::firstN(o.members.size()).minus(clustered | keep);
    auto rigidBefore = [&](std::size_t i, std::size_t j) {
        if (!established(o.members[j]))
            return false;
        const Edge& e = edge(o, i, j);
        return e.samples >= mature &&
               (e.state == EdgeState::Active || (e.state == EdgeState::Broken && e.brokenUnseen));
    };
    keep.forEach([&](std::size_t i) {
        Member& m = o.members[i];
        if (m.visible || !established(m))
            return;
        bool ambiguous = false;
        otherClusters.forEach([&](std::size_t j) { ambiguous = ambiguous || rigidBefore(i, j); });
        unclustered.forEach(
            [&](std::size_t j) { m.partnersLeftUnseen += rigidBefore(i, j) ? 1u : 0u; });
        if (ambiguous)
            m.framesReliable = 0;
    });
}

void ObjectCalibrator::joinClustersSharingATriangle(const Object& o,
                                                    std::span<const MarkerSet> clusters) {
    // Each cluster is rigid; two that share three markers not on one line are rigid with each
    // other, whether or not those three are a face of a pyramid in both. Without this a body
    // whose parts are bridged only that way splits, is merged back in place (its markers sit on
    // the object's) and splits again, every few frames, and the bridge markers never settle.
    joinedClusters_.clear();
    for (const MarkerSet& c : clusters)
        joinedClusters_.push_back(c); // room for all: there are no more clusters than cliques
    bool joined = true;
    while (joined) {
        joined = false;
        for (std::size_t a = 0; a < joinedClusters_.size() && !joined; ++a)
            for (std::size_t b = a + 1; b < joinedClusters_.size() && !joined; ++b) {
                if (!spansATriangle(o, joinedClusters_[a] & joinedClusters_[b]))
                    continue;
                joinedClusters_[a] |= joinedClusters_[b];
                // Keep the clustering's order (the first cluster wins ties below).
                for (std::size_t c = b; c + 1 < joinedClusters_.size(); ++c)
                    joinedClusters_[c] = joinedClusters_[c + 1];
                joinedClusters_.pop_back();
                joined = true;
            }
    }
}

bool ObjectCalibrator::spansATriangle(const Object& o, const MarkerSet& shared) const {
    // Only members whose whereabouts are known now count: their edges to both clusters are
    // measured. A member hidden all the while two bodies moved apart keeps its unmeasured edges
    // to both and would join them. Positions of one frame only (a member not verified since a
    // re-base is in the old one).
    FixedVector<Vec3, MarkerSet::kCapacity> points;
    shared.forEach([&](std::size_t i) {
        const Member& m = o.members[i];
        if (m.verified && (m.visible || predictable(o, m)))
            points.push_back(m.model_mm);
    });
    if (points.size() < 3)
        return false;
    std::size_t far = 1;
    for (std::size_t i = 2; i < points.size(); ++i)
        if ((points[i] - points[0]).squaredNorm() > (points[far] - points[0]).squaredNorm())
            far = i;
    const Vec3 axis = points[far] - points[0];
    if (axis.norm() < kMinTriangleHeight_mm)
        return false;
    const Vec3 direction = axis.normalized();
    for (const Vec3& p : points) {
        const Vec3 offset = p - points[0];
        if ((offset - offset.dot(direction) * direction).norm() >= kMinTriangleHeight_mm)
            return true;
    }
    return false;
}

void ObjectCalibrator::removeGhosts(Object& o) {
    // A marker is expected when the cameras (near the rig's origin, against the objects'
    // distance) look at it as they did when it was seen, and markers it was seen with are seen
    // where the pose puts them. A member that is almost never there
    // when expected has a position from a wrong frame (measured while its object was still mixed
    // with another), so the marker it stood for came back as a new member long ago: the stale
    // one goes. (Markers seen with it being in view is not enough on its own: on a cube, the
    // face beside it can be in view for seconds while its own face is turned away.)
    const RigidTransform T_object_from_rig = o.T_rig_from_object.inverse();
    for (std::size_t i = o.members.size(); i-- > 0;) {
        Member& m = o.members[i];
        if (!m.verified || !established(m))
            continue;
        const double clarity = m.seenFrom_object.norm();
        if (clarity < kMinFacingClarity)
            continue;
        const Vec3 towardsCameras_object =
            T_object_from_rig.rotation * (-o.T_rig_from_object.apply(m.model_mm).normalized());
        if (towardsCameras_object.dot(m.seenFrom_object) < kFacingCosine * clarity)
            continue;
        std::size_t partnersSeen = 0;
        for (std::size_t j = 0; j < o.members.size() && partnersSeen < 3; ++j)
            if (j != i && o.members[j].visible && o.members[j].inlier && edge(o, i, j).coVisible)
                ++partnersSeen;
        if (partnersSeen < 3)
            continue;
        ++m.expectedFrames;
        if (!m.visible)
            ++m.missedFrames;
        if (m.expectedFrames >= kGhostEvidence_frames &&
            static_cast<double>(m.missedFrames) > kGhostMissShare * m.expectedFrames) {
            removeMember(o, i);
            o.dirty = true;
            ++counters_.ghostsRemoved;
        }
    }
}

} // namespace edgetrack
