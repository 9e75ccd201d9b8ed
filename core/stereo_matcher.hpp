// Stereo correspondence of blobs (paper section 3.1, eq. 1-4) and triangulation into 3D markers.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include "core/blob_detector.hpp"
#include "core/bounded_vector.hpp"
#include "core/correspondence.hpp"
#include "core/stereo_rig.hpp"

namespace edgetrack {

/// \brief Tuning of the stereo matcher; defaults suit the simulated desktop rig.
struct StereoConfig {
    /// sigma_ep of eq. 1: expected epipolar error in rectified pixels (calibration and centroids).
    double sigmaEpipolar_px = 0.8;
    /// Proximity is exactly zero beyond this many sigma_ep; it bounds the independent blocks.
    double epipolarBand_sigmas = 4.0;
    /// sigma_sim of eq. 4: expected difference of neighbourhood layouts (rectified px).
    double sigmaSimilarity_px = 20.0;
    /// S: side of the square region R around each blob whose neighbours are compared (eq. 2).
    double neighbourhood_px = 160.0;
    /// Working volume along the rectified depth axis; sets the admissible disparities.
    double minDepth_mm = 200.0;
    double maxDepth_mm = 2500.0;
    /// A correspondence needs at least this proximity G_ij.
    double minProximity = 1e-3;
    /// Triangulated rays may miss each other by at most this much.
    double maxRayGap_mm = 1.5;
    /// A marker must reproject within this distance of both its blobs.
    double maxReprojection_px = 1.5;
    /// The two blobs of one sphere tell the same marker radius: blob radius times range over
    /// the camera's pixelsPerRadian() at the blob (which holds the 1 / cos^3 growth of the image
    /// off the axis and the lens distortion). Real images add what this leaves out: the rim a
    /// threshold puts round a blurred edge (a fixed width in px, larger in a brighter image),
    /// gain, vignetting and focus that differ between the views, and flat markers that each
    /// camera sees at its own slant. So the size is a weight, not a test: G_ij of eq. 4 is
    /// multiplied by exp(-l^2 / 2 s^2), l the log of the two radii's ratio, s^2 = sizeSigma^2 +
    /// (sizeRimSigma_px / r0)^2 + (sizeRimSigma_px / r1)^2 for blob radii r0, r1 (px), so that
    /// of two pairs competing for a blob the one that is one sphere wins. 0 leaves size out
    /// (blobs without an area count as 0 too).
    double sizeSigma = 0.05;
    /// Uncertainty of a blob's radius from its rim (px): see sizeSigma.
    double sizeRimSigma_px = 0.2;
    /// Two markers on one epipolar line (one of them hidden from one camera, or both seen and
    /// paired crosswise) leave blobs with two partners that both triangulate, and the
    /// correspondence may take the wrong ones. A point within this distance (mm) of where a point
    /// of the last frame was expected (its last step carried on) continues it; pairs give way to
    /// other pairs of their blobs whose points continue points that had continued for 20 frames
    /// and lie nearer, by more than a millimetre summed, to where the last frame's points were
    /// expected, a point continuing none counting as this far off (MarkerPipeline). 0 turns this
    /// off (frames that do not follow each other), and with it the carrying of markers below.
    double continuity_mm = 3.0;
    /// A marker that had continued for 20 frames and is now hidden in one image inside another
    /// marker's blob, while the other camera still sees it apart, is carried on for at most this
    /// many frames in a row: its point taken on the seeing camera's ray, nearest where it is
    /// expected (StereoMarker::carried). 0 turns this off.
    std::uint32_t maxCarriedFrames = 20;
    /// A marker of the last frame that no pair continues now is sought where it is expected: a
    /// blob of several discs there (split, refused, or passed as one disc) is fitted again with
    /// a disc of its size starting there, and the disc, paired with its blob in the other image,
    /// is the marker when it triangulates within continuity_mm of where it was expected
    /// (MarkerPipeline, given the images). false turns this off (as does continuity_mm = 0).
    bool seekExpectedMarkers = true;
    /// Markers kept per frame; more are counted as overflow.
    std::size_t maxMarkers = 256;

