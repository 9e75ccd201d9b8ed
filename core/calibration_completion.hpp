// Completion of a calibration session: the provisional models tracked through all its frames.
#pragma once

#include <algorithm>
#include <array>
#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <span>
#include <utility>
#include <vector>

#include "core/layout_precision.hpp"
#include "core/marker_model.hpp"
#include "core/model_tracker.hpp"
#include "core/rigid_transform.hpp"
#include "core/session_buffer.hpp"

namespace edgetrack {

namespace completion_detail {
struct SortedTriangle;
class TrianglesByLongestSide;
} // namespace completion_detail

/// \brief Settings of the completion stage; defaults suit hand-held objects at 100 Hz.
struct CompletionConfig {
    /// How the provisional models are followed through the session.
    ModelTrackingConfig tracking = defaultTracking();
    /// A body is found afresh from at most this many of its markers, whatever its S_min.
    std::size_t maxAcquireMarkers = 6;
    /// Models and markers per model it works with (more are refused and counted).
    std::size_t maxModels = 16;
    std::size_t maxMarkersPerModel = 96;
    /// Points of one place in an object's frame: within this of its mean (mm), or within three
    /// times the median distance of the object's points from its markers where they scatter
    /// more (a 500 mm box placed by a fit of all its markers puts them 1-2 mm about their place),
    /// but never more than half of minMarkerSpacing_mm.
    double siteRadius_mm = 1.5;
    /// A place becomes a marker when a point sat there, the object posed, this long (s)...
    double minSeen_s = 0.3;
    /// ...and in at least this share of the frames in which the cameras looked at it within
    /// sameViewAngle_deg of a direction it was seen from: a marker of another body that sat
    /// still against this one for a while is missing when this one is seen that way again.
    double minSeenShare = 0.3;
    double sameViewAngle_deg = 8.0;
    /// Points farther than this from an object's markers are not looked at for it (mm).
    double reach_mm = 60.0;
    /// Places (markers yet to be learnt) are looked for this far beyond the farthest known
    /// marker from the object's centre (mm): the markers first learnt of a large plate may all
    /// lie at one end of it. Points of other objects within it are kept out by their own poses
    /// and by the places' tests (seen whenever the cameras look that way again).
    double placeReach_mm = 120.0;
    /// Places looked at per object and round (more are refused and counted).
    std::size_t maxSites = 65536;
    /// Rounds of tracking, joining and re-measuring; it stops earlier once nothing changes.
    int maxRounds = 4;
    /// Two objects found at once in this many frames are one rigid body when both layouts, joined
    /// by one relative pose, fit the points of at least sameBodyShare of those frames as one.
    std::size_t minSharedFrames = 10;
    double sameBodyShare = 0.8;
    /// Fitted as one, every point lies within this of its marker (mm); also how close relative
    /// poses must come to start that fit.
    double sameBodyTolerance_mm = 2.0;
    /// Where the tracker needs four markers to find a body, three points pose it when their
    /// distances match one triangle of its layout within triangleTolerance_mm on each side, and no
    /// other triangle of any body comes within triangleUniqueness times that of this one; taken in
    /// runs of at least minTriangleRun consecutive frames whose poses move on by at most
    /// maxTriangleStep_mm, in frames of at most maxTrianglePoints points.
    /// Each of the three markers must be seen from within triangleViewAngle_deg of a direction it
    /// was seen from in a frame posed otherwise.
    double triangleTolerance_mm = 0.75;
    double triangleUniqueness = 4.0;
    double triangleViewAngle_deg = 30.0;
    std::size_t minTriangleRun = 10;
    double maxTriangleStep_mm = 10.0;
    std::size_t maxTrianglePoints = 32;
    /// Two markers of one model closer than this are one (mm).
    double minMarkerSpacing_mm = 4.0;
    /// Rounds of pose fits and a joint least-squares marker step at the end.
    int refineIterations = 4;
    /// A marker whose typical squared residual (the median over its frames) is more than this
    /// times the rig's (that of the most rigid body's markers) did not move with its body and
    /// is dropped: 4 is twice the RMS, far beyond the scatter of a median over 30 frames or more.
    double maxResidualRatio = 4.0;
    /// A frame whose points lie off its fit by more than this times the rig's typical squared
    /// residual on average (3 times the RMS) is left out of the layout's least squares.
    double maxFrameResidualRatio = 9.0;
    /// A model has at least this many markers.
    std::size_t minModelMarkers = 4;
    /// ...of which at least minModelMarkers were each seen, with three others of it, this long
    /// (s): a piece of an object that was shown only for a moment, and that nothing ties to the
    /// rest, would otherwise be tracked as an object of its own.
    double minModelSeen_s = 1.0;
    /// Where the cameras are, rig frame (mm): markers are seen from here.
    Vec3 viewpoint_rig_mm = Vec3::Zero();
    /// The points come from one stereo rig at viewpoint_rig_mm, whose error grows with the
    /// square of the distance (residuals are compared in units of it); false for points from a
    /// multi-camera system around a room (a C3D file), whose error does not depend on where.
    bool noiseGrowsWithDistance = true;
    SminConfig smin{};

