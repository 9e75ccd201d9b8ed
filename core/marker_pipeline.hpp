// The marker front end: both cameras' blob detection and stereo correspondence, images to 3D
// points.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <utility>

#include "core/blob_detector.hpp"
#include "core/bounded_vector.hpp"
#include "core/geometry.hpp"
#include "core/stereo_matcher.hpp"

namespace edgetrack {

/// \brief Settings of the front end: `[blobs]` and `[stereo]` of edgetrack.toml.
struct MarkerPipelineConfig {
    BlobDetectorConfig blobs{};
    StereoConfig stereo{};

    bool operator==(const MarkerPipelineConfig&) const = default;
};

/// \brief What the front end refused for want of room or shape, summed over both cameras.
struct MarkerPipelineCounters {
    std::uint64_t rejectedNotRound = 0;
    /// Blobs not round that were split into their discs, and those that could not be.
    std::uint64_t splitBlobs = 0;
    std::uint64_t splitRefused = 0;
    /// Discs cut by an edge in front of them, centred by their visible arc.
    std::uint64_t cutDiscs = 0;
    /// Blobs not round (or perhaps merged) kept whole as one marker's elliptic image.
    std::uint64_t ellipses = 0;
    /// Blobs of two discs split on the epipolar lines of the other camera's separate blobs.
    std::uint64_t splitOnLines = 0;
    /// Splits on epipolar lines not tried for want of the frame's budget (a burst of blobs).
    std::uint64_t splitAttemptsSkipped = 0;
    /// Stereo pairs given up for another partner whose point continues a marker of the last
    /// frame (StereoConfig::continuity_mm).
    std::uint64_t pairsForContinuity = 0;
    /// Markers carried on from one camera's blob while hidden in the other image inside another
    /// marker's blob (StereoConfig::maxCarriedFrames): marker-frames.
    std::uint64_t carriedMarkers = 0;
    /// Markers found again in a blob of several discs where they were expected.
    std::uint64_t markersSplitWhereExpected = 0;
    std::uint64_t blobOverflow = 0;
    std::uint64_t labelOverflow = 0;
    std::uint64_t markerOverflow = 0;
};

/// \brief An 8-bit image of the rig's size: its first row, and rows stride_bytes apart.
struct ImageView {
    const std::uint8_t* pixels = nullptr;
    int stride_bytes = 0;
};

/// \brief How stereo pairs blobs: the paper's matcher, or the epipolar-only baseline of its
/// Figure 6 (for evaluations).
enum class StereoMethod : std::uint8_t { Svd, EpipolarOnly };

/**
 * \brief Turns one exposure of the rig's two cameras into 3D markers (rig frame, mm).
 *
 * This is the one composition of blob detection and stereo that every user runs: the firmware's
 * frame loop, the offline commands (`reconstruct`, `calibrate`, `track`) and the quality runs.
 * A frame is either both images (detectBlobs()) or blobs given from outside (blobs level: fill
 * blobs() yourself), then matchStereo(). All storage is sized by the constructor from the
 * configuration; a frame allocates nothing.
 */
class MarkerPipeline {
public:
    /// \param rig the stereo calibration; both cameras must have the same image size.
    MarkerPipeline(const StereoRig& rig, const MarkerPipelineConfig& config);
    MarkerPipeline(const MarkerPipeline&) = delete;
    MarkerPipeline& operator=(const MarkerPipeline&) = delete;

    /// \return false when the configuration or the rig cannot run (see error()).
    bool isValid() const { return error_ == nullptr; }
    const char* error() const { return error_ == nullptr ? "" : error_; }

    /**
     * \brief Use \a rig from the next frame on (the board's own rig calibration).
     * \return false, keeping the old rig, when \a rig is invalid or of another image size.
     */
    bool setRig(const StereoRig& rig) { return stereo_.setRig(rig); }
    const StereoRig& rig() const { return stereo_.rig(); }

    /**
     * \brief Detect the blobs of one camera's image into blobs(\a camera).
     * \param pixels 8-bit image of the rig's size; rows \a stride_bytes apart (>= width).
     */
    void detectBlobs(int camera, const std::uint8_t* pixels, int stride_bytes);

