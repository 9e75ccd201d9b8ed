// Blob detection in 8-bit IR frames: NEON threshold scan, run-based connected components, moments.
#pragma once

#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "core/bounded_vector.hpp"
#include "core/disjoint_sets.hpp"
#include "core/geometry.hpp"

namespace edgetrack {

/// \brief Thresholds of the blob detector; defaults suit the simulated desktop rig.
struct BlobDetectorConfig {
    /// Pixels at or above this level (DN) belong to blobs. Background is ~10 DN, markers saturate.
    std::uint8_t threshold = 60;
    /// Blobs with fewer pixels are noise or specks (a 6 mm marker at 1 m is ~25 px).
    int minArea_px = 6;
    /// Blobs with more pixels are lamps or large reflections, not markers.
    int maxArea_px = 3000;
    /// Largest ratio of the blob's principal axes; two touching markers measure 1.4 to 2.2.
    double maxElongation = 1.35;
    /// Smallest share of the moment ellipse that the blob fills; merged markers leave gaps.
    double minFill = 0.75;
    /// One marker's image is an ellipse, not always a disc: a sphere theta off the optical axis
    /// images 1 / cos(theta) longer along the radius (1.15 at 30 degrees, 2 at 60), a flat
    /// marker 1 / cos of the slant it is seen at, and the lens distortion stretches either way.
    /// A blob that fails the tests above or below but whose whole outline one ellipse fits
    /// (as well as a split part's circle must fit its own) is one marker up to this
    /// elongation; beyond it, a streak (a lit edge, a cable) is no marker.
    double maxMarkerElongation = 2.0;
    /// A blob that fails those two tests is split into the discs it is made of (up to five),
    /// each centred by a circle fitted to its own part of the outline (see BlobDetector).
    bool splitMerged = true;
    /// Blobs kept per image; more are counted as overflow.
    std::size_t maxBlobs = 256;
    /// When more blobs pass than maxBlobs, those within this distance (px) of an expected centre
    /// (where a tracked marker was a frame ago) are kept first, then the roundest: a burst of
    /// reflections then costs the stray blobs, not the markers being tracked.
    double keepNear_px = 12.0;
    /// Connected-component labels per image; a flood of specks beyond this is counted, not stored.
    std::size_t maxLabels = 4096;

    bool operator==(const BlobDetectorConfig&) const = default;
};

/// \brief A detected blob: centre in raw pixels of its camera, with (0, 0) the top-left pixel.
struct Blob {
    /// Intensity-weighted centre (px).
    Vec2 centre_px = Vec2::Zero();
    /// Number of pixels at or above the threshold.
    float area_px = 0.0f;
    /// Ratio of principal axes of the pixel distribution (1 for a disc).
    float elongation = 1.0f;
    std::uint16_t left = 0, top = 0, right = 0, bottom = 0;
    std::uint8_t peak = 0;
    /// Part of a blob of touching discs: its centre is the fit of a circle to its own
    /// part of the outline, and left..bottom are those of the whole blob.
    bool split = false;
    /// A disc cut by an edge in front of it (a hand, the object's body): its centre is that of
    /// the circle through its visible arc, and left..bottom are those of the visible part.
    bool cut = false;
    /// For a split part or a cut disc, the RMS distance of its outline points from the fitted
    /// circle (px).
    float fitRms_px = 0.0f;

