// Object calibration (paper section 4): learns rigid marker models while the user moves objects.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "core/bounded_vector.hpp"
#include "core/marker_model.hpp"
#include "core/marker_set.hpp"
#include "core/marker_tracker.hpp"
#include "core/pyramid_clustering.hpp"
#include "core/rigid_transform.hpp"
#include "core/session_buffer.hpp"

namespace edgetrack {

/// \brief Tuning and capacities of object calibration; defaults suit hand-held objects at 100 Hz.
struct CalibrationConfig {
    /// Frame-to-frame correspondence that gives markers their IDs (step 1).
    FrameToFrameConfig tracking{};
    /// Objects (graphs) alive at once, the whole scene at the start included.
    std::size_t maxObjects = 32;
    /// Markers per object graph; at most MarkerSet::kCapacity (128).
    std::size_t maxMarkersPerObject = 128;
    /// Markers known at once over all objects, occluded ones included.
    std::size_t maxMarkers = 512;
    /// N of the paper: the running distance of an edge averages about this many frames.
    double edgeWindow_frames = 10.0;
    /// An edge breaks when its running distance departs this far from its long-run distance (mm).
    double edgeBreak_mm = 2.0;
    /// Markers that vanish after fewer frames than this are invalid and removed (step 3).
    std::uint32_t minLifetime_frames = 10;
    /// A new marker this close to an occluded marker's predicted position is that marker (mm).
    double reappearRadius_mm = 4.0;
    /// A marker within this of its place under the object's pose is reliable for the pose (mm).
    double poseInlier_mm = 1.5;
    /// Model positions are running means over about this many frames.
    std::uint32_t modelAverage_frames = 200;
    /// A marker enters the exported model once seen this many frames as a reliable member.
    std::uint32_t minModelFrames = 30;
    /// A member hidden this many frames whose place no pose predicts leaves the clustering
    /// (its edges are no longer measured): it stays with its object until it is seen.
    std::uint32_t untrackedHidden_frames = 300;
    /// An exported model has at least this many markers.
    std::size_t minModelMarkers = 4;
    /// Bounds of one clustering run (see PyramidClustering).
    std::size_t maxCliques = 512;
    std::size_t cliqueStepBudget = 50000;
    SminConfig smin{};

    bool operator==(const CalibrationConfig&) const = default;
};

/// \brief What calibration did and what did not fit, for the status view and the summary.
struct CalibrationCounters {
    std::uint64_t frames = 0;
    std::uint64_t markersBorn = 0;
    std::uint64_t markersReappeared = 0;
    std::uint64_t invalidRemoved = 0;
    std::uint64_t edgesBroken = 0;
    std::uint64_t splits = 0;
    std::uint64_t collapsed = 0;
    std::uint64_t clusteringDeferred = 0;
    /// Lost objects found again among new markers, and searches cut short by their budget.
    std::uint64_t refound = 0;
    std::uint64_t refindBudgetExhausted = 0;
    /// Objects merged into another object that was the same body.
    std::uint64_t merged = 0;
    /// Members removed because they were almost never where they were expected.
    std::uint64_t ghostsRemoved = 0;
    /// Objects whose frame was started afresh because no pose agreed with three markers.
    std::uint64_t rebased = 0;
    /// Points of a frame beyond the frame-to-frame tracker's capacity, left out.
    std::uint64_t pointOverflow = 0;
    /// Refused for lack of room: markers, objects, markers in an object.
    std::uint64_t markerOverflow = 0;
    std::uint64_t objectOverflow = 0;
    std::uint64_t memberOverflow = 0;
    /// Objects that gave up their slot to a new one: out of view, with no established marker.
    std::uint64_t objectsEvicted = 0;
};

/// \brief Progress of one object for a display: its size now.
struct CalibrationObjectView {
    std::uint32_t id = 0;
    std::size_t markers = 0;
    std::size_t established = 0;
    std::size_t visible = 0;
    bool posed = false;
    /// Rig from object-graph frame (mm); meaningful when posed.
    RigidTransform T_rig_from_object{};
};

/**
 * \brief Learns the rigid marker objects in a stream of unlabelled 3D markers.
 *
 * Follows the seven steps of the paper's section 4.2 every frame: frame-to-frame tracking gives
 * marker IDs; every object graph updates its elastic edges between visible markers; markers that
 * lived only briefly are removed; graphs that lost edges are split by pyramid clustering; each
 * object's pose is fitted to its reliable markers so that occluded markers are predicted and new
 * markers near a prediction are recognised as reappearing; other new markers join every posed
 * object (or, with no object in view, start a new one); objects that became a subset of another
 * are collapsed. Beyond the paper: a lost object is found again among new markers with its
 * partial model, fragments of one body are merged back, and members that are never where they
 * are expected are removed (docs/object-calibration.md explains each and why).
 *
 * All storage is sized by the constructor from the configuration; update() never allocates.
 * Whatever does not fit is refused and counted.
 */
class ObjectCalibrator {
public:
    explicit ObjectCalibrator(const CalibrationConfig& config);