    /**
     * \brief Pair blobs(0) with blobs(1) and triangulate: markers() and points_rig_mm().
     *
     * Given the two images the blobs were detected in, stereo goes back to them: a blob left
     * unpaired whose epipolar line runs through a blob of the other image may share that blob
     * with other discs (markers far over each other in that image, apart in this one). That blob
     * is then split again on the epipolar lines of all its discs (BlobDetector::splitOnLines()),
     * and each disc triangulated with its partner. A blob the detector refused as not round is
     * split so too, when two or more unpaired blobs' lines cross it. A marker of the frame before
     * that nothing continues is then sought in a blob of several discs where it is expected
     * (StereoConfig::seekExpectedMarkers).
     * \param images the images of this frame's detectBlobs(), or none (blobs given from outside).
     */
    void matchStereo(StereoMethod method = StereoMethod::Svd,
                     const std::array<ImageView, 2>& images = {});

    /// \brief Expect no blob in particular in the next images (see expect()).
    void clearExpected();
    /**
     * \brief Expect a blob where a marker at \a marker_rig_mm (rig frame, mm) appears in each
     * image: when an image has more blobs than room, those near an expected place
     * (BlobDetectorConfig::keepNear_px) are kept first. Places beyond maxBlobs are not kept.
     */
    void expect(const Vec3& marker_rig_mm);

    /// \brief Both images in, 3D markers (rig frame, mm) out.
    std::span<const Vec3> process(const std::uint8_t* pixels0, int stride0_bytes,
                                  const std::uint8_t* pixels1, int stride1_bytes);

    /// \return camera \a camera's blobs (raw pixels) of this frame; writable for blobs level.
    BoundedVector<Blob>& blobs(int camera) { return blobs_[index(camera)]; }
    const BoundedVector<Blob>& blobs(int camera) const { return blobs_[index(camera)]; }
    std::span<const StereoMarker> markers() const { return markers_.span(); }
    /// \return this frame's 3D markers (rig frame, mm), in the order of markers().
    std::span<const Vec3> points_rig_mm() const { return points_rig_mm_.span(); }

