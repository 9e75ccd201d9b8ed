// Model-based tracking (paper section 5): finds calibrated marker models in unlabelled 3D points.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <span>
#include <vector>

#include "core/bounded_vector.hpp"
#include "core/geometry.hpp"
#include "core/marker_model.hpp"
#include "core/marker_set.hpp"
#include "core/rigid_fit.hpp"
#include "core/rigid_transform.hpp"

namespace edgetrack {

/// \brief Thresholds and capacities of model-based tracking; defaults suit the simulated rig.
struct ModelTrackingConfig {
    /// A data distance and a model edge agree within this (mm); also the hashtable's bin width.
    /// The paper used 4 mm; the simulated rig's distances are good to 0.1 mm, and each halving of
    /// the tolerance halves the candidates of a search (a quarter of its pair checks). Models
    /// learnt by `calibrate` or the board carry an S_min found at this tolerance (a wrong pose
    /// starts from distances that agree within it), which stays safe at any smaller one; a
    /// tracker set to a larger one needs its models learnt again.
    double distanceTolerance_mm = 1.0;
    /// A data point this close to a model marker placed by a pose is that marker (mm).
    double matchRadius_mm = 2.0;
    /// When a pose's residual exceeds half its residual gate (below), the match that lies
    /// outlierFactor times the RMS of the others (and at least outlierFloor_mm) away from their
    /// fit is dropped: a spurious point beside a hidden marker would otherwise pull the pose by a
    /// millimetre.
    double outlierFactor = 3.0;
    double outlierFloor_mm = 0.5;
    /// A pose is accepted when the RMS of eq. 6 over its matched markers is at most this (mm),
    /// and, once the body has a track record, at most rmsGateFactor times its typical residual
    /// (but never below rmsGateFloor_mm): a wrong point among few markers raises the residual
    /// well above what the body usually shows, while the absolute bound must allow for noisier
    /// rigs (real Vicon data fits at 0.25 mm, the simulated rig at 0.06 mm).
    double maxRms_mm = 1.0;
    double rmsGateFactor = 4.0;
    double rmsGateFloor_mm = 0.25;
    /// Around a predicted marker, the first association looks this far (mm): it covers a
    /// prediction that is off by an unforeseen acceleration between two frames.
    double predictionRadius_mm = 12.0;
    /// A body is predicted from its last poses for this long after it was last found (s); after
    /// that it is lost and searched for.
    double predictionHorizon_s = 0.05;
    /// A body followed from its prediction stays found with this many markers, even below its
    /// S_min: its identity comes from continuity, S_min only has to hold when it is first found.
    std::uint32_t minTrackedMarkers = 4;
    /// The matched markers of a pose must lie at least this far (mm, largest distance in the
    /// model frame) off the line that fits them best: markers on one line leave the turn about it
    /// undetermined, and such a pose puts every other marker of the body at random.
    double minPoseSpread_mm = 3.0;
    /// A body with a copy (same layout) that was found within this time (s) keeps its identity by
    /// position when both are searched for: each copy takes the hypothesis nearest to where it was.
    double identityMemory_s = 2.0;
    /// Data points per frame; more are counted and left out.
    std::size_t maxPoints = 256;
    /// Candidate (data point, model marker) pairs kept per model marker in one search (at most
    /// 64: the agreement between candidates is held in one 64-bit word per candidate).
    std::size_t maxCandidatesPerMarker = 64;
    /// Candidate pair checks per frame over all searches: what a flood of spurious points may
    /// cost. Searches past it are skipped and counted.
    std::uint64_t searchBudget = 200000;

    bool operator==(const ModelTrackingConfig&) const = default;
};

/// \brief How a body was found in the last frame.
enum class PoseSource : std::uint8_t {
    None,      ///< not found
    Predicted, ///< its prediction from the last poses was confirmed
    Searched,  ///< found by the subgraph search
};

/// \brief One body (one model) after a frame.
struct TrackedBody {
    /// The model's id (body_<id>.json).
    std::uint32_t modelId = 0;
    PoseSource source = PoseSource::None;
    /// Maps model coordinates (mm) to rig coordinates (mm); valid when source != None.
    RigidTransform T_rig_from_model;
    /// Markers matched to data points.
    std::uint32_t markers = 0;
    /// Eq. 6 as an RMS over the matched markers (mm).
    double rms_mm = 0.0;
    /// Time (s) of the last frame the body was found in; -infinity before the first.
    double lastFound_s = -std::numeric_limits<double>::infinity();

