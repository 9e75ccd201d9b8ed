// Object calibration, step 7: duplicates collapsed, and objects that move as one body merged.
#include <algorithm>
#include <cmath>

#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

// --- Step 7: small duplicates of an object are removed. ----------------------------------------

void ObjectCalibrator::collapseObjects() {
    for (std::size_t a = 0; a < objects_.size(); ++a) {
        Object& small = objects_[a];
        if (!small.active)
            continue;
        for (std::size_t b = 0; b < objects_.size(); ++b) {
            const Object& large = objects_[b];
            if (b == a || !large.active || large.members.size() < small.members.size())
                continue;
            // Of two equal objects the older stays.
            if (large.members.size() == small.members.size() && large.id > small.id)
                continue;
            ++stampValue_;
            for (const Member& member : large.members)
                stamp_[member.marker] = stampValue_;
            const bool subset =
                std::all_of(small.members.begin(), small.members.end(), [&](const Member& member) {
                    return stamp_[member.marker] == stampValue_;
                });
            if (subset) {
                deactivate(small);
                ++counters_.collapsed;
                break;
            }
        }
    }
}

// --- Step 7, continued: two objects that are one body become one. -----------------------------

void ObjectCalibrator::mergeDuplicates() {
    // A body can end up as two objects: it was lost and its markers came back as new ones, which
    // joined other objects and broke away from them as a fragment. A fragment is merged into the
    // object it duplicates when its markers sit on that object's markers in place (both posed),
    // or, when the two were never seen apart, when its layout fits the other's.
    recordObjectsSeenApart();
    const double radius2 = config_.reappearRadius_mm * config_.reappearRadius_mm;
    for (Object& fragment : objects_) {
        if (!fragment.active || !fragment.posed)
            continue;
        // The fragment's markers in view (rig, mm), for the search in a lost body below.
        searchPoints_.clear();
        for (const Member& m : fragment.members)
            if (m.visible && m.verified)
                searchPoints_.push_back(markers_[m.marker].position_rig_mm);
        if (searchPoints_.size() < kMergeInPlaceMin)
            continue;
        for (Object& body : objects_) {
            if (&body == &fragment || !body.active)
                continue;
            const bool larger =
                body.members.size() > fragment.members.size() ||
                (body.members.size() == fragment.members.size() && body.id < fragment.id);
            if (!body.posed) {
                // A body lost before the fragment was born: the fragment's markers in view may
                // be the body's hidden ones.
                if (body.lostAtFrame >= fragment.bornFrame)
                    continue;
                const std::optional<RigidTransform> T_rig_from_body =
                    fitLayout(body, searchPoints_.span(), Members::Occluded);
                if (!T_rig_from_body)
                    continue;
                // The smaller goes into the larger: a body seen from a new side after it came
                // back may have grown past what was learnt before it was lost.
                if (larger) {
                    body.posed = true;
                    body.T_rig_from_object = *T_rig_from_body;
                    merge(fragment, body, T_rig_from_body->inverse() * fragment.T_rig_from_object);
                } else {
                    merge(body, fragment, fragment.T_rig_from_object.inverse() * *T_rig_from_body);
                }
                ++counters_.merged;
                structureChanged_ = true;
                break;
            }
            if (!larger)
                continue; // the pair is looked at from the other side
            // Only markers established in both count: a new marker joins every object for a
            // while, so sitting on both proves nothing until it has stayed with both.
            std::size_t onBody = 0;
            for (const Member& a : fragment.members) {
                if (!a.visible || !a.verified || !established(a))
                    continue;
                const Vec3& p = markers_[a.marker].position_rig_mm;
                for (const Member& m : body.members)
                    if (m.verified && established(m) &&
                        (body.T_rig_from_object.apply(m.model_mm) - p).squaredNorm() <= radius2) {
                        ++onBody;
                        break;
                    }
            }
            if (onBody < kMergeInPlaceMin)
                continue;
            merge(fragment, body, body.T_rig_from_object.inverse() * fragment.T_rig_from_object);
            ++counters_.merged;
            structureChanged_ = true;
            break;
        }
    }
    mergeByLayout();
}