    int width_px() const { return width_px_; }
    int height_px() const { return height_px_; }
    const MarkerPipelineConfig& config() const { return config_; }
    const BlobDetector& detector(int camera) const { return detectors_[index(camera)]; }
    const StereoMatcher& stereo() const { return stereo_; }
    /// \brief Refusals since construction. Blobs given from outside that did not fit count too.
    MarkerPipelineCounters counters() const;

private:
    static std::size_t index(int camera) { return camera == 0 ? 0 : 1; }
    /// markerOfBlob_ from markers_.
    void indexMarkersByBlob();
    /// After stereo, and again after the split pass: a marker takes, in one camera, another
    /// blob on its epipolar line when that pair's point continues a point of the last frame and
    /// the frame's points then continue the last frame's closer by more than
    /// kContinuityMargin_mm (a marker that continues none counting as StereoConfig::continuity_mm
    /// off): a blob without a partner (two markers on one line, one hidden from the other
    /// camera), or the blob of another marker, which takes this marker's blob in exchange (two
    /// markers on one line, paired crosswise, whose ghosts may have gone on from frame to frame
    /// as smoothly as markers, but not as close to the two markers' points). \a afterSplit: the
    /// second time, when blobs may have been added or centred anew since stereo prepared them.
    void preferContinuingPairs(bool afterSplit);
    /// After the split pass: a point of the last frame that had continued kMinContinuedFrames and
    /// that no marker continues now is carried on when one camera has a blob without a partner on
    /// whose ray it is expected (within StereoConfig::continuity_mm) and, in the other image,
    /// where that place projects, a blob of several discs covers it (a blob split into discs, or
    /// one refused as not round; given the images, on a lit pixel) or the round blob of a nearer
    /// marker covers its whole disc (nearerMarkerCovers()): the marker is there, hidden in
    /// another's disc. Its point is taken on the ray, nearest where it is expected: where it
    /// was, moved by the step its neighbours took (neighboursStep()). StereoMarker::carried.
    void carryHiddenMarkers(const std::array<ImageView, 2>& images);
    /// After the split pass: which of the last frame's points this frame's markers continue
    /// (lastContinued_, lastStep_, continuesLast_).
    void noteContinuedPoints();
    /// After noteContinuedPoints(): each point of the last frame that had continued one before
    /// and that no marker continues now (or missing for up to kMaxMissingFrames) is sought where
    /// it is expected (its own last step carried on; its neighbours' while missing). Where a blob
    /// of several discs covers that place in an image (parts of a split blob, a blob refused as
    /// not round, or a blob that passed as one disc but is larger than its marker was by
    /// kOwnBlobSize), the blob is fitted again with a free disc for each marker sought in it,
    /// of the size it had, the blob's parts free beside them (BlobDetector::splitOnLines(),
    /// DiscOnLine::free). A disc placed so, paired with the marker's disc or own unpaired blob in
    /// the other image, is the marker when it triangulates within StereoConfig::continuity_mm of
    /// where it was expected; a marker stereo made of a whole blob in which such a disc was found
    /// (the middle of several discs) goes. Trackers follow blobs through merges the same way: the
    /// guess seeds the fit, the outline measures the place.
    void splitWhereMarkersAreExpected(const std::array<ImageView, 2>& images);
    /// The radius (mm) of the sphere that marker \a m's blobs are images of (blob radius times
    /// range over CameraModel::pixelsPerRadian()), the mean of both cameras'; 0 when unknown (a
    /// carried marker's other blob covers several discs).
    double markerSize(std::size_t m) const;
    /// The image radius (px) in \a camera of a sphere of radius \a size_mm (as markerSize())
    /// at \a point_rig_mm.
    double radiusAt(double size_mm, const Vec3& point_rig_mm, int camera) const;
    /// The step (mm) from the last frame to this one of the points near last_[\a hidden] that a
    /// marker continues (within kNeighbourhood_mm, the nearer weighing more); zero when none.
    /// Not its own last step carried on: a marker about to hide moves its disc into another's,
    /// whose blob pulls its centre along; carried on, that step left a third of the carried
    /// points 3-6 mm off within a few frames (touching, seed 1). Nor no step: on the stress
    /// scene's fast objects, 30 carried points fell 3-6 mm behind.
    Vec3 neighboursStep(std::size_t hidden) const;
    /// Whether the bounds of a blob of several discs of \a camera hold \a pixel_px: a part of a
    /// split blob (its index into \a blob) or a blob detection refused as not round (-1).
    /// The covering blob itself into \a cover, when given.
    bool mergedBlobAt(int camera, const Vec2& pixel_px, int& blob, Blob* cover = nullptr) const;
    /// Whether a blob of \a camera that is one marker's, a marker nearer that camera than
    /// \a point_rig_mm, covers the disc of that point (projected at \a pixel_px, of
    /// \a size_mm as LastPoint::size_mm) but for kHiddenDiscMargin_px: the point may be
    /// hidden behind it, their centres too near to show two discs. That blob into \a blob.
    bool nearerMarkerCovers(int camera, const Vec2& pixel_px, const Vec3& point_rig_mm,
                            double size_mm, int& blob) const;
    /// Triangulate \a blob of \a camera (its index \a at) with \a otherBlob of the other camera
    /// (\a otherAt), whichever camera is camera 0.
    bool pairBlobs(int camera, const Blob& blob, int at, const Blob& otherBlob, int otherAt,
                   StereoMarker& marker);
    /// The same for blob \a blob of \a camera and blob \a otherBlob of the other camera.
    bool pairBlobs(int camera, int blob, int otherBlob, StereoMarker& marker);
    /// How far (mm) \a point_rig_mm lies from where a point of the last frame that had continued
    /// kMinContinuedFrames was expected, when within StereoConfig::continuity_mm and no marker
    /// but \a m and \a n (-1: none) continues that point better; infinity otherwise.
    double continuedDistance(const Vec3& point_rig_mm, std::size_t m, int n) const;
    /// After a frame: its points and their ages become the last frame's.
    void rememberForContinuity();
    /// Distance (mm) from \a point_rig_mm to where the nearest of the last frame's points was
    /// expected (its index in last_ into \a nearestIndex, when given); infinity when none lies
    /// within StereoConfig::continuity_mm.
    double distanceToLastFrame(const Vec3& point_rig_mm, std::size_t* nearestIndex = nullptr) const;
    /// The second pass of matchStereo(): blobs of several discs split on epipolar lines.
    void splitOnEpipolarLines(const std::array<ImageView, 2>& images);
    // In the steps of that pass, \a camera is the camera of the unpaired blobs, and \a image
    // is the other camera's image, whose blob is split.
    /// Split blob \a shared of camera 1 - \a camera, which has a partner, and the parts split from
    /// the same blob with it, again with the discs of this camera's unpaired blobs whose epipolar
    /// lines cross it; blobs and markers are updated when every disc with a partner triangulates.
    void splitWithUnpaired(const ImageView& image, int camera, int shared);
    /// A blob of camera 1 - camera to split: its parts so far (blobs of that camera; none for a
    /// blob taken as one disc or refused), and the blob its first new disc replaces (-1: none).
    struct SplitTarget {
        Blob blob;
        std::span<const int> member;
        int replaces = -1;
    };
    /// Split \a blob, a blob of camera 1 - \a camera without a partner (the blob at \a replaces)
    /// or refused by detection as not round (\a replaces -1), into the discs of two or more of
    /// this camera's unpaired blobs whose epipolar lines cross it.
    void splitUnpaired(const ImageView& image, int camera, const Blob& blob, int replaces);
    /// Call \a visit(blob, rectified position) for each blob of \a camera without a partner
    /// that stereo could rectify.
    template <typename Visit>
    void forEachUnpaired(int camera, Visit visit) const;
    /// How many rows (rectified px) a blob of \a camera at \a rectified_px lies off a target of
    /// the other camera at \a targetRectified_px, when its epipolar line crosses the target
    /// (within \a rowReach_px rows, at a disparity of the working volume give or take
    /// \a disparityMargin_px); infinity otherwise.
    double crossingOff(int camera, const Vec2& rectified_px, const Vec2& targetRectified_px,
                       double rowReach_px, double disparityMargin_px) const;
    /// Unpaired blobs whose epipolar lines cross a blob to split: the nearest (by row offset)
    /// first, as many as it can take discs.
    struct Candidates {
        std::array<std::pair<double, int>, BlobDetector::kMaxLineDiscs> nearest{};
        std::size_t count = 0;
        /// Blob \a blob, \a off rows off: kept when among the nearest (never when infinite).
        void offer(double off, int blob);
    };
    /// Split \a target with \a discs (its members' filled in) and the discs of all the
    /// \a candidates, or all but one, at least \a minAdded (see splitAndPair()); their lines are
    /// taken near \a targetRay, the ray of the target's centre. True on the first that pairs.
    bool trySplits(const ImageView& image, int camera, const SplitTarget& target,
                   const Ray& targetRay, std::span<DiscOnLine> discs, std::span<int> source,
                   const Candidates& candidates, std::size_t minAdded);
    /// Split \a target into \a discs (its members' first), pair each with blob \a source of
    /// \a camera (-1: none) and triangulate; true, with blobs and markers updated, when every
    /// pair passes stereo's checks.
    bool splitAndPair(const ImageView& image, int camera, const SplitTarget& target,
                      std::span<const DiscOnLine> discs, std::span<const int> source);
    /// An epipolar line in the other camera's image, and the ratio of the point's ranges from
    /// this camera and from the other (how much larger the other camera sees it).
    struct LineNear {
        PixelLine line;
        double scale;
    };
    /// The epipolar line in the other camera's image of blob \a blob of \a camera, near where
    /// its ray passes \a otherRay (a ray of the other camera).
    std::optional<LineNear> epipolarLineNear(int camera, int blob, const Ray& otherRay) const;