    static ModelTrackingConfig defaultTracking() {
        ModelTrackingConfig c;
        // Points of a session are noisier than the tracker's bench rig (0.3 mm at the far end).
        c.distanceTolerance_mm = 1.5;
        // Off the frame loop, a frame's search may take longer than on it: up to about 780
        // hypotheses (at 1,024 checks each), which the noisy real Vicon recording needs.
        c.searchBudget = 800000;
        // Three markers near their predicted places carry a pose on: a piece of an object is
        // followed while it turns out of view, so the markers that come into view join it.
        c.minTrackedMarkers = 3;
        return c;
    }

    bool operator==(const CompletionConfig&) const = default;
};

/// \brief What completion did, for the summary and the status view.
struct CompletionCounters {
    std::uint64_t rounds = 0;
    std::uint64_t framesTracked = 0;
    /// Frames in which a body the tracker had lost was followed on from a neighbouring frame.
    std::uint64_t framesFollowed = 0;
    /// Frames in which a body was posed from three of its markers (a unique triangle).
    std::uint64_t framesFromTriangles = 0;
    /// Frames in which a body kept a pose it took from a joined piece, not found again by the
    /// tracker.
    std::uint64_t framesKept = 0;
    std::uint64_t seeds = 0;
    /// Bodies found in the session's points that no seed explained.
    std::uint64_t discovered = 0;
    /// Objects joined because they moved as one body, or because one's layout lies in the other's
    /// (four or more markers, or the one triangle they share) and they were never seen apart.
    std::uint64_t joinedByMotion = 0;
    std::uint64_t joinedByLayout = 0;
    /// Objects joined because three or more of their markers were the same points, followed
    /// from frame to frame from the one's poses to the other's.
    std::uint64_t joinedByTracks = 0;
    /// Objects dropped for having fewer than minModelMarkers markers in the end.
    std::uint64_t dropped = 0;
    /// Objects not made models because too few of their markers were seen four at once for
    /// minModelSeen_s.
    std::uint64_t droppedSeenBriefly = 0;
    /// Markers found beyond the seeds', and seed markers not confirmed.
    std::uint64_t markersAdded = 0;
    std::uint64_t markersRemoved = 0;
    /// Markers dropped at the end because their points did not move with their body (see
    /// maxResidualRatio), and objects left with too few markers by it: not rigid.
    std::uint64_t markersNotRigid = 0;
    std::uint64_t droppedNotRigid = 0;
    /// Markers dropped at the end because no frame fixed them to the rest of their body (see
    /// rigidGroupsOf: tied by markers on one line at most).
    std::uint64_t markersNotFixed = 0;
    /// Pairs of models written that hold two or more of the same markers (UntiedPieces).
    std::uint64_t untiedPieces = 0;
    /// Refused for lack of room: places, models, markers of a model.
    std::uint64_t siteOverflow = 0;
    std::uint64_t modelOverflow = 0;
    std::uint64_t markerOverflow = 0;
};

/**
 * \brief Two models written that hold the same markers, yet no frame tied them into one layout.
 *
 * Points followed from frame to frame sat on two or more markers of both, so both are pieces of
 * one object; yet no tie of the join step held: most often they share two markers, which leave
 * the turn about the line through them open, and no frame showed enough of both to fix it. The
 * session cannot make one model of them: the user has to show the object again, turning it so
 * that the markers between the pieces are in view together.
 */
struct UntiedPieces {
    /// The two models, by id (index into run()'s output), the larger first.
    std::size_t first = 0;
    std::size_t second = 0;
    /// Markers of the one that are markers of the other too.
    std::size_t sharedMarkers = 0;
};

/**
 * \brief Turns the online stage's provisional models into complete ones, using every frame of the
 * session (the paper's section 7.1: the tracker applied where frame-to-frame correspondence was
 * lost).
 *
 * In rounds: all models are tracked together through the session, forwards and backwards, by the
 * model-based tracker; two models that move as one rigid body, or one of whose layouts lies in the
 * other's while they are never seen apart, are joined; then every model is measured again from
 * scratch: each frame's points are put into the model's frame by its pose, and the places where
 * points sit across many frames, and are seen whenever the cameras look at them as before, become
 * its markers. The rounds stop when the models stop changing. Marker positions are then refined by
 * least squares over every pose and marker at once, co-visibility edges are counted, and S_min is
 * set.
 *
 * It runs once, when a session ends, off the frame loop (the firmware gives it a thread of its
 * own): run() allocates its working storage when it starts, unlike the per-frame stages.
 */
class CalibrationCompletion {
public:
    explicit CalibrationCompletion(const CompletionConfig& config);