    /// \return the radius (px) of a disc of the blob's area; a split part's and a cut disc's area
    /// is that of its fitted circle. 0 for a blob of no area.
    double discRadius_px() const {
        return std::sqrt(static_cast<double>(area_px) / 3.14159265358979323846);
    }
};

/// \return whether the bounds of \a blob (with half a pixel about them) hold \a pixel_px.
inline bool boundsHold(const Blob& blob, const Vec2& pixel_px) {
    return pixel_px.x() >= blob.left - 0.5 && pixel_px.x() <= blob.right + 0.5 &&
           pixel_px.y() >= blob.top - 0.5 && pixel_px.y() <= blob.bottom + 0.5;
}

/// \return whether \a a and \a b are parts of one blob split into discs (they keep its bounds).
inline bool partsOfOneBlob(const Blob& a, const Blob& b) {
    return a.split && b.split && a.left == b.left && a.top == b.top && a.right == b.right &&
           a.bottom == b.bottom;
}

/// \brief A straight line in raw pixels of one camera: point_px + t * direction, direction a unit
/// vector. Over the few pixels of a blob, an epipolar line curved by lens distortion is straight.
struct PixelLine {
    Vec2 point_px = Vec2::Zero();
    Vec2 direction = Vec2::UnitX();
};

/// \brief A disc of a blob for BlobDetector::splitOnLines(): where its centre lies, and its size.
struct DiscOnLine {
    /// Its centre lies on this line (raw px).
    PixelLine line{};
    /// A first guess of its centre (raw px), when known is set.
    Vec2 start_px = Vec2::Zero();
    /// Its expected radius (px).
    double radius_px = 0.0;
    /// start_px is a fair guess (a disc the detector split off); else the whole blob is scanned.
    bool known = true;
    /// A disc that stays where start_px puts it (no line is known for it): it only explains its
    /// part of the outline.
    bool fixed = false;
    /// A disc whose centre may move any way from start_px (line is not used): where a marker
    /// tracked in the frames before is expected, with no line of the other camera to hold it.
    bool free = false;
};

/// \brief Per-detector counters for the status view (cumulative).
struct BlobCounters {
    std::uint64_t images = 0;
    std::uint64_t accepted = 0;
    std::uint64_t rejectedSmall = 0;
    std::uint64_t rejectedLarge = 0;
    std::uint64_t rejectedNotRound = 0;
    std::uint64_t splitBlobs = 0;   ///< blobs of touching discs split into their discs
    std::uint64_t splitParts = 0;   ///< discs those gave
    std::uint64_t splitRefused = 0; ///< blobs not round that could not be split with confidence
    std::uint64_t cutDiscs = 0;     ///< discs cut by an edge, centred by their visible arc
    /// Blobs not round or perhaps merged whose outline one ellipse fits: one marker each.
    std::uint64_t ellipses = 0;
    /// Blobs split again, with at least one disc placed, on the epipolar lines of the other
    /// camera's blobs (splitOnLines() without free discs).
    std::uint64_t splitOnLines = 0;
    std::uint64_t blobOverflow = 0;
    std::uint64_t labelOverflow = 0;
};

/**
 * \brief Finds bright round blobs in one camera's images.
 *
 * One pass over the image: NEON compares 16 pixels at a time with the threshold and skips dark
 * stretches, which is nearly all of an IR frame; bright stretches become runs, runs that touch
 * (8-connected) join through union-find, and each component accumulates its moments as it grows.
 * All storage is sized in the constructor from the configuration and the image width.
 */
class BlobDetector {
public:
    BlobDetector(const BlobDetectorConfig& config, int width_px, int height_px);
    ~BlobDetector();
    BlobDetector(const BlobDetector&) = delete;
    BlobDetector& operator=(const BlobDetector&) = delete;

    bool isValid() const { return valid_; }

    /**
     * \brief Detect the blobs of one image.
     * \param pixels first row; rows are \a stride_bytes apart and width_px wide.
     * \param out cleared, then filled with accepted blobs in the order their top rows appear.
     * \param expected_px where blobs are expected (raw pixels, e.g. tracked markers a frame ago):
     * when more blobs pass than out holds, those near one are kept first (keepNear_px).
     */
    void detect(const std::uint8_t* pixels, int stride_bytes, BoundedVectorView<Blob>& out,
                std::span<const Vec2> expected_px = {});

    /**
     * \brief Split \a blob, one of the last detect()'s, into the discs \a discs describe.
     *
     * Two discs far over each other in this image may lie apart in the other camera's: there each
     * has its own blob, whose epipolar line runs through this blob. A centre on a known line has
     * one unknown instead of two, so the discs are found even where the blob's outline shows no
     * neck or shoulder. The outline is that of the blob's own pixels in \a pixels. Each disc not
     * fixed is placed on its line by a scan over the blob, then fitted (place and radius) to the
     * outline points on its circle and outside the others. It is placed when it rests on them:
     * a fit within kSplitFitRms_px, a place on its line known within kLinePlaceError_px
     * (standard error), a radius within a third of the expected one. Each disc is judged on its
     * own; the discs need not explain the whole outline (a blob of many discs may hold one whose
     * line is not given). A free disc (DiscOnLine::free) is fitted from its start in both
     * directions and placed when both are known within kLinePlaceError_px and it moved less than
     * half its radius.
     * \param pixels the image of the last detect(), rows \a stride_bytes apart.
     * \param discs two to kMaxLineDiscs discs (or one free disc); \param parts receives them, in
     * that order, and \param placed whether each was placed (a fixed disc never is; the parts of
     * those not placed are unspecified). \return how many discs were placed.
     */
    std::size_t splitOnLines(const std::uint8_t* pixels, int stride_bytes, const Blob& blob,
                             std::span<const DiscOnLine> discs, std::span<Blob> parts,
                             std::span<bool> placed);
    /// Discs splitOnLines() fits at most: the touching renders show blobs of eight markers, of
    /// which detection split five at most.
    static constexpr std::size_t kMaxLineDiscs = 8;