    MarkerPipelineConfig config_;
    int width_px_;
    int height_px_;
    std::array<BlobDetector, 2> detectors_;
    std::array<BoundedVector<Blob>, 2> blobs_;
    /// Per camera, where blobs are expected (raw px): see expect().
    std::array<BoundedVector<Vec2>, 2> expected_px_;
    StereoMatcher stereo_;
    BoundedVector<StereoMarker> markers_;
    BoundedVector<Vec3> points_rig_mm_;
    /// A point of the last frame (rig frame, mm), or one missing for a few frames
    /// (kMaxMissingFrames), for preferContinuingPairs() and carryHiddenMarkers(): where it was,
    /// where it is expected now (its last step carried on; for a missing point, where its
    /// neighbours' steps moved it), and for how many frames before it had continued a point
    /// (within StereoConfig::continuity_mm).
    struct LastPoint {
        Vec3 position_rig_mm = Vec3::Zero();
        Vec3 expected_rig_mm = Vec3::Zero();
        std::uint32_t age = 0;
        /// Frames in a row it was carried (carryHiddenMarkers()).
        std::uint32_t carried = 0;
        /// Frames it has been missing (0: a point of the last frame).
        std::uint32_t missing = 0;
        /// Its radius as its blobs tell it (mm), as markerSize(); 0 when unknown.
        double size_mm = 0.0;
    };
    /// The last frame's points in order of expected x, and this frame's while it is remembered
    /// (the two swap their storage).
    BoundedVector<LastPoint> last_;
    BoundedVector<LastPoint> current_;
    /// Per marker of this frame, during preferContinuingPairs(): how far it lies from where a
    /// point of the last frame was expected (mm), StereoConfig::continuity_mm at most.
    BoundedVector<double> continuation_mm_;
    /// Per blob of each camera, during preferContinuingPairs(): its centre's place in rectified
    /// coordinates (NaN where it has none).
    std::array<BoundedVector<Vec2>, 2> rectified_px_;
    /// Per point of the last frame, from noteContinuedPoints() on: whether a marker continues it.
    BoundedVector<std::uint8_t> lastContinued_;
    /// Per point of the last frame that a marker continues, its step to this frame (mm).
    BoundedVector<Vec3> lastStep_;
    /// Per marker of this frame, the point of the last frame it continues (-1: none).
    BoundedVector<int> continuesLast_;
    /// A blob without a partner and its ray (rig frame) from its centre now, for
    /// carryHiddenMarkers().
    struct UnpairedRay {
        int blob = -1;
        Ray ray;
    };
    std::array<BoundedVector<UnpairedRay>, 2> unpairedRays_;
    /// Points this near (mm) a hidden one share its motion (neighboursStep()): an object's
    /// markers lie within a few centimetres of each other. 100 mm took in other objects' steps
    /// (stress: 7 carried points 3-6 mm off, none with 40).
    static constexpr double kNeighbourhood_mm = 40.0;
    /// A point nothing continues stays among the last frame's points this many frames
    /// (LastPoint::missing): a marker hidden in both images for a few frames keeps its age when
    /// found again, and can be carried when next it hides in one image. Touching seeds 1 / 2,
    /// found of exact blobs: 97.10 / 97.99% without, 97.47 / 98.19% with 3, 97.49 / 98.24% with 5
    /// (false markers 31 / 63 -> 32 / 61), 97.57 / 98.26% with 10 (37 / 59).
    static constexpr std::uint32_t kMaxMissingFrames = 5;
    std::uint64_t carriedMarkers_ = 0;
    /// Markers found by splitWhereMarkersAreExpected().
    std::uint64_t markersSplitWhereExpected_ = 0;
    /// A pair gives way only to one continuing a point that had continued this many frames (0.2 s
    /// at 100 Hz): a ghost the correspondence made can last a few dozen frames (two markers on
    /// one line in both cameras, paired crosswise), and must not be carried on against the
    /// markers when the correspondence finds them again. With 10, the crowd (seed 2) kept such
    /// ghosts: 177 false markers against 163 without the step; with 20, 160; with 40 the touching
    /// scene lost most of the gain (69 against 35).
    static constexpr std::uint32_t kMinContinuedFrames = 20;
    std::uint64_t pairsForContinuity_ = 0;
    /// Per camera and blob, the index of the marker it is in (-1: none), during matchStereo().
    std::array<std::unique_ptr<int[]>, 2> markerOfBlob_;
    /// Splits on epipolar lines tried a frame at most: a blob's fit takes tens of microseconds,
    /// and a burst of reflections offers hundreds of blobs without a partner.
    static constexpr std::size_t kMaxSplitAttempts = 24;
    /// Markers splitWhereMarkersAreExpected() seeks a frame at most.
    static constexpr std::size_t kMaxSoughtMarkers = 64;
    /// An unpaired blob where a sought marker is expected is its own only when its radius is
    /// less than this times the marker's: larger, it holds another disc too.
    static constexpr double kOwnBlobSize = 1.1;
    /// How far (px) a disc hidden behind a nearer marker's may stick out of it, for
    /// nearerMarkerCovers(). Behind a round blob, a disc that stuck out further would show; the
    /// touching scene's hidden markers stick out 0.55 px at the median, 1.03 px at the 90th
    /// percentile (seeds 1-6), while a ghost of the crowd (two markers' images, paired crosswise
    /// for 20 frames and then left with one) stuck out 1.25 px and more.
    static constexpr double kHiddenDiscMargin_px = 1.0;
    /// preferContinuingPairs() exchanges blobs only when that brings the markers involved this
    /// much nearer (mm, summed) to where points of the last frame were expected: a marker
    /// continues its point within a few tenths of a millimetre at 100 Hz (touching scene: 0.02-0.6
    /// mm), so less is noise.
    static constexpr double kContinuityMargin_mm = 1.0;
    /// continuesLast_ of a marker splitWhereMarkersAreExpected() drops.
    static constexpr int kDroppedMarker = -2;
    std::size_t splitAttemptsLeft_ = 0;
    std::uint64_t splitAttemptsSkipped_ = 0;
    const char* error_ = nullptr;
};

} // namespace edgetrack