    bool operator==(const StereoConfig&) const = default;
};

/// \brief A triangulated marker and the blobs it came from.
struct StereoMarker {
    int blob0 = -1;
    int blob1 = -1;
    /// Rig frame (mm).
    Vec3 position_rig_mm = Vec3::Zero();
    float rayGap_mm = 0.0f;
    float reprojection_px = 0.0f;
    /// Rectified row of blob0 minus that of blob1 (px): the epipolar error. Its spread over
    /// many markers tells how well the rig still fits the cameras.
    float epipolar_px = 0.0f;
    /// Seen apart by one camera only and hidden in the other image inside another marker's blob
    /// (MarkerPipeline carries it on): the point lies on the ray of the seeing camera's blob,
    /// nearest where the marker was in the frame before moved by its neighbours' step since. Its
    /// depth is that guess, not a measurement. The other camera's blob index is the
    /// covering blob's (-1 when detection refused that blob); rayGap_mm, reprojection_px and
    /// epipolar_px are 0.
    bool carried = false;
};

/// \brief A correspondence between element \a left of one set and \a right of the other.
struct IndexPair {
    int left = -1;
    int right = -1;
};

struct StereoCounters {
    std::uint64_t frames = 0;
    std::uint64_t blocks = 0;
    std::uint64_t largestBlock = 0;
    std::uint64_t blockOverflow = 0;
    std::uint64_t correspondences = 0;
    std::uint64_t rejectedRayGap = 0;
    std::uint64_t rejectedReprojection = 0;
    std::uint64_t unrectifiable = 0;
    std::uint64_t markerOverflow = 0;
};

/**
 * \brief Pairs blobs of the two cameras by the method of Scott and Longuet-Higgins with the paper's
 * proximity (epipolar term eq. 1 times neighbourhood-similarity term eq. 2-4), then triangulates.
 *
 * All storage is sized in the constructor from maxBlobsPerCamera and the configuration.
 */
class StereoMatcher {
public:
    StereoMatcher(const StereoRig& rig, const StereoConfig& config, std::size_t maxBlobsPerCamera);
    ~StereoMatcher();
    StereoMatcher(const StereoMatcher&) = delete;
    StereoMatcher& operator=(const StereoMatcher&) = delete;

    bool isValid() const { return valid_; }

    /**
     * \brief Use \a rig from the next frame on (a new rig calibration); the storage stays.
     * \return false, keeping the old rig, when \a rig is invalid or of another image size.
     */
    bool setRig(const StereoRig& rig);

    /// \brief The paper's matcher: blobs of both cameras in, triangulated markers out.
    void match(std::span<const Blob> blobs0, std::span<const Blob> blobs1,
               BoundedVectorView<StereoMarker>& out);

    /**
     * \brief The baseline of the paper's Figure 6: every pair within the epipolar band and the
     * disparity range becomes a marker (no uniqueness, no similarity, no ray checks).
     */
    void matchEpipolarOnly(std::span<const Blob> blobs0, std::span<const Blob> blobs1,
                           BoundedVectorView<StereoMarker>& out);

    /**
     * \brief Triangulate \a blob0 (index \a i in camera 0) and \a blob1 (\a j in camera 1) into
     * \a marker, with match()'s checks of the rays' gap and the reprojection (and its counters).
     * \return false when the pair fails them; \a marker is then unspecified.
     */
    bool triangulateBlobs(const Blob& blob0, int i, const Blob& blob1, int j, StereoMarker& marker);

    /**
     * \brief Blob \a i of camera \a camera as the last match() or matchEpipolarOnly() saw it.
     * \param ray its ray (rig frame); \param rectified_px its rectified position (px).
     * \return false when it could not be rectified or was not among that call's blobs.
     */
    bool preparedBlob(int camera, int i, Ray& ray, Vec2& rectified_px) const;

    /// \return whether \a disparity_px (rectified x of camera 0 minus camera 1) lies within
    /// \a margin_px of the disparities of the working volume (minDepth_mm to maxDepth_mm).
    bool admissibleDisparity(double disparity_px, double margin_px = 0.0) const {
        return disparity_px >= minDisparity_px_ - margin_px &&
               disparity_px <= maxDisparity_px_ + margin_px;
    }

    // The steps of match(), public so that tests can compare against a full-matrix solution.
    /// \brief Undistort, rectify and cast rays for both cameras' blobs.
    void prepare(std::span<const Blob> blobs0, std::span<const Blob> blobs1);
    /// \return G_ij of eq. 4 for prepared blobs (0 outside the band or the disparity range).
    double proximity(int i, int j) const;
    /// \brief SVD correspondence per block: fills \a pairs with (blob0, blob1) indices.
    void correspond(BoundedVectorView<IndexPair>& pairs);

    const StereoCounters& counters() const { return counters_; }
    const StereoConfig& config() const { return config_; }
    const StereoRig& rig() const { return rig_; }

private:
    struct Prepared;

    void disparityRange();
    bool inBand(int i, int j) const;
    double neighbourhoodDistance(int i, int j) const;
    void collectNeighbours(int camera);
    void triangulatePair(int i, int j, BoundedVectorView<StereoMarker>& out);
    /// Triangulate two rays into \a marker's position, ray gap and reprojection, with the checks.
    bool checkedMarker(const Ray& ray0, const Ray& ray1, const Vec2& pixel0, const Vec2& pixel1,
                       StereoMarker& marker);
    /// The exponent of the size weight of sizeSigma for prepared blobs \a i and \a j (0 where a
    /// size is unknown).
    double sizeExponent(int i, int j) const;

    StereoRig rig_;
    StereoConfig config_;
    std::size_t maxBlobs_;
    bool valid_ = false;
    double minDisparity_px_ = 0.0;
    double maxDisparity_px_ = 0.0;
    double band_px_ = 0.0;
    StereoCounters counters_{};

    std::unique_ptr<Prepared> prepared_;
    BipartiteBlocks blocks_;
    BlockSolver solver_;
    BoundedVector<IndexPair> pairs_;
};

} // namespace edgetrack