    /// \return the blobs of the last detect() that were not round and could not be split (up to
    /// maxBlobs): bounds, intensity-weighted centre and pixel count, for splitOnLines().
    std::span<const Blob> refused() const { return refused_.span(); }

    const BlobCounters& counters() const { return counters_; }
    const BlobDetectorConfig& config() const { return config_; }

private:
    struct Moments;
    struct Run;

    int newLabel();
    int findRoot(int label);
    int unite(int a, int b);
    void closeRun(int y, int x0, int x1, const std::uint8_t* row);
    void finishRow();
    void emitBlobs(const std::uint8_t* pixels, int stride_bytes, BoundedVectorView<Blob>& out,
                   std::span<const Vec2> expected_px);
    /// Split the blob of \a m (not round, or perhaps merged) into its discs, or take it whole as
    /// one marker whose image is an ellipse: of the two, the one whose outline fits better. One
    /// ellipse (5 parameters) explains one marker's outline to the outline's own noise, and
    /// two discs far over each other only to their notches; two circles (6) explain the latter.
    /// So the blob stays whole when one ellipse of at most maxMarkerElongation fits its outline
    /// within kSplitFitRms_px and no worse than the split's circles fit their own arcs.
    /// \return false when it is neither (refused).
    bool splitOrEllipse(const Moments& m, const std::uint8_t* pixels, int stride_bytes,
                        std::uint32_t order, std::size_t minParts);
    /// Split a blob that is not round into the discs it is made of (up to kMaxSplitParts), as
    /// candidates (those that can be centred with confidence), or centre it as one disc cut by an
    /// edge; false when neither, or when fewer than \a minParts discs can be centred. Its outline
    /// is the one traceOutline() traced last (\a edges points in splitEdge_, pixels in
    /// splitMask_).
    bool splitIntoDiscs(const Moments& m, std::size_t edges, std::uint32_t order,
                        std::size_t minParts);
    /// The outline of the component through pixel (\a seedX, \a seedY) inside the bounds
    /// \a left..\a bottom: its pixels into splitMask_ and its outline points into splitEdge_, on a
    /// grid of the bounds with a frame of one pixel. \return the number of outline points; 0 when
    /// the bounds are too large or touch the image's border.
    std::size_t traceOutline(int left, int top, int right, int bottom, int seedX, int seedY,
                             const std::uint8_t* pixels, int stride_bytes);
    bool addCandidate(const Blob& blob, std::uint32_t order);
    /// A blob with the bounds and peak of component \a m, to be given its centre and shape.
    static Blob framedBlob(const Moments& m);
    struct Shape {
        /// Ratio of the principal axes of the pixel distribution (1 for a disc).
        double elongation;
        /// Share of the moment ellipse the pixels fill (1 for a disc).
        double fill;
    };
    static Shape shapeOf(const Moments& m);
    /// Component \a m as one blob, centred on its intensity-weighted mean.
    static Blob roundBlob(const Moments& m);

    BlobDetectorConfig config_;
    int width_;
    int height_;
    bool valid_ = false;
    BlobCounters counters_{};

    std::unique_ptr<Moments[]> moments_;
    DisjointSets labels_{0};
    bool labelsExhausted_ = false;