    bool found() const { return source != PoseSource::None; }
};

/// \brief Run-time counters of the tracker (PX4 style: printed by the status view).
struct ModelTrackingCounters {
    std::uint64_t frames = 0;
    std::uint64_t pointOverflow = 0;      ///< data points left out (more than maxPoints)
    std::uint64_t predictedHits = 0;      ///< bodies confirmed from their prediction
    std::uint64_t predictionFailures = 0; ///< predictions not confirmed (then searched for)
    std::uint64_t searches = 0;           ///< subgraph searches run (one body, one frame)
    std::uint64_t searchHits = 0;         ///< searches that found their body
    std::uint64_t pairChecks = 0;         ///< candidate pair checks (the search's unit of work)
    std::uint64_t hypotheses = 0;         ///< 4-cliques fitted
    std::uint64_t candidateOverflow = 0;  ///< candidates dropped (maxCandidatesPerMarker)
    std::uint64_t budgetExhausted = 0;    ///< frames in which the search budget ran out
    std::uint64_t searchesSkipped = 0;    ///< searches not run or cut short by the budget
    std::uint64_t identityYields = 0;     ///< hypotheses left to a copy that was nearer to them
    std::uint64_t degeneratePoses = 0;    ///< poses refused: their markers lie on one line
    /// Search hypotheses refused at once: their first matches were refused before in the search.
    std::uint64_t repeatedRefusals = 0;
};

/**
 * \brief Finds the poses of several rigid marker models in each frame of 3D points.
 *
 * Built once from the models: a distance hashtable per model (its co-visibility edges binned by
 * length, bin width = distance tolerance), the model's adjacency, and every per-frame buffer,
 * sized from the models and the configuration. update() then never allocates.
 *
 * Each frame, bodies found recently are first predicted (constant velocity and turn rate) and
 * confirmed against the data; the others are searched for as the paper describes: for a data point
 * p, its distances to the other points are looked up in the hashtable, giving candidate
 * (point, marker) pairs for every model marker V that p may be; three candidates that agree with
 * each other on distances and co-visibility make a 4-clique with (p, V); its least-squares fit
 * places the model, and every data point near a model marker is matched. A hypothesis with at
 * least S_min matches and a small residual is kept; of all the hypotheses the best wins: the most
 * matched markers, then the smallest eq. 6 residual. Each data point serves one body at most.
 */
class ModelTracker {
public:
    /**
     * \param models the models to track (copied); bodies() follows their order.
     * \param config thresholds and capacities.
     */
    ModelTracker(std::span<const MarkerModel> models, const ModelTrackingConfig& config);

    /// \return false when a model has more than MarkerSet::kCapacity markers or the
    /// configuration is unusable (non-positive tolerances, no points).
    bool isValid() const { return valid_; }

    /**
     * \brief Track one frame.
     * \param time_s frame time (s), increasing.
     * \param points_rig_mm the frame's 3D markers, rig frame (mm), in any order.
     * \param searchLost false to leave the bodies that their predictions do not confirm unfound
     * in this frame, without a search (offline passes that search only every few frames).
     */
    void update(double time_s, std::span<const Vec3> points_rig_mm, bool searchLost = true);

    /// \brief Forget every body's history (as after a gap in the data).
    void reset();

    /**
     * \brief Carry body \a fromBody of \a from over to this tracker's body \a body: its last
     * poses (for prediction and for telling copies apart by position), residual record and the
     * time it was last found. For a model set replaced by another in which that body's model
     * keeps its frame (a recalibrated layout registered onto the old one): it is then followed on
     * at once, and of two identical objects each keeps its id.
     */
    void continueBody(std::size_t body, const ModelTracker& from, std::size_t fromBody);

    /// \return one entry per model, in model order, as of the last update().
    std::span<const TrackedBody> bodies() const { return bodies_; }