    /// \brief False when the configuration cannot work (e.g. too many markers per object).
    bool isValid() const { return valid_; }

    /**
     * \brief Process one frame.
     * \param time_s frame time (s).
     * \param points_rig_mm this frame's markers, rig frame (mm), any order.
     */
    void update(double time_s, std::span<const Vec3> points_rig_mm);

    /// \brief Forget everything learnt (a new calibration).
    void reset();

    /**
     * \brief The models learnt so far: one per object with at least minModelMarkers established
     * markers, each in its canonical frame, with co-visibility edges and S_min.
     * \param out models to fill, each sized for maxMarkersPerObject markers.
     * \return how many models were written (at most out.size()).
     */
    std::size_t exportModels(std::span<MarkerModel> out) const;

    /**
     * \brief The models as exportModels gives them but without S_min (each keeps sMin 4): the
     * layouts and edges alone, for watching a session's progress. S_min is most of an export's
     * cost (a toy car's 38-marker model's, about 90 ms on the host); only tracking needs it.
     * \param out models to fill, each sized for maxMarkersPerObject markers.
     * \return how many models were written (at most out.size()).
     */
    std::size_t exportLayouts(std::span<MarkerModel> out) const;

    /// \brief The objects now, for a progress display.
    std::size_t objectViews(std::span<CalibrationObjectView> out) const;
    std::size_t objectCount() const;

    /// \brief One member of an object, for diagnostics and viewers.
    struct MemberView {
        std::uint32_t objectId = 0;
        std::uint32_t markerId = 0;
        bool visible = false;
        bool established = false;
        /// Rig frame (mm): where it is seen, or predicted when occluded and the object is posed.
        Vec3 position_rig_mm = Vec3::Zero();
        /// Its learnt position, object-graph frame (mm).
        Vec3 model_mm = Vec3::Zero();
    };
    /// \brief Call \a visit(const MemberView&) for every member of every object.
    template <typename Visit>
    void forEachMember(Visit&& visit) const {
        for (const Object& o : objects_) {
            if (!o.active)
                continue;
            for (const Member& m : o.members) {
                MemberView v;
                v.objectId = o.id;
                v.markerId = markers_[m.marker].id;
                v.visible = m.visible;
                v.established = established(m);
                v.position_rig_mm = m.visible ? markers_[m.marker].position_rig_mm
                                              : o.T_rig_from_object.apply(m.model_mm);
                v.model_mm = m.model_mm;
                visit(v);
            }
        }
    }