    /// Blobs that passed the tests, before the choice of which fit in the output.
    struct Candidate {
        Blob blob;
        /// Order of the choice: 0 for a blob near an expected centre, then its distance (px);
        /// 1 for any other, then its elongation.
        int group = 1;
        double key = 0.0;
        std::uint32_t order = 0;
    };
    BoundedVector<Candidate> candidates_;
    /// Labels of this image's blobs that are not round, to be split once the round ones are known.
    BoundedVector<std::uint32_t> notRound_;
    /// Round enough to pass as one disc, yet a little long: maybe two discs over each other.
    BoundedVector<std::uint32_t> maybeMerged_;
    /// This image's blobs refused as not round and not splittable (see refused()).
    BoundedVector<Blob> refused_;
    /// Scratch of splitIntoDiscs, for a bounding box of at most kSplitSide x kSplitSide pixels.
    static constexpr int kSplitSide = 128;
    /// Discs a blob is split into at most: a marker's image may touch several others, and a
    /// chain of them is one blob. A large oval reflection shows six or more peaks along its
    /// length, and circles fit pieces of its ends: such a blob stays refused.
    static constexpr std::size_t kMaxSplitParts = 5;
    /// Candidates' order: a label's blob, then its split parts.
    static constexpr std::uint32_t kOrderStride = kMaxSplitParts + 1;
    /// A split part's circle must fit its outline points this well (px RMS).
    static constexpr double kSplitFitRms_px = 0.3;
    /// A part whose own outline covers less than about half its circle is kept only when that
    /// arc covers at least a third of it (the points' mean unit vector from the centre is
    /// shorter than this) and fits it within kShortArcFitRms_px.
    static constexpr double kShortArcShare = 0.85;
    static constexpr double kShortArcFitRms_px = 0.15;
    /// An outline point this far inside a cut disc's circle (px) lies on the cut, not the arc.
    static constexpr double kCutInside_px = 0.4;
    /// A blob round enough to pass as one disc but longer than this may be two discs far over
    /// each other (a disc's own pixels measure 1.00 to 1.05): it is split when two discs fit
    /// its outline, and stays one blob otherwise.
    static constexpr double kMaybeMergedElongation = 1.08;
    /// Likewise a blob that passes but fills less of its moment ellipse than a disc (1.0; a
    /// disc of radius 2.5 px or more measures 0.95 or more): three or four discs in a cluster are
    /// round as a whole. Blobs of the smallest discs (0.89) fit no two circles and stay one.
    static constexpr double kMaybeMergedFill = 0.9;
    std::unique_ptr<std::uint8_t[]> splitMask_;
    std::unique_ptr<std::uint16_t[]> splitDistance_;
    std::unique_ptr<std::uint16_t[]> splitStack_;
    std::unique_ptr<Vec2[]> splitEdge_;
    /// splitOnLines scans a line at kLineSteps places, two lines together at kPairSteps places
    /// each, scoring at most kLinePoints outline points (more are sampled); its scratch holds the
    /// points' residuals from each place scanned and from the circles not scanned.
    static constexpr int kLineSteps = 48;
    static constexpr int kPairSteps = 24;
    static constexpr std::size_t kLinePoints = 256;
    std::unique_ptr<float[]> lineResidual_;
    /// What traceOutline traced last, in splitEdge_: its tracedEdges_ outline points.
    struct Traced {
        const std::uint8_t* pixels = nullptr;
        int left = 0, top = 0, right = 0, bottom = 0, seedX = 0, seedY = 0;
        bool operator==(const Traced&) const = default;
    };
    Traced traced_{};
    std::size_t tracedEdges_ = 0;
    /// splitOnLines holds a disc's radius to its expected size with this weight, against 1 for each
    /// outline point: about the (0.2 px) scatter of the points over a (0.1 px) trust in the size.
    static constexpr double kRadiusPrior = 4.0;
    /// A disc placed by splitOnLines is kept when its place on its line has a standard error of
    /// at most kLinePlaceError_px, from its points' scatter, taken as no less than kLineNoise_px.
    static constexpr double kLinePlaceError_px = 0.15;
    static constexpr double kLineNoise_px = 0.1;
    /// A free disc may be cut by an edge in front of it: an outline point more than this (px)
    /// inside its circle is no point of its arc (1 px for a disc on a line, whose place the line
    /// holds). Touching seeds 1 / 2, found of exact blobs: 98.68 / 98.56% with 1 px, 98.84 / 98.60%
    /// with 0.6, 98.81 / 98.59% with 0.4 (kCutInside_px).
    static constexpr double kFreeDiscInside_px = 0.6;
    /// A free disc is placed only within this share of its radius of where it started: one that
    /// went further took another disc's arc.
    static constexpr double kFreeDiscReach = 0.3;

    std::unique_ptr<Run[]> previousRuns_;
    std::unique_ptr<Run[]> currentRuns_;
    int previousCount_ = 0;
    /// First previous run that can still touch a run of the current row.
    int previousScan_ = 0;
    int currentCount_ = 0;
};

} // namespace edgetrack