    /// \brief False when the configuration cannot work.
    bool isValid() const { return valid_; }

    /**
     * \brief Complete \a seeds over \a session.
     * \param session every frame of the session.
     * \param seeds provisional models (the online stage's), any frame each.
     * \param out models to fill, each able to hold maxMarkersPerModel markers.
     * \return how many models were written, ids 0, 1, ... in order of size.
     */
    std::size_t run(const SessionBuffer& session, std::span<const MarkerModel> seeds,
                    std::span<MarkerModel> out);

    const CompletionCounters& counters() const { return counters_; }
    /// \brief Per model written by the last run() (by id): how closely the session fixed it.
    std::span<const LayoutPrecision> precision() const { return precision_; }
    /// \return for each model of the last complete(), the most of its markers one frame of the
    /// session showed: a model whose S_min is above it will seldom or never be found.
    std::span<const std::size_t> mostSeenTogether() const { return mostSeenTogether_; }
    /// \brief The models written by the last run() that are pieces of one object (see
    /// UntiedPieces).
    std::span<const UntiedPieces> untiedPieces() const { return untiedPieces_; }

private:
    /// An object as completion knows it: markers in its own frame (mm) and, per session frame,
    /// its pose if it was found.
    struct Body {
        std::vector<Vec3> markers_mm;
        /// Co-visible marker pairs (a < b).
        std::vector<std::pair<std::uint16_t, std::uint16_t>> edges;
        std::vector<RigidTransform> T_rig_from_body;
        std::vector<std::uint8_t> posed;
        /// Frames whose pose came from a piece joined to it (the piece's pose).
        std::vector<std::uint8_t> posedByJoin;
        /// Its poses when tracked with no other body: where pieces of one object share markers,
        /// the joint tracker gives the shared points to one of them, and the other goes unposed.
        std::vector<RigidTransform> T_rig_from_body_alone;
        std::vector<std::uint8_t> posedAlone;
        /// The model those poses were tracked with: tracked alone again only when it changed.
        std::optional<MarkerModel> trackedAloneAs;
        bool alive = true;
        /// Stable over the rounds (bodies_ is sorted): which body this is.
        std::uint32_t id = 0;
        /// Ids of the bodies found with it in many frames at changing relative poses: other
        /// objects, whose points are never this one's markers.
        std::vector<std::uint32_t> apartFrom;
        bool isApartFrom(std::uint32_t other) const {
            return std::find(apartFrom.begin(), apartFrom.end(), other) != apartFrom.end();
        }
        /// How far its points lie from its places (mm): siteRadius_mm, or more where they scatter.
        double placeRadius_mm = 0.0;
        /// The most of its markers seen in one frame while it was posed (measure()); 0 before.
        std::size_t mostSeenTogether = 0;
        /// Places (body frame, mm) where points sat in a few frames, too few to be markers: where
        /// a piece of the same body, which holds them as markers, may register onto this one.
        std::vector<Vec3> glimpsed_mm;
        /// Its markers refined by least squares over its poses (refine(), the body left as it
        /// is), set by joinBodies(): the layout by which pieces are registered on each other.
        std::vector<Vec3> refined_mm;
        /// Point tracks (linkPointTracks) that sat at one place in its frame while it was posed,
        /// by track: its markers, and points that rode on it.
        struct TrackPlace {
            std::uint32_t track = 0;
            Vec3 place_mm = Vec3::Zero();
        };
        std::vector<TrackPlace> trackPlaces;
        /// Per marker: frames of the last refine() in which it was found with three others.
        std::vector<std::uint32_t> framesInFour;
        /// How closely the frames fix its layout, from the final refine().
        LayoutPrecision precision;
        /// Per marker: the median of its squared residuals over the last refine() pass (mm^2),
        /// each scaled up by the share the fit took of it and down by (d / 1 m)^4 at d from the
        /// cameras (the growth of a stereo point's variance with distance; see
        /// CompletionConfig::noiseGrowsWithDistance); 0 when no frame matched it.
        std::vector<double> markerResidual_mm2;
        /// Per marker: the frames of the last refine() pass that matched it.
        std::vector<std::uint32_t> markerFrames;
        /// The largest mean over a frame's points of their residuals in that pass, in the units
        /// of markerResidual_mm2.
        double worstFrameResidual_mm2 = 0.0;
        /// Its rigid groups in that pass (completion_detail::rigidGroupsOf).
        std::vector<std::array<std::uint64_t, 2>> rigidGroups;
        /// \brief Whether at least \a markers of its markers were each seen in four for at
        /// least \a frames frames.
        bool seenInFour(std::size_t markers, std::uint32_t frames) const {
            return static_cast<std::size_t>(
                       std::count_if(framesInFour.begin(), framesInFour.end(),
                                     [&](std::uint32_t n) { return n >= frames; })) >= markers;
        }
    };
    struct Site {
        Vec3 sum_mm = Vec3::Zero();
        std::uint32_t hits = 0;
        std::uint32_t lastFrame = UINT32_MAX;
        std::int32_t next = -1;
    };