ObjectCalibrator::FrameGroup ObjectCalibrator::largerFrameGroup(const Object& o) const {
    std::size_t current = 0, old = 0;
    for (const Member& m : o.members) {
        current += static_cast<std::size_t>(selects(Members::Verified, m) && established(m));
        old += static_cast<std::size_t>(selects(Members::OldFrame, m));
    }
    if (old > current)
        return {Members::OldFrame, old};
    return {Members::Verified, current};
}

void ObjectCalibrator::mergeByLayout() {
    // A lost body whose layout a posed object repeats, the two never seen apart, is that object:
    // it came back and was not recognised in time. One layout search per check, taking the posed
    // objects in turn: a search is bounded but not cheap, and a duplicate that is there now is
    // there at the next check too.
    const std::size_t count = objects_.size();
    for (std::size_t step = 0; step < count; ++step) {
        const std::size_t f = (nextShapeSearch_ + step) % count;
        Object& fragment = objects_[f];
        if (!fragment.active || !fragment.posed)
            continue;
        // The fragment's layout: its established members, in its own frame.
        searchPoints_.clear();
        for (const Member& m : fragment.members)
            if (m.verified && established(m))
                searchPoints_.push_back(m.model_mm);
        if (searchPoints_.size() < kRefindMinMarkers)
            continue;
        nextShapeSearch_ = f + 1;
        for (std::size_t b = 0; b < count; ++b) {
            Object& body = objects_[b];
            if (b == f || !body.active || body.posed || seenApart(f, b))
                continue;
            // A body lost soon after a re-base keeps most of what it learnt in its old frame;
            // only one frame's members can be fitted at a time.
            const FrameGroup group = largerFrameGroup(body);
            const Members layout = group.members;
            // The body's layout: the established members of that frame, in its own frame.
            piecePoints_.clear();
            for (const Member& m : body.members)
                if (selects(layout, m) && established(m))
                    piecePoints_.push_back(m.model_mm);
            if (group.established < kRefindMinMarkers) {
                // Too few to carry a merge: a small lost piece whose markers fit the posed
                // object's layout, all or all but one in four, is a stale duplicate of part of
                // it, and goes. (A piece formed while two bodies still moved together can hold
                // a marker of the other; it fits neither whole, and no pose finds it again.)
                if (piecePoints_.size() >= kMergeInPlaceMin &&
                    fitLayout(fragment, piecePoints_.span(), Members::Verified, kMergeInPlaceMin,
                              0.75)) {
                    deactivate(body);
                    ++counters_.collapsed;
                    structureChanged_ = true;
                    return;
                }
                continue;
            }
            // The smaller layout is searched for in the larger one, so that most of the smaller
            // one must lie on the larger: a small lost piece of a large posed object, or a small
            // posed piece of a large lost body.
            std::optional<RigidTransform> T_fragment_from_body;
            if (group.established < searchPoints_.size()) {
                if (const std::optional<RigidTransform> bodyFromFragment =
                        fitLayout(fragment, piecePoints_.span(), Members::Verified))
                    T_fragment_from_body = bodyFromFragment->inverse();
            } else {
                T_fragment_from_body = fitLayout(body, searchPoints_.span(), layout);
            }
            if (!T_fragment_from_body)
                continue;
            // Into the posed object, whose frame is the current one; the body's members of the
            // other frame cannot be placed and are dropped.
            merge(body, fragment, *T_fragment_from_body, layout);
            ++counters_.merged;
            structureChanged_ = true;
            return;
        }
        return;
    }
}

void ObjectCalibrator::recordObjectsSeenApart() {
    // Where each posed object in view is: the centre and radius of its established members.
    for (std::size_t i = 0; i < objects_.size(); ++i) {
        const Object& o = objects_[i];
        extentRadius_[i] = -1.0;
        if (!o.active || !o.posed)
            continue;
        std::size_t inView = 0, establishedCount = 0;
        Vec3 centre = Vec3::Zero();
        for (const Member& m : o.members) {
            if (!m.verified || !established(m))
                continue;
            inView += m.visible ? 1 : 0;
            centre += o.T_rig_from_object.apply(m.model_mm);
            ++establishedCount;
        }
        if (inView < 3)
            continue;
        centre /= static_cast<double>(establishedCount);
        double radius = 0.0;
        for (const Member& m : o.members)
            if (m.verified && established(m))
                radius = std::max(radius, (o.T_rig_from_object.apply(m.model_mm) - centre).norm());
        extentCentre_[i] = centre;
        extentRadius_[i] = radius;
    }
    // Two bodies in view at once whose spheres do not touch are two objects, even if their
    // layouts agree (identical cubes).
    for (std::size_t a = 0; a < objects_.size(); ++a)
        for (std::size_t b = a + 1; b < objects_.size(); ++b)
            if (extentRadius_[a] >= 0.0 && extentRadius_[b] >= 0.0 &&
                (extentCentre_[a] - extentCentre_[b]).norm() >
                    extentRadius_[a] + extentRadius_[b] + config_.reappearRadius_mm)
                setSeenApart(a, b, true);
}