    const CalibrationCounters& counters() const { return counters_; }
    const ClusteringCounters& clusteringCounters() const { return clustering_.counters(); }
    const MarkerTracker& tracker() const { return tracker_; }

private:
    enum class EdgeState : std::uint8_t { None, Active, Broken };
    struct Edge {
        EdgeState state = EdgeState::None;
        bool coVisible = false;
        std::uint32_t samples = 0;
        double mean_mm = 0.0;
        double recent_mm = 0.0;
        /// It broke while one end was hidden and placed by the object's pose, not seen.
        bool brokenUnseen = false;
    };
    /// A marker as calibration knows it, whether visible now or occluded.
    struct KnownMarker {
        bool used = false;
        std::uint32_t id = 0;
        /// Frame-to-frame ID bound to it this frame (0: not seen this frame).
        std::uint32_t trackerId = 0;
        bool visible = false;
        Vec3 position_rig_mm = Vec3::Zero();
        std::uint32_t framesSeen = 0;
        std::uint32_t objectCount = 0;
        /// Dropped from every object while visible: ignored for a while.
        bool rejected = false;
        std::uint64_t rejectedAtFrame = 0;
    };
    struct Member {
        std::size_t marker = 0;
        /// Position in the object graph's frame (mm): a running mean.
        Vec3 model_mm = Vec3::Zero();
        std::uint32_t samples = 0;
        std::uint32_t framesReliable = 0;
        bool visible = false;
        bool inlier = false;
        /// It agreed with the object's pose the last frame it was seen: its prediction holds.
        bool wasInlier = false;
        /// Running share (window N) of the frames it was seen, the object posed, in which it
        /// agreed with the pose: a model takes a member only while most of them did.
        double recentAgreement = 0.0;
        /// Running mean of the distance from its place under the object's pose (mm).
        double recentResidual_mm = 0.0;
        /// Mean unit direction from it towards the rig's origin (the cameras) while it was seen
        /// agreeing with the pose, object-graph frame: where it faces, for removeGhosts.
        Vec3 seenFrom_object = Vec3::Zero();
        std::uint32_t seenFromSamples = 0;
        /// Frames in which it faced the cameras as when it was seen and markers seen with it were
        /// seen, and of those, frames it was not.
        std::uint32_t expectedFrames = 0;
        std::uint32_t missedFrames = 0;
        /// model_mm belongs to the object's current frame (false after a re-base, until seen).
        bool verified = true;
        /// Established members that left the object as members of no cluster, rigid with this
        /// one, since it was last seen: see forgetAmbiguousHiddenMembers and placeInDoubt.
        std::uint32_t partnersLeftUnseen = 0;
        /// counters_.frames when it was last seen (or joined).
        std::uint64_t lastSeenFrame = 0;
    };
    struct Object {
        bool active = false;
        std::uint32_t id = 0;
        BoundedVector<Member> members;
        /// Edges between members, one per pair: see edgeIndex().
        BoundedVector<Edge> edges;
        bool dirty = false;
        bool posed = false;
        RigidTransform T_rig_from_object{};
        /// Frame (counters.frames) of its creation, and of the last loss of its pose.
        std::uint64_t bornFrame = 0;
        std::uint64_t lostAtFrame = 0;
    };

    /// Pair (i, j), i != j, in either order, in a triangular table: pairs of members below j
    /// come before those of j.
    static std::size_t edgeIndex(std::size_t i, std::size_t j) {
        if (i > j)
            std::swap(i, j);
        return j * (j - 1) / 2 + i;
    }
    static std::size_t edgeCount(std::size_t members) { return members * (members - 1) / 2; }
    Edge& edge(Object& o, std::size_t i, std::size_t j) { return o.edges[edgeIndex(i, j)]; }
    const Edge& edge(const Object& o, std::size_t i, std::size_t j) const {
        return o.edges[edgeIndex(i, j)];
    }
    bool established(const Member& m) const { return m.framesReliable >= config_.minModelFrames; }
    /// Three established members rigid with it left as members of no cluster while it was
    /// hidden: it may be on the body they were, and goes into no model until seen again.
    static bool placeInDoubt(const Member& m) { return m.partnersLeftUnseen >= 3; }
    /// An occluded member whose place the object's pose predicts: established, in the current
    /// frame, and agreeing with the pose the last time it was seen.
    bool predictable(const Object& o, const Member& m) const {
        return o.posed && m.verified && m.wasInlier && established(m);
    }
    /// Which members of an object a layout search looks at or a merge carries over. Occluded:
    /// verified and hidden. Verified: positions in the object's current frame. OldFrame:
    /// established positions still in the frame before a re-base (see rebase()).
    enum class Members : std::uint8_t { Any, Occluded, Verified, OldFrame };
    bool selects(Members which, const Member& m) const {
        switch (which) {
        case Members::Any:
            return true;
        case Members::Occluded:
            return m.verified && !m.visible;
        case Members::Verified:
            return m.verified;
        case Members::OldFrame:
            return !m.verified && established(m);
        }
        return false;
    }
    /// The first member of \a o (of those \a which names) that \a T_to_from_object puts
    /// within the reappearance radius of \a p_mm; kNone when there is none.
    std::size_t memberNear(const Object& o, const RigidTransform& T_to_from_object,
                           const Vec3& p_mm, Members which) const;