    /// \brief Models of the bodies [0, count) for the tracker: their markers, co-visibility (or
    /// every pair while none is known) and S_min as completion tracks.
    std::vector<MarkerModel> trackingModels(std::size_t count);
    /// Where one tracked model's poses go: per session frame, whether it was found and its pose.
    struct PoseTrack {
        std::vector<std::uint8_t>* posed;
        std::vector<RigidTransform>* T_rig_from_body;
    };
    /// Which other bodies markersOfOthersAt() looks at: every one, or those known to be other
    /// objects (Body::apartFrom).
    enum class OtherBodies { All, KnownApart };
    /// \brief Where the alive bodies other than \a body that were found in frame \a f put their
    /// markers (rig frame, mm), into \a out (cleared first).
    void markersOfOthersAt(std::size_t f, const Body& body, OtherBodies which,
                           std::vector<Vec3>& out) const;
    /// \brief Every alive body tracked together (bodies_ sorted alive first, largest first).
    void trackAll(const SessionBuffer& session);
    /// \brief Drop the markers whose typical residual (refine() measured it) is more than
    /// maxResidualRatio times \a typical_mm2, the rig's: they did not move with the body. A body
    /// left with fewer than minModelMarkers is no longer alive. Whether it changed the body.
    bool dropMarkersThatDoNotMoveWithTheBody(Body& body, double typical_mm2);
    /// \brief The bodies' final layouts: refined over all their poses, then judged against the
    /// rig's noise (markers that did not move with their body, frames posed wrongly) and cut to
    /// what frames fix (keepTheLargestRigidGroup), each body's precision measured last.
    void settleLayouts(const SessionBuffer& session);
    /// \brief Keep only the markers of the body's rigid group seen most (refine() found the
    /// groups): the others are tied to it by markers on one line at most, and their places about
    /// it are fixed by no frame. Whether any was dropped.
    bool keepTheLargestRigidGroup(Body& body);
    /// \brief Of two markers closer than minMarkerSpacing_mm, keep the one more frames matched:
    /// two markers that close are one blob to the cameras. Whether any was dropped.
    bool mergeCrowdedMarkers(Body& body);
    /// \brief Poses that \a body took from a piece joined to it (Body::posedByJoin, \a was) and
    /// the tracker did not find again, kept where its markers still fit the points: a body joined
    /// from pieces may need more markers to be found afresh than a piece of it shows.
    void keepJoinedPosesThatStillFit(const SessionBuffer& session, Body& body,
                                     std::span<const RigidTransform> was);
    /// \brief \a models tracked together through the session forwards and backwards; model k's
    /// poses go to \a tracks[k].
    void trackBothWays(const SessionBuffer& session, const std::vector<MarkerModel>& models,
                       std::span<const PoseTrack> tracks);
    /// \brief Every alive body posed, in the frames the tracker did not find it, from three
    /// points that match a triangle of its layout that no other triangle of any body resembles.
    void poseFromTriangles(const SessionBuffer& session);
    /// A body to pose from triangles, and what poseFromTriangles() gathers for it.
    struct TriangleJob;
    void poseFromTriangles(const SessionBuffer& session, std::vector<TriangleJob>& jobs);
    /// Frame \a f's pose of each of \a jobs' bodies not posed there, from the frame's points
    /// \a free and their triangles \a seenTriangles, where one pose is best. \a owned holds
    /// every job's own triangles, by longest side, with SortedTriangle::body naming the job.
    void poseFromTriangles(std::span<const Vec3> free,
                           std::span<const completion_detail::SortedTriangle> seenTriangles,
                           const completion_detail::TrianglesByLongestSide& owned,
                           std::span<TriangleJob> jobs, std::size_t f) const;
    /// The poses from triangles that lie in runs of poses following on from each other, into
    /// \a job's body.
    void keepTriangleRuns(TriangleJob& job);
    /// \brief New bodies from sets of four or more points that no body explains, that keep their
    /// distances while they move over a third of a second; each tracked through the session.
    void discoverBodies(const SessionBuffer& session);
    /// \brief \a body followed frame by frame into the frames next to its poses where the
    /// tracker lost it: its pose carried on at its speed, fitted to the points near its markers
    /// and near points that sat at one place in its frame for a few frames, as the online stage
    /// follows a turning object whose markers come and go. Those points become markers only if
    /// measure() finds them so.
    void follow(const SessionBuffer& session, Body& body);
    /// \return whether any were joined.
    bool joinBodies(const SessionBuffer& session);
    /// \brief Every point of the session linked to the point it continues in the frame before,
    /// where that is plain (mutual nearest to where its speed puts it, every other candidate far):
    /// trackOf_ names each point's track.
    void linkPointTracks(const SessionBuffer& session);
    /// \brief Body::trackPlaces of \a body from its poses.
    void placeTracks(const SessionBuffer& session, Body& body) const;
    /// \brief How many markers of \a a are markers of \a b too: tracks that sat on a marker of
    /// each, in pairs as far apart in both layouts (Body::trackPlaces must be current).
    std::size_t sharedMarkers(const Body& a, const Body& b) const;
    /// \brief b's frame to a's, when three or more point tracks, not on one line, sat at one
    /// place in each piece's frame (one physical point, followed from one piece's poses to the
    /// other's) and those places agree as one rigid layout.
    std::optional<RigidTransform> tiedByTracks(const Body& a, const Body& b) const;
    struct OneBodyFit {
        /// b's frame to a's, refined by least squares over the frames that fit.
        RigidTransform T_into_from_from;
        /// Shared frames whose points the union of both layouts fits, every point within
        /// sameBodyTolerance_mm, each body with two or more markers found where its own pose puts
        /// them (a marker they share must be the same point for both).
        std::size_t framesFitting = 0;
    };
    /// \brief Whether \a a and \a b, found at once in \a sharedFrames (jointly, or each alone
    /// when \a alone), are one rigid body: their layouts joined by \a T_a_from_b and fitted as one.
    OneBodyFit fitAsOneBody(const SessionBuffer& session, std::span<const std::size_t> sharedFrames,
                            const Body& a, const Body& b, bool alone,
                            const RigidTransform& T_a_from_b) const;
    /// \brief Whether \a b's centre wanders about in \a a's frame over the frames the joint
    /// tracker found both in: two objects, not two pieces of one.
    bool wandersApart(const Body& a, const Body& b) const;
    /// \brief Whether \a a and \a b, as one body by \a T_a_from_b, move on at no more than
    /// the speed either was seen to move wherever one piece leaves view and the other comes in
    /// (each found alone): a likeness of two objects puts the one body in two places at once.
    bool movesOnSmoothly(const SessionBuffer& session, const Body& a, const Body& b,
                         const RigidTransform& T_a_from_b) const;
    /// The place radius for \a body: three times the median distance of the points near its
    /// markers from them, within [siteRadius_mm, minMarkerSpacing_mm / 2].
    double placeRadiusOf(const SessionBuffer& session, const Body& body) const;
    bool measure(const SessionBuffer& session, Body& body);
    /// \brief Markers refined by least squares over every pose and marker at once (\a iterations
    /// steps), with the poses fitted again, frames whose fit fails unposed, and the edges counted
    /// anew. With \a judge (at the end of completion), the last pass also measures the body's
    /// precision, each marker's typical residual and the worst frame's (Body), and a frame whose
    /// points lie off its fit by more than \a maxFrameResidual_mm2 on average (in the units of
    /// Body::markerResidual_mm2; 0: no limit) is unposed too.
    void refine(const SessionBuffer& session, Body& body, int iterations, bool judge = false,
                double maxFrameResidual_mm2 = 0.0);
    /// \brief \a body's markers as refine() would place them, the body itself left as it is.
    std::vector<Vec3> refinedMarkers(const SessionBuffer& session, const Body& body);
    void countEdges(const SessionBuffer& session, Body& body);
    /// Index of the site within siteRadius_mm of \a q_mm, or -1.
    std::int32_t siteNear(const Vec3& q_mm) const;
    std::int32_t addSite(const Vec3& q_mm);
    std::size_t cellOf(const Vec3& q_mm) const;