    /// \return for each data point of the last frame, the index in bodies() of the body that
    /// used it, or -1.
    std::span<const std::int16_t> pointOwners() const {
        return std::span<const std::int16_t>(frame_.owner.data(), frame_.count);
    }

    const ModelTrackingCounters& counters() const { return counters_; }

private:
    struct HashEntry {
        std::uint16_t a = 0;
        std::uint16_t b = 0;
        double distance_mm = 0.0;
    };
    /// Where one model's data lives in the flat arrays.
    struct ModelSlot {
        std::size_t firstMarker = 0;
        std::size_t markerCount = 0;
        std::size_t firstDistance = 0;
        std::size_t firstBin = 0;
        std::size_t binCount = 0;
        std::uint32_t sMin = 4;
        /// Models of one layout share a group (the index of one of them).
        std::size_t shapeGroup = 0;
        Vec3 centroid_model_mm = Vec3::Zero();
        /// Largest distance of a marker from the centroid (mm).
        double radius_mm = 0.0;
    };
    struct Candidate {
        std::uint16_t point = 0;
        std::uint16_t marker = 0;
    };
    /// Pose history of one body for prediction.
    struct History {
        RigidTransform previous;
        double previous_s = 0.0;
        bool hasPrevious = false;
        RigidTransform last;
        double last_s = 0.0;
        bool hasLast = false;
        /// Running mean of the body's fit residual (mm), for the residual gate.
        double typicalRms_mm = 0.0;
        bool hasRms = false;
    };
    /// One accepted pose hypothesis: pose, matches, residual.
    struct Hypothesis {
        RigidTransform T_rig_from_model;
        std::uint32_t markers = 0;
        double rms_mm = 0.0;
    };

    std::span<const Vec3> modelMarkers(std::size_t body) const {
        const ModelSlot& s = models_.slots[body];
        return std::span<const Vec3>(models_.markers_model_mm)
            .subspan(s.firstMarker, s.markerCount);
    }
    const MarkerSet& adjacency(std::size_t body, std::size_t marker) const {
        return models_.adjacency[models_.slots[body].firstMarker + marker];
    }

    bool predict(std::size_t body, double time_s, RigidTransform& T_rig_from_model) const;
    bool confirmPrediction(std::size_t body, const RigidTransform& predicted);
    void search(std::size_t body, double time_s);
    /// Evaluates the cliques that hold point \a p; false when it did not evaluate them all (it
    /// stopped early, or dropped candidates to maxCandidatesPerMarker).
    bool searchFrom(std::size_t body, std::size_t p, double time_s, Hypothesis& best,
                    bool& haveBest);
    void evaluateClique(std::size_t body, std::span<const Candidate> clique, double time_s,
                        Hypothesis& best, bool& haveBest);
    /// Match free data points to the model placed by \a pose within \a radius_mm; fills
    /// match_.ofMarker and returns the number of matches.
    std::size_t matchMarkers(std::size_t body, const RigidTransform& T_rig_from_model,
                             double radius_mm);
    /// Refine \a pose by matching and fitting until the matches settle; false when fewer than
    /// \a minMatches match, the residual is too large or the matches lie on one line.
    /// With \a rememberRefusals (a search's hypotheses), the first matches of each refusal are
    /// kept until the next search (the last kRememberedRefusals), and a hypothesis whose first
    /// matches are one of those is refused without going on.
    bool refine(std::size_t body, RigidTransform& T_rig_from_model, double firstRadius_mm,
                std::size_t minMatches, Hypothesis& out, bool rememberRefusals = false);
    static constexpr std::size_t kRememberedRefusals = 16;
    /// Whether the matched markers of \a body (match_.ofMarker) lie minPoseSpread_mm or more off
    /// the line that fits them best.
    bool spreadOffOneLine(std::size_t body) const;
    /// Drop up to two outlying matches (see outlierFactor); returns the matches left.
    std::size_t trimOutliers(std::size_t body, RigidTransform& T_rig_from_model,
                             std::size_t matches, std::size_t minMatches, double& rms_mm);
    /// Whether a copy of \a body that is still to be searched for was last seen nearer to
    /// \a centre_rig_mm than \a body was.
    bool nearerCopyWants(std::size_t body, const Vec3& centre_rig_mm, double time_s) const;
    bool hasCopy(std::size_t body) const;
    /// The largest residual (mm) a pose of \a body may have (see maxRms_mm).
    double rmsGate(std::size_t body) const;
    /// Whether \a body was found recently enough to keep its identity by position.
    bool remembers(std::size_t body, double time_s) const;
    /// Publish \a h as \a body's pose and give it the points of match_.ofMarker.
    void accept(std::size_t body, PoseSource source, const Hypothesis& h);
    /// Least-squares fit of the model markers to their matches (match_.ofMarker), \a leftOut
    /// excepted.
    std::optional<RigidFit> fitMatches(std::size_t body, std::size_t leftOut = SIZE_MAX);
    /// The pairs fitMatches() fits, into match_.fitFrom, fitTo and fitMarker.
    void gatherMatches(std::size_t body, std::size_t leftOut = SIZE_MAX);
    bool budgetLeft() const { return frameChecks_ < config_.searchBudget; }