    void bindTrackedMarkers(std::span<const TrackedMarker> tracked);
    void removeInvalidMarkers();
    void updateObject(Object& o);
    /// After a split, which members are measured again in the part's frame: none, those not yet
    /// established (the part that keeps the object), or all of them (a part that splits off).
    enum class Remeasure { None, NewMembers, All };
    void fitPose(Object& o, Remeasure remeasure = Remeasure::None);
    /// An object's pose (rig from object-graph frame, mm) and whether only established members
    /// made it.
    struct ConsensusPose {
        RigidTransform T_rig_from_object;
        bool fromEstablished = false;
    };
    /// The pose most of fitFrom_/fitTo_ agree with (weighted by votes_), refitted by refit().
    std::optional<ConsensusPose> consensusPose();
    /// Least-squares pose of the first \a count pairs of fitFrom_/fitTo_ (which it reorders):
    /// of their established members alone when three of them (not on a line) fix it, else of all.
    std::optional<ConsensusPose> refit(std::size_t count);
    void rebase(Object& o);
    void clusterObject(std::size_t objectIndex);
    void removeGhosts(Object& o);
    void recogniseReappearing(std::span<const TrackedMarker> tracked);
    void insertNewMarkers(std::span<const TrackedMarker> tracked);
    /// The members of one of \a o's frames (after a re-base its hidden members keep the frame
    /// before it until seen again): the frame with more established members, and how many.
    struct FrameGroup {
        Members members;
        std::size_t established;
    };
    FrameGroup largerFrameGroup(const Object& o) const;
    /// True when member \a i of \a o has mature edges to two members whose edge broke.
    bool bridgesABreak(const Object& o, std::size_t i) const;
    /// When members outside \a keep leave \a o (to other \a clusters, or to none): hidden
    /// members it keeps that may be on the body of those that leave must be seen again to count.
    void forgetAmbiguousHiddenMembers(Object& o, std::span<const MarkerSet> clusters,
                                      const MarkerSet& keep);
    /// Fills joinedClusters_ with \a clusters, those sharing three members not on a line joined.
    void joinClustersSharingATriangle(const Object& o, std::span<const MarkerSet> clusters);
    /// True when \a shared holds three members of \a o (current frame) not on one line.
    bool spansATriangle(const Object& o, const MarkerSet& shared) const;
    void collapseObjects();
    void refind(Object& o);
    /// Where \a o's layout (the members \a which names) lies among \a points
    /// (mm, any frame): the transform from \a o's frame to the points' frame, found from
    /// congruent triangles; nothing unless at least \a minPoints and \a share of the
    /// points sit on members, all of them within the pose threshold after a joint fit.
    /// The scratch of fitLayout() for \a o's members that \a which names: their pairs by
    /// distance (memberPairs_), by first member (pairsByMember_) and their places
    /// (searchedMembers_); false when they make fewer than six pairs.
    bool indexMemberPairs(const Object& o, Members which);
    std::optional<RigidTransform> fitLayout(const Object& o, std::span<const Vec3> points,
                                            Members which,
                                            std::size_t minPoints = kRefindMinMarkers,
                                            double share = kRefindShare);
    /// Two objects both posed at once in places too far apart to be one body (by the slots of
    /// objects_): they may share a layout (identical objects) but are never merged by shape.
    void recordObjectsSeenApart();
    bool seenApart(std::size_t a, std::size_t b) const;
    void setSeenApart(std::size_t a, std::size_t b, bool apart);
    void mergeDuplicates();
    void mergeByLayout();
    /// Moves \a from's members (those \a carry names; the rest are dropped) into \a into, through
    /// \a T_into_from_from, and deactivates \a from.
    void merge(Object& from, Object& into, const RigidTransform& T_into_from_from,
               Members carry = Members::Any);

    /// A free object slot; when none is free, the slot of the object least worth keeping (see
    /// the definition), never \a keep's.
    Object* newObject(const Object* keep = nullptr);
    void deactivate(Object& o);
    bool addMember(Object& o, std::size_t marker, const Vec3& model_mm);
    void removeMember(Object& o, std::size_t member);
    std::size_t newMarker(std::uint32_t trackerId, const Vec3& position_rig_mm);
    void releaseMarker(std::size_t marker);
    void rebuildTrackerIndex();
    std::size_t findByTrackerId(std::uint32_t trackerId) const;