bool ObjectCalibrator::seenApart(std::size_t a, std::size_t b) const {
    return (seenApart_[a * seenApartWords_ + b / 64] >> (b % 64)) & 1u;
}

void ObjectCalibrator::setSeenApart(std::size_t a, std::size_t b, bool apart) {
    auto set = [&](std::size_t row, std::size_t column) {
        std::uint64_t& word = seenApart_[row * seenApartWords_ + column / 64];
        const std::uint64_t bit = std::uint64_t{1} << (column % 64);
        word = apart ? (word | bit) : (word & ~bit);
    };
    set(a, b);
    set(b, a);
}

void ObjectCalibrator::merge(Object& from, Object& into, const RigidTransform& T_into_from_from,
                             Members carry) {
    const double radius2 = config_.reappearRadius_mm * config_.reappearRadius_mm;
    FixedVector<std::size_t, MarkerSet::kCapacity> indexInto;
    for (const Member& a : from.members) {
        if (!selects(carry, a)) {
            indexInto.push_back(kNone);
            continue;
        }
        const Vec3 position = T_into_from_from.apply(a.model_mm);
        std::size_t match = kNone;
        double nearest2 = radius2;
        for (std::size_t j = 0; j < into.members.size(); ++j) {
            const double d2 = (into.members[j].model_mm - position).squaredNorm();
            if (into.members[j].verified && d2 <= nearest2) {
                nearest2 = d2;
                match = j;
            }
        }
        if (match != kNone) {
            Member& b = into.members[match];
            KnownMarker& seenNow = markers_[a.marker];
            KnownMarker& known = markers_[b.marker];
            if (b.marker != a.marker && seenNow.visible && !known.visible) {
                // One physical marker, two identities: the older one is seen again.
                known.visible = true;
                known.trackerId = seenNow.trackerId;
                known.position_rig_mm = seenNow.position_rig_mm;
                known.framesSeen += seenNow.framesSeen;
                seenNow.visible = false;
                seenNow.trackerId = 0;
                b.visible = true;
            }
            b.framesReliable = std::max(b.framesReliable, a.framesReliable);
            b.partnersLeftUnseen = std::max(b.partnersLeftUnseen, a.partnersLeftUnseen);
            b.lastSeenFrame = std::max(b.lastSeenFrame, a.lastSeenFrame);
            indexInto.push_back(match);
        } else if (addMember(into, a.marker, position)) {
            Member& copy = into.members.back();
            copy.samples = a.samples;
            copy.framesReliable = a.framesReliable;
            copy.visible = a.visible;
            copy.inlier = a.inlier;
            copy.wasInlier = a.wasInlier;
            copy.recentAgreement = a.recentAgreement;
            copy.partnersLeftUnseen = a.partnersLeftUnseen;
            copy.lastSeenFrame = a.lastSeenFrame;
            copy.seenFrom_object = T_into_from_from.rotation * a.seenFrom_object;
            copy.seenFromSamples = a.seenFromSamples;
            indexInto.push_back(into.members.size() - 1);
        } else {
            indexInto.push_back(kNone);
        }
    }
    for (std::size_t i = 0; i < from.members.size(); ++i)
        for (std::size_t j = i + 1; j < from.members.size(); ++j) {
            const std::size_t a = indexInto[i], b = indexInto[j];
            if (a == kNone || b == kNone || a == b)
                continue;
            Edge& e = edge(into, a, b);
            const Edge& carried = edge(from, i, j);
            if (e.state == EdgeState::None)
                e = carried;
            e.coVisible = e.coVisible || carried.coVisible;
        }
    deactivate(from);
    into.dirty = true;
}

} // namespace edgetrack
