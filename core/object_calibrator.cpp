// Object calibration (paper section 4.2), the online stage: the frame loop, marker identities,
// invalid markers, storage, views and model export. The steps live in object_calibrator_*.cpp.
#include "core/object_calibrator.hpp"

#include <algorithm>
#include <cmath>

#include "core/rigid_fit.hpp"

namespace edgetrack {

ObjectCalibrator::ObjectCalibrator(const CalibrationConfig& config)
    : config_(config)
    , valid_(config.maxMarkersPerObject >= 4 &&
             config.maxMarkersPerObject <= MarkerSet::kCapacity && config.maxObjects >= 1 &&
             config.maxMarkers >= config.maxMarkersPerObject && config.edgeWindow_frames >= 1.0)
    , stride_(std::min(config.maxMarkersPerObject, MarkerSet::kCapacity))
    , tracker_(config.tracking)
    , clustering_(config.maxCliques, config.cliqueStepBudget)
    , joinedClusters_(config.maxCliques)
    , markers_(config.maxMarkers)
    , byTrackerId_(config.maxMarkers)
    , knownOfTracked_(config.tracking.maxMarkers)
    , sortedPoints_(config.tracking.maxMarkers)
    , fitFrom_(stride_)
    , fitTo_(stride_)
    , votes_(stride_)
    , positionNow_(stride_)
    , whereabouts_(stride_)
    , stamp_(config.maxMarkers)
    , candidates_(config.maxMarkers)
    , memberPairs_(stride_ * stride_)
    , pairsByMember_(stride_ * stride_)
    , pairsOfMemberStart_(stride_ + 1)
    , thirdCorners_(stride_)
    , searchedMembers_(stride_)
    , placedMembers_(stride_)
    , searchPoints_(config.maxMarkers)
    , piecePoints_(stride_)
    , seenApart_(
          std::make_unique<std::uint64_t[]>(config.maxObjects * ((config.maxObjects + 63) / 64)))
    , seenApartWords_((config.maxObjects + 63) / 64)
    , extentCentre_(config.maxObjects)
    , extentRadius_(config.maxObjects)
    , sminWorkspace_(stride_)
    , edgeAlpha_(2.0 / (config.edgeWindow_frames + 1.0)) {
    objects_.resize(config.maxObjects);
    for (Object& o : objects_) {
        o.members = BoundedVector<Member>(stride_);
        o.edges = BoundedVector<Edge>(edgeCount(stride_));
        o.edges.resize(edgeCount(stride_));
    }
    markers_.resize(config.maxMarkers);
    stamp_.resize(config.maxMarkers);
    for (std::size_t i = 0; i < config.maxObjects; ++i) {
        extentCentre_.push_back(Vec3::Zero());
        extentRadius_.push_back(-1.0);
    }
}

void ObjectCalibrator::reset() {
    tracker_.reset();
    for (Object& o : objects_) {
        o.active = false;
        o.members.clear();
    }
    for (KnownMarker& m : markers_)
        m = KnownMarker{};
    byTrackerId_.clear();
    std::fill_n(seenApart_.get(), objects_.size() * seenApartWords_, std::uint64_t{0});
    nextShapeSearch_ = 0;
    counters_ = CalibrationCounters{};
    nextMarkerId_ = 1;
    nextObjectId_ = 0;
}

void ObjectCalibrator::update(double time_s, std::span<const Vec3> points_rig_mm) {
    if (!valid_)
        return;
    ++counters_.frames;
    structureChanged_ = false;
    // One order of the points whatever order they came in, so that nothing learnt depends on it.
    sortedPoints_.clear();
    for (const Vec3& p : points_rig_mm)
        if (!sortedPoints_.push_back(p)) {
            counters_.pointOverflow += points_rig_mm.size() - sortedPoints_.size();
            break;
        }
    sortPointsCanonically(sortedPoints_.span());
    const std::span<const TrackedMarker> tracked = tracker_.update(time_s, sortedPoints_.span());
    bindTrackedMarkers(tracked); // step 1
    removeInvalidMarkers();      // step 3 (before the edges see them)
    for (Object& o : objects_)   // step 2, and the poses of step 5
        if (o.active)
            updateObject(o);
    for (std::size_t i = 0; i < objects_.size(); ++i) // step 4
        if (objects_[i].active && objects_[i].dirty)
            clusterObject(i);
    if (structureChanged_) // step 7
        collapseObjects();
    if (counters_.frames % kMergeInterval_frames == 0)
        mergeDuplicates();
    recogniseReappearing(tracked); // step 5
    insertNewMarkers(tracked);     // step 6
    rebuildTrackerIndex();
}

// --- Step 1: markers keep their calibration identity through the frame-to-frame IDs. ---------

void ObjectCalibrator::bindTrackedMarkers(std::span<const TrackedMarker> tracked) {
    for (KnownMarker& m : markers_)
        m.visible = false;
    knownOfTracked_.clear();
    knownOfTracked_.resize(tracked.size());
    for (std::size_t t = 0; t < tracked.size(); ++t) {
        knownOfTracked_[t] = kNone;
        if (tracked[t].age == 0)
            continue;
        const std::size_t k = findByTrackerId(tracked[t].id);
        if (k == kNone)
            continue;
        KnownMarker& m = markers_[k];
        m.visible = true;
        m.position_rig_mm = tracked[t].position_rig_mm;
        ++m.framesSeen;
        knownOfTracked_[t] = k;
    }
}

std::size_t ObjectCalibrator::findByTrackerId(std::uint32_t trackerId) const {
    const auto* it = std::lower_bound(byTrackerId_.begin(), byTrackerId_.end(), trackerId,
                                      [](const std::pair<std::uint32_t, std::size_t>& e,
                                         std::uint32_t id) { return e.first < id; });
    return it != byTrackerId_.end() && it->first == trackerId ? it->second : kNone;
}

void ObjectCalibrator::rebuildTrackerIndex() {
    byTrackerId_.clear();
    for (std::size_t k = 0; k < markers_.size(); ++k)
        if (markers_[k].used && markers_[k].visible && markers_[k].trackerId != 0)
            byTrackerId_.push_back({markers_[k].trackerId, k});
    std::sort(byTrackerId_.begin(), byTrackerId_.end());
}

// --- Step 3: markers seen only briefly were reflections, not markers. ------------------------

void ObjectCalibrator::removeInvalidMarkers() {
    for (std::size_t k = 0; k < markers_.size(); ++k) {
        KnownMarker& m = markers_[k];
        if (!m.used || m.visible)
            continue;
        m.trackerId = 0;
        m.rejected = false;
        if (m.framesSeen < config_.minLifetime_frames) {
            for (Object& o : objects_) {
                if (!o.active)
                    continue;
                for (std::size_t i = 0; i < o.members.size(); ++i)
                    if (o.members[i].marker == k) {
                        removeMember(o, i);
                        o.dirty = true;
                        break;
                    }
            }
            ++counters_.invalidRemoved;
            if (markers_[k].used)
                releaseMarker(k);
        } else if (m.objectCount == 0) {
            releaseMarker(k);
        }
    }
}

// --- Storage. -----------------------------------------------------------------------------------

ObjectCalibrator::Object* ObjectCalibrator::newObject(const Object* keep) {
    // With every slot taken, the object least worth keeping makes room: one out of view that
    // never established a marker (it would give no model), with the least evidence (its members'
    // reliable frames), out of view the longest. Without this, reflections and glimpses that
    // pass by fill the slots for good and an object that comes into view later is never learnt.
    if (std::all_of(objects_.begin(), objects_.end(), [](const Object& o) { return o.active; })) {
        Object* victim = nullptr;
        std::uint64_t victimEvidence = 0;
        for (Object& o : objects_) {
            if (&o == keep || o.posed ||
                std::any_of(o.members.begin(), o.members.end(),
                            [&](const Member& m) { return established(m); }))
                continue;
            std::uint64_t evidence = 0;
            for (const Member& m : o.members)
                evidence += m.framesReliable;
            if (victim == nullptr || evidence < victimEvidence ||
                (evidence == victimEvidence && o.lostAtFrame < victim->lostAtFrame)) {
                victim = &o;
                victimEvidence = evidence;
            }
        }
        if (victim != nullptr) {
            deactivate(*victim);
            ++counters_.objectsEvicted;
            structureChanged_ = true;
        }
    }
    for (Object& o : objects_) {
        if (o.active)
            continue;
        o.active = true;
        o.id = nextObjectId_++;
        o.members.clear();
        o.dirty = false;
        o.posed = false;
        o.bornFrame = counters_.frames;
        o.lostAtFrame = counters_.frames;
        const auto slot = static_cast<std::size_t>(&o - objects_.data());
        for (std::size_t other = 0; other < objects_.size(); ++other)
            setSeenApart(slot, other, false);
        return &o;
    }
    return nullptr;
}

void ObjectCalibrator::deactivate(Object& o) {
    while (!o.members.empty())
        removeMember(o, o.members.size() - 1);
    o.active = false;
}

bool ObjectCalibrator::addMember(Object& o, std::size_t marker, const Vec3& model_mm) {
    const std::size_t index = o.members.size();
    Member* member = o.members.append();
    if (member == nullptr) {
        ++counters_.memberOverflow;
        return false;
    }
    member->marker = marker;
    member->model_mm = model_mm;
    member->samples = 1;
    member->framesReliable = 0;
    member->verified = true;
    member->visible = false;
    member->inlier = false;
    member->wasInlier = false;
    member->recentAgreement = 0.0;
    member->recentResidual_mm = 0.0;
    member->seenFrom_object = Vec3::Zero();
    member->seenFromSamples = 0;
    member->expectedFrames = 0;
    member->missedFrames = 0;
    member->lastSeenFrame = counters_.frames;
    for (std::size_t j = 0; j < stride_; ++j)
        if (j != index)
            edge(o, index, j) = Edge{};
    ++markers_[marker].objectCount;
    return true;
}

void ObjectCalibrator::removeMember(Object& o, std::size_t member) {
    const std::size_t last = o.members.size() - 1;
    const std::size_t marker = o.members[member].marker;
    if (member != last) {
        // The last member takes this index; its edges move with it.
        for (std::size_t j = 0; j < last; ++j)
            if (j != member)
                edge(o, member, j) = edge(o, last, j);
    }
    o.members.swapRemove(member);
    KnownMarker& m = markers_[marker];
    if (--m.objectCount == 0) {
        if (m.visible) {
            m.rejected = true;
            m.rejectedAtFrame = counters_.frames;
        } else
            releaseMarker(marker);
    }
}

std::size_t ObjectCalibrator::newMarker(std::uint32_t trackerId, const Vec3& position_rig_mm) {
    for (std::size_t k = 0; k < markers_.size(); ++k) {
        KnownMarker& m = markers_[k];
        if (m.used)
            continue;
        m = KnownMarker{};
        m.used = true;
        m.id = nextMarkerId_++;
        m.trackerId = trackerId;
        m.visible = true;
        m.position_rig_mm = position_rig_mm;
        m.framesSeen = 1;
        return k;
    }
    ++counters_.markerOverflow;
    return kNone;
}

void ObjectCalibrator::releaseMarker(std::size_t marker) {
    markers_[marker] = KnownMarker{};
}

// --- Views and export. --------------------------------------------------------------------------

std::size_t ObjectCalibrator::objectCount() const {
    return static_cast<std::size_t>(
        std::count_if(objects_.begin(), objects_.end(), [](const Object& o) { return o.active; }));
}

std::size_t ObjectCalibrator::objectViews(std::span<CalibrationObjectView> out) const {
    std::size_t count = 0;
    for (const Object& o : objects_) {
        if (!o.active || count == out.size())
            continue;
        CalibrationObjectView& v = out[count++];
        v.id = o.id;
        v.markers = o.members.size();
        v.established = static_cast<std::size_t>(std::count_if(
            o.members.begin(), o.members.end(), [&](const Member& m) { return established(m); }));
        v.visible = static_cast<std::size_t>(std::count_if(
            o.members.begin(), o.members.end(), [](const Member& m) { return m.visible; }));
        v.posed = o.posed;
        v.T_rig_from_object = o.T_rig_from_object;
    }
    return count;
}

std::size_t ObjectCalibrator::exportModels(std::span<MarkerModel> out) const {
    const std::size_t count = exportLayouts(out);
    computeSmin(out.first(count), config_.smin, sminWorkspace_);
    return count;
}

std::size_t ObjectCalibrator::exportLayouts(std::span<MarkerModel> out) const {
    std::size_t count = 0;
    FixedVector<std::size_t, MarkerSet::kCapacity> chosen;
    FixedVector<Vec3, MarkerSet::kCapacity> layout;
    const double radius2 = config_.reappearRadius_mm * config_.reappearRadius_mm;
    for (const Object& o : objects_) {
        if (!o.active || count == out.size())
            continue;
        chosen.clear();
        layout.clear();
        // After a re-base an object's hidden members keep positions in the frame before it
        // until they are seen again: a model takes the members of one frame, the larger group.
        const Members frame = largerFrameGroup(o).members;
        // A member that mostly disagreed with the pose when last seen is not where the model
        // would put it (a marker of another body, established in the frames after a re-base,
        // then seen off the pose for good). Most, not the last sighting: the
        // frame-to-frame tracker can hand a vanishing marker's ID to a neighbour for a frame.
        for (std::size_t i = 0; i < o.members.size(); ++i)
            if (established(o.members[i]) && selects(frame, o.members[i]) &&
                o.members[i].recentAgreement >= 0.5 && !placeInDoubt(o.members[i]))
                chosen.push_back(i);
        // One physical marker can have two identities in an object (lost, then born again
        // before its prediction caught it): the better-measured one goes into the model.
        std::sort(chosen.begin(), chosen.end(), [&](std::size_t a, std::size_t b) {
            return o.members[a].framesReliable > o.members[b].framesReliable;
        });
        std::size_t distinct = 0;
        for (std::size_t c = 0; c < chosen.size(); ++c) {
            const Vec3& p = o.members[chosen[c]].model_mm;
            const bool duplicate = std::any_of(layout.begin(), layout.end(), [&](const Vec3& q) {
                return (p - q).squaredNorm() <= radius2;
            });
            if (duplicate)
                continue;
            chosen[distinct++] = chosen[c];
            layout.push_back(p);
        }
        while (chosen.size() > distinct)
            chosen.pop_back();
        if (chosen.size() < config_.minModelMarkers)
            continue;
        MarkerModel& model = out[count];
        model.clear();
        model.id = static_cast<std::uint32_t>(count);
        const RigidTransform canonicalFromObject = canonicalFrame(layout.span()).inverse();
        for (const Vec3& p : layout)
            model.markers_model_mm.push_back(canonicalFromObject.apply(p));
        for (std::size_t a = 0; a < chosen.size(); ++a)
            for (std::size_t b = a + 1; b < chosen.size(); ++b) {
                if (!edge(o, chosen[a], chosen[b]).coVisible)
                    continue;
                model.edges.push_back(
                    {static_cast<std::uint16_t>(a), static_cast<std::uint16_t>(b),
                     (model.markers_model_mm[a] - model.markers_model_mm[b]).norm()});
            }
        ++count;
    }
    return count;
}

} // namespace edgetrack