    CalibrationConfig config_;
    bool valid_ = false;
    std::size_t stride_ = 0;
    MarkerTracker tracker_;
    PyramidClustering clustering_;
    /// The clustering's clusters with those rigidly linked through three shared members joined.
    BoundedVector<MarkerSet> joinedClusters_;
    CalibrationCounters counters_{};
    std::vector<Object> objects_;
    BoundedVector<KnownMarker> markers_;
    /// (trackerId, marker) sorted by trackerId, for the markers seen last frame.
    BoundedVector<std::pair<std::uint32_t, std::size_t>> byTrackerId_;
    /// Per tracked marker of this frame: the known marker it is, or kNone.
    BoundedVector<std::size_t> knownOfTracked_;
    /// This frame's points in canonical order (sortPointsCanonically).
    BoundedVector<Vec3> sortedPoints_;
    /// Scratch of the size of one object: point pairs to fit, and each pair's vote.
    BoundedVector<Vec3> fitFrom_;
    BoundedVector<Vec3> fitTo_;
    BoundedVector<double> votes_;
    /// Scratch of updateObject: where each member is now (rig frame, mm), and how that is known.
    enum class Whereabouts : std::uint8_t { Seen, Predicted, Unknown };
    BoundedVector<Vec3> positionNow_;
    BoundedVector<Whereabouts> whereabouts_;
    FixedVector<MarkerSet, MarkerSet::kCapacity> adjacency_;
    BoundedVector<std::uint32_t> stamp_;
    BoundedVector<std::size_t> candidates_;
    struct MemberPair {
        double distance_mm = 0.0;
        std::size_t i = 0;
        std::size_t j = 0;
    };
    BoundedVector<MemberPair> memberPairs_;
    /// The same pairs by first member, each member's by distance (pairs of member i start at
    /// pairsOfMemberStart_[i]): where a layout search finds the third corner of a triangle.
    BoundedVector<MemberPair> pairsByMember_;
    BoundedVector<std::size_t> pairsOfMemberStart_;
    /// Scratch of a layout search: the members that can be a triangle's third corner, and the
    /// searched members' places (object frame) and where a try puts them (the points' frame).
    BoundedVector<std::size_t> thirdCorners_;
    BoundedVector<Vec3> searchedMembers_;
    BoundedVector<Vec3> placedMembers_;
    /// Scratch of layout searches: the points searched for (mm), and a small piece's layout.
    BoundedVector<Vec3> searchPoints_;
    BoundedVector<Vec3> piecePoints_;
    /// maxObjects x maxObjects bits: which objects were seen apart (recordObjectsSeenApart).
    std::unique_ptr<std::uint64_t[]> seenApart_;
    std::size_t seenApartWords_ = 0;
    /// Scratch of recordObjectsSeenApart: per object slot, centre (rig, mm) and radius (mm) of its
    /// established members when it is posed and in view, else a negative radius.
    BoundedVector<Vec3> extentCentre_;
    BoundedVector<double> extentRadius_;
    /// Scratch of exportModels' S_min (mutable: exporting changes nothing the calibrator knows).
    mutable SminWorkspace sminWorkspace_;
    /// Round-robin start of the shape searches of mergeDuplicates, one per check.
    std::size_t nextShapeSearch_ = 0;
    std::uint32_t stampValue_ = 0;
    double edgeAlpha_ = 0.2;
    std::uint32_t nextMarkerId_ = 1;
    std::uint32_t nextObjectId_ = 0;
    bool structureChanged_ = false;

    static constexpr std::size_t kConsensusTries = 40;
    static constexpr double kEstablishedVote = 10.0;
    /// A marker dropped from every object gets another chance to join one after this long: it
    /// may have been dropped while the objects around it were still splitting.
    static constexpr std::uint64_t kRetryRejected_frames = 100;
    /// A lost object is found again from at least this many of its markers.
    static constexpr std::size_t kRefindMinMarkers = 6;
    static constexpr double kRefindShare = 0.6;
    /// Established markers of two posed objects that must coincide to make them one body.
    static constexpr std::size_t kMergeInPlaceMin = 4;
    /// Three shared markers link two clusters rigidly when one stands this far off the line
    /// through the other two (mm): a few times the pose threshold.
    static constexpr double kMinTriangleHeight_mm = 5.0;
    /// A member missing from this share of at least this many frames in which it was expected
    /// is stale (see removeGhosts).
    static constexpr std::uint32_t kGhostEvidence_frames = 300;
    static constexpr double kGhostMissShare = 0.95;
    /// A member is expected only while the cameras look at it from within this cone (cosine of
    /// its half angle) about the mean direction it was seen from, when that mean is this clear
    /// (its length: 1 when always seen from one direction).
    static constexpr double kFacingCosine = 0.866;
    static constexpr double kMinFacingClarity = 0.5;
    /// Inner steps of one search for a lost object, so that a flood of new points cannot stall.
    static constexpr std::size_t kRefindBudget = 200000;
    /// Objects are compared for duplicates every this many frames.
    static constexpr std::uint64_t kMergeInterval_frames = 10;
    static constexpr std::size_t kNone = static_cast<std::size_t>(-1);
};

} // namespace edgetrack