    ModelTrackingConfig config_;
    bool valid_ = true;

    /// The models as the search reads them, built once from the model set.
    struct Models {
        std::vector<ModelSlot> slots;
        std::vector<Vec3> markers_model_mm;
        std::vector<MarkerSet> adjacency;
        /// Each model's marker-to-marker distances (mm), markerCount x markerCount from
        /// firstDistance.
        std::vector<float> distance_mm;
        std::size_t maxMarkers = 0;
    } models_;
    /// The distance hashtable (CSR): bins of all models one after another;
    /// binStart[firstBin + b] .. binStart[firstBin + b + 1) index entries.
    struct DistanceTable {
        std::vector<std::uint32_t> binStart;
        std::vector<HashEntry> entries;
    } table_;

    std::vector<TrackedBody> bodies_;
    std::vector<History> history_;
    std::vector<std::uint8_t> searched_;
    ModelTrackingCounters counters_;

    /// The frame's points and what the search knows of them, sized at construction.
    struct FramePoints {
        std::span<const Vec3> points;
        std::size_t count = 0;
        /// The body each point was given to (-1: free).
        std::vector<std::int16_t> owner;
        std::vector<std::uint8_t> explained;
        /// Points every clique of which the search has looked at, as a seed: later seeds leave
        /// them out, since any clique holding them was evaluated from them.
        std::vector<std::uint8_t> seeded;
        std::vector<std::uint16_t> nearby;
        std::vector<std::uint32_t> candidateCount;
        std::vector<Candidate> candidates;
        /// Distances between the points (mm), count x count, computed at the frame's first
        /// search.
        std::vector<float> distance_mm;
        bool distancesReady = false;
    } frame_;
    double pointDistance(std::size_t a, std::size_t b) const {
        return static_cast<double>(frame_.distance_mm[a * frame_.count + b]);
    }
    /// One hypothesis's matches and fit, sized at construction.
    struct Matching {
        /// Bit b of agreement[a]: candidates a and b of the marker under study agree.
        std::vector<std::uint64_t> agreement;
        std::vector<std::int32_t> ofMarker;
        std::vector<std::int32_t> bestOfMarker;
        std::vector<std::int32_t> fitted;
        std::vector<std::int32_t> claimant;
        std::vector<double> claimDistance;
        BoundedVector<Vec3> fitFrom{0};
        BoundedVector<Vec3> fitTo{0};
        /// The marker of each pair in fitFrom / fitTo.
        std::vector<std::uint32_t> fitMarker;
        /// Outlier trimming: each pair's leave-one-out RMS (mm), and the pairs by it.
        std::vector<double> leftOutRms;
        std::vector<std::uint32_t> fitOrder;
        /// refine(): the point of each marker after the first matching, and the last such sets
        /// that the current search refused (kRememberedRefusals of markerCount each, a ring).
        std::vector<std::int32_t> firstMatches;
        std::vector<std::int32_t> refused;
        std::size_t refusedCount = 0;
        std::size_t refusedNext = 0;
    } match_;
    std::uint64_t frameChecks_ = 0;
};

} // namespace edgetrack