    CompletionConfig config_;
    bool valid_ = false;
    CompletionCounters counters_{};
    std::vector<LayoutPrecision> precision_;
    std::vector<std::size_t> mostSeenTogether_;
    std::vector<UntiedPieces> untiedPieces_;
    std::vector<Body> bodies_;
    /// The alive bodies' models as trackAll() last tracked them (bodies_ order).
    std::vector<MarkerModel> roundModels_;
    std::uint32_t nextBodyId_ = 0;
    /// S_min of earlier rounds: each body's tracking model as S_min last saw it (by body id), and
    /// the largest congruence of one onto another (by the two ids). A body whose model stands
    /// keeps its pairs; S_min, computed for every pair of bodies, is most of a round's cost
    /// after the tracking.
    std::map<std::uint32_t, MarkerModel> sminLayoutOf_;
    std::map<std::pair<std::uint32_t, std::uint32_t>, std::size_t> sminLargest_;
    double frameRate_hz_ = 100.0;
    std::vector<Site> sites_;
    /// Each of the session's points' track, by SessionBuffer::firstPoint(frame) + index.
    std::vector<std::uint32_t> trackOf_;
    /// The place radius of the body being measured (mm).
    double placeRadius_mm_ = 1.5;
    /// Places hashed by the cell of their position: the first place of each of kSiteCells cells.
    static constexpr std::size_t kSiteCells = std::size_t{1} << 16;
    std::vector<std::int32_t> cellHead_;
};

} // namespace edgetrack
