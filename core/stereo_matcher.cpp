// Stereo correspondence of blobs (paper section 3.1, eq. 1-4) and triangulation into 3D markers.
#include "core/stereo_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "core/simd/neon.hpp"
#include "core/triangulation.hpp"

namespace edgetrack {

namespace {
constexpr std::size_t idx(int i) {
    return static_cast<std::size_t>(i);
}
constexpr std::size_t kMaxNeighbours = 32;

// A blob's neighbourhood in region R as separate x and y arrays of offsets (rectified px), padded
// to whole NEON vectors with far-away points that never win a minimum.
struct Neighbourhood {
    static constexpr float kFar = 1e9f;
    std::size_t count = 0;
    // Room beyond the list (one slot, rounded up to a whole vector): the collecting sweep writes
    // every candidate at the end and only counts the ones inside the region, which keeps its
    // unpredictable test off the branch predictor.
    alignas(16) float x[kMaxNeighbours + 4];
    alignas(16) float y[kMaxNeighbours + 4];

    void clear() { count = 0; }
    void add(const Vec2& offset) {
        if (count == kMaxNeighbours)
            return; // a crowded region keeps its first 32
        x[count] = static_cast<float>(offset.x());
        y[count] = static_cast<float>(offset.y());
        ++count;
    }
    void pad() {
        for (std::size_t i = count; i % 4 != 0; ++i)
            x[i] = y[i] = kFar;
    }
    std::size_t paddedCount() const { return (count + 3) & ~std::size_t{3}; }
};

// Eq. 2: mean over the smaller set of the distance to the closest point of the larger set.
// Four points of the smaller set are handled at once against each point of the larger set, so
// there is no horizontal minimum at all.
double meanClosestDistance(const Neighbourhood& smaller, const Neighbourhood& larger) {
    float sum = 0.0f;
    for (std::size_t k = 0; k < smaller.count; k += 4) {
        const float32x4_t qx = vld1q_f32(smaller.x + k);
        const float32x4_t qy = vld1q_f32(smaller.y + k);
        float32x4_t closest = vdupq_n_f32(Neighbourhood::kFar);
        for (std::size_t i = 0; i < larger.count; ++i) {
            const float32x4_t dx = vsubq_f32(vdupq_n_f32(larger.x[i]), qx);
            const float32x4_t dy = vsubq_f32(vdupq_n_f32(larger.y[i]), qy);
            closest = vminq_f32(closest, vmlaq_f32(vmulq_f32(dx, dx), dy, dy));
        }
        // Padding lanes of the smaller set (beyond its count) must not count.
        alignas(16) float squared[4];
        vst1q_f32(squared, closest);
        const std::size_t valid = std::min<std::size_t>(4, smaller.count - k);
        for (std::size_t lane = 0; lane < valid; ++lane)
            sum += std::sqrt(squared[lane]);
    }
    return static_cast<double>(sum) / static_cast<double>(smaller.count);
}
} // namespace

// Per-blob data of one frame, for both cameras, in storage sized once.
struct StereoMatcher::Prepared {
    explicit Prepared(std::size_t maxBlobs) {
        for (int c = 0; c < 2; ++c) {
            rectified[c] = std::make_unique<Vec2[]>(maxBlobs);
            pixel[c] = std::make_unique<Vec2[]>(maxBlobs);
            radius[c] = std::make_unique<double[]>(maxBlobs);
            logAngularRadius[c] = std::make_unique<double[]>(maxBlobs);
            rimVariance[c] = std::make_unique<double[]>(maxBlobs);
            rays[c] = std::make_unique<Ray[]>(maxBlobs);
            valid[c] = std::make_unique<bool[]>(maxBlobs);
            neighbours[c] = std::make_unique<Neighbourhood[]>(maxBlobs);
            byRow[c] = std::make_unique<int[]>(maxBlobs);
            sortedX[c] = std::make_unique<double[]>(maxBlobs);
            sortedY[c] = std::make_unique<double[]>(maxBlobs);
        }
        columnOf = std::make_unique<int[]>(maxBlobs);
        gridX = std::make_unique<double[]>(maxBlobs);
        gridY = std::make_unique<double[]>(maxBlobs);
        gridRank = std::make_unique<int[]>(maxBlobs);
    }
    std::size_t count[2] = {0, 0};
    std::unique_ptr<Vec2[]> rectified[2];
    std::unique_ptr<Vec2[]> pixel[2];
    /// Radius of a disc of the blob's area (px).
    std::unique_ptr<double[]> radius[2];
    /// Log of the angular radius (rad) of the sphere whose image that is (radius over
    /// pixelsPerRadian()), and the variance its rim adds, (sizeRimSigma_px / radius)^2; a blob
    /// without an area has a negative variance (no size).
    std::unique_ptr<double[]> logAngularRadius[2];
    std::unique_ptr<double[]> rimVariance[2];
    std::unique_ptr<Ray[]> rays[2];
    std::unique_ptr<bool[]> valid[2];
    /// Offsets of the other blobs of the same camera inside region R (rectified px).
    std::unique_ptr<Neighbourhood[]> neighbours[2];
    /// Valid blobs sorted by rectified y, so that bands and regions are found by bisection.
    std::unique_ptr<int[]> byRow[2];
    /// Rectified x and y in byRow order, side by side for the scans.
    std::unique_ptr<double[]> sortedX[2];
    std::unique_ptr<double[]> sortedY[2];
    std::size_t validCount[2] = {0, 0};

    /// Region R's columns (filled for one camera at a time): the column of each blob in byRow
    /// order, and the blobs column after column, each column in row order.
    static constexpr int kMaxColumns = 64;
    std::unique_ptr<int[]> columnOf;
    int columnStart[kMaxColumns + 1] = {};
    int columnNext[kMaxColumns] = {};
    std::unique_ptr<double[]> gridX, gridY;
    /// Position in byRow order of each blob in the columns.
    std::unique_ptr<int[]> gridRank;

    double rowOf(int camera, int sorted) const { return sortedY[camera][idx(sorted)]; }
    /// First position in byRow[camera] whose rectified y is >= \a y.
    int lowerBound(int camera, double y) const {
        int low = 0, high = static_cast<int>(validCount[camera]);
        while (low < high) {
            const int mid = (low + high) / 2;
            if (rowOf(camera, mid) < y)
                low = mid + 1;
            else
                high = mid;
        }
        return low;
    }
};

StereoMatcher::StereoMatcher(const StereoRig& rig, const StereoConfig& config,
                             std::size_t maxBlobsPerCamera)
    : rig_(rig)
    , config_(config)
    , maxBlobs_(maxBlobsPerCamera)
    , prepared_(std::make_unique<Prepared>(maxBlobsPerCamera))
    , blocks_(maxBlobsPerCamera, maxBlobsPerCamera)
    , pairs_(maxBlobsPerCamera) {
    valid_ = rig.isValid() && config.sigmaEpipolar_px > 0.0 && config.sigmaSimilarity_px > 0.0 &&
             config.minDepth_mm > 0.0 && config.maxDepth_mm > config.minDepth_mm &&
             maxBlobsPerCamera > 0;
    disparityRange();
    band_px_ = config.epipolarBand_sigmas * config.sigmaEpipolar_px;
}

void StereoMatcher::disparityRange() {
    const double focalBaseline = rig_.rectifiedFocal_px() * rig_.baseline_mm();
    minDisparity_px_ = focalBaseline / config_.maxDepth_mm;
    maxDisparity_px_ = focalBaseline / config_.minDepth_mm;
}

bool StereoMatcher::setRig(const StereoRig& rig) {
    for (int c = 0; c < 2; ++c)
        if (rig.camera(c).intrinsics().width_px != rig_.camera(c).intrinsics().width_px ||
            rig.camera(c).intrinsics().height_px != rig_.camera(c).intrinsics().height_px)
            return false;
    if (!rig.isValid())
        return false;
    rig_ = rig;
    disparityRange();
    return true;
}

StereoMatcher::~StereoMatcher() = default;

void StereoMatcher::prepare(std::span<const Blob> blobs0, std::span<const Blob> blobs1) {
    const std::span<const Blob> blobs[2] = {blobs0, blobs1};
    for (int c = 0; c < 2; ++c) {
        Prepared& p = *prepared_;
        p.count[c] = std::min(blobs[c].size(), maxBlobs_);
        for (std::size_t i = 0; i < p.count[c]; ++i) {
            p.pixel[c][i] = blobs[c][i].centre_px;
            p.radius[c][i] = blobs[c][i].discRadius_px();
            p.logAngularRadius[c][i] = 0.0;
            p.rimVariance[c][i] = -1.0;
            p.valid[c][i] = false;
            const std::optional<Ray> ray = rig_.camera(c).ray(blobs[c][i].centre_px);
            if (!ray) {
                ++counters_.unrectifiable;
                continue;
            }
            const std::optional<Vec2> rectified = rig_.rectifyDirection(ray->direction_rig);
            if (!rectified) {
                ++counters_.unrectifiable;
                continue;
            }
            p.rays[c][i] = *ray;
            p.rectified[c][i] = *rectified;
            p.valid[c][i] = true;
            if (config_.sizeSigma > 0.0 && p.radius[c][i] > 0.0) {
                const double pixelsPerRadian = rig_.camera(c).pixelsPerRadian(ray->direction_rig);
                if (pixelsPerRadian > 0.0) {
                    p.logAngularRadius[c][i] = std::log(p.radius[c][i] / pixelsPerRadian);
                    const double rim = config_.sizeRimSigma_px / p.radius[c][i];
                    p.rimVariance[c][i] = rim * rim;
                }
            }
        }
        std::size_t valid = 0;
        for (std::size_t i = 0; i < p.count[c]; ++i)
            if (p.valid[c][i])
                p.byRow[c][valid++] = static_cast<int>(i);
        p.validCount[c] = valid;
        const Vec2* rectifiedOf = p.rectified[c].get();
        std::sort(p.byRow[c].get(), p.byRow[c].get() + valid, [rectifiedOf](int a, int b) {
            return rectifiedOf[idx(a)].y() < rectifiedOf[idx(b)].y();
        });
        for (std::size_t k = 0; k < valid; ++k) {
            p.sortedX[c][k] = rectifiedOf[idx(p.byRow[c][k])].x();
            p.sortedY[c][k] = rectifiedOf[idx(p.byRow[c][k])].y();
        }
        collectNeighbours(c);
    }
}

void StereoMatcher::collectNeighbours(int camera) {
    // Region R: the blobs within half of S in x and y. The blobs are dealt into columns at least
    // that wide, each in row order, so a blob's region lies in its own column and the two beside
    // it; in each, the stretch of rows within reach only moves down as the blobs do. Scanning
    // three columns instead of whole rows skips the blobs that are far to the side.
    Prepared& p = *prepared_;
    const double half = 0.5 * config_.neighbourhood_px;
    const int valid = static_cast<int>(p.validCount[camera]);
    for (std::size_t i = 0; i < p.count[camera]; ++i)
        p.neighbours[camera][i].clear();
    if (valid == 0)
        return;
    const double* xs = p.sortedX[camera].get();
    const double* ys = p.sortedY[camera].get();
    const auto [minX, maxX] = std::minmax_element(xs, xs + valid);
    const double columnWidth =
        std::max(half, (*maxX - *minX) / static_cast<double>(Prepared::kMaxColumns));
    const int columns =
        std::min(Prepared::kMaxColumns, static_cast<int>((*maxX - *minX) / columnWidth) + 1);
    int* columnOf = p.columnOf.get();
    int* start = p.columnStart;
    std::fill(start, start + columns + 1, 0);
    for (int s = 0; s < valid; ++s) {
        columnOf[s] = std::min(columns - 1, static_cast<int>((xs[s] - *minX) / columnWidth));
        ++start[columnOf[s] + 1];
    }
    for (int c = 0; c < columns; ++c)
        start[c + 1] += start[c];
    int* next = p.columnNext;
    std::copy(start, start + columns, next);
    double* gridX = p.gridX.get();
    double* gridY = p.gridY.get();
    int* gridRank = p.gridRank.get();
    for (int s = 0; s < valid; ++s) {
        const int k = next[columnOf[s]]++;
        gridX[k] = xs[s];
        gridY[k] = ys[s];
        gridRank[k] = s;
    }
    // Region R is symmetric, so each pair is found once, from the blob higher in the image, and
    // entered in both lists. next[c] now moves on to column c's first blob below the current one.
    std::copy(start, start + columns, next);
    Neighbourhood* lists = p.neighbours[camera].get();
    const int* byRow = p.byRow[camera].get();
    for (int s = 0; s < valid; ++s) {
        Neighbourhood& list = lists[idx(byRow[s])];
        const double x = xs[s], y = ys[s];
        for (int c = std::max(0, columnOf[s] - 1); c <= std::min(columns - 1, columnOf[s] + 1);
             ++c) {
            int first = next[c];
            while (first < start[c + 1] && gridRank[first] <= s)
                ++first;
            next[c] = first;
            for (int k = first; k < start[c + 1] && gridY[k] - y < half; ++k) {
                const auto dx = static_cast<float>(gridX[k] - x);
                const auto dy = static_cast<float>(gridY[k] - y);
                const auto inside = static_cast<std::size_t>(std::abs(gridX[k] - x) < half);
                // Every candidate is written past the end and only counted when inside, which
                // keeps this unpredictable test off the branch predictor; a full list keeps
                // counting (to be seen as full below) but writes into its spare slot.
                Neighbourhood& other = lists[idx(byRow[gridRank[k]])];
                const std::size_t slot = std::min(list.count, kMaxNeighbours);
                list.x[slot] = dx;
                list.y[slot] = dy;
                list.count += inside;
                const std::size_t otherSlot = std::min(other.count, kMaxNeighbours);
                other.x[otherSlot] = -dx;
                other.y[otherSlot] = -dy;
                other.count += inside;
            }
        }
    }

    for (int s = 0; s < valid; ++s) {
        Neighbourhood& list = lists[idx(byRow[s])];
        const double x = xs[s], y = ys[s];
        if (list.count > kMaxNeighbours) {
            // More than the list holds: keep the nearest rows, scanning outward from the blob's.
            list.clear();
            int up = s - 1, down = s + 1;
            while (list.count < kMaxNeighbours) {
                const double dyUp = up >= 0 ? y - ys[up] : std::numeric_limits<double>::infinity();
                const double dyDown =
                    down < valid ? ys[down] - y : std::numeric_limits<double>::infinity();
                if (std::min(dyUp, dyDown) >= half)
                    break;
                const int k = dyUp <= dyDown ? up-- : down++;
                const double dx = xs[k] - x;
                if (std::abs(dx) < half)
                    list.add({dx, ys[k] - y});
            }
        }
        list.pad();
    }
}

bool StereoMatcher::inBand(int i, int j) const {
    const Prepared& p = *prepared_;
    if (!p.valid[0][idx(i)] || !p.valid[1][idx(j)])
        return false;
    const Vec2& a = p.rectified[0][idx(i)];
    const Vec2& b = p.rectified[1][idx(j)];
    const double disparity = a.x() - b.x();
    return std::abs(a.y() - b.y()) <= band_px_ && disparity >= minDisparity_px_ &&
           disparity <= maxDisparity_px_;
}

double StereoMatcher::neighbourhoodDistance(int i, int j) const {
    // Both neighbourhoods are translated so that the candidate pair sits at the origin.
    const Neighbourhood& a = prepared_->neighbours[0][idx(i)];
    const Neighbourhood& b = prepared_->neighbours[1][idx(j)];
    const Neighbourhood& smaller = a.count <= b.count ? a : b;
    const Neighbourhood& larger = a.count <= b.count ? b : a;
    if (smaller.count == 0)
        return 0.0;
    return meanClosestDistance(smaller, larger);
}

double StereoMatcher::sizeExponent(int i, int j) const {
    const Prepared& p = *prepared_;
    const double rim0 = p.rimVariance[0][idx(i)], rim1 = p.rimVariance[1][idx(j)];
    if (rim0 < 0.0 || rim1 < 0.0)
        return 0.0;
    // The point's ranges from both centres, from its rectified coordinates: depth f B / d along
    // the rectified axis, and each camera's rectified ray length per unit depth.
    const Vec2& a = p.rectified[0][idx(i)];
    const Vec2& b = p.rectified[1][idx(j)];
    const double f2 = rig_.rectifiedFocal_px() * rig_.rectifiedFocal_px();
    // Half the log of x, the ratio of the squared ray lengths, by atanh's series: ln x =
    // 2 (y + y^3 / 3 + ...) with y = (x - 1) / (x + 1). For the two rays of one point x stays
    // within 2.5 of 1 even on a wide converging rig (the rays differ by the disparity alone),
    // where the terms left out are under 0.003 (a pair's log is weighed at 0.05).
    const double r0 = a.squaredNorm() + f2, r1 = b.squaredNorm() + f2;
    const double y = (r0 - r1) / (r0 + r1);
    const double logRatio =
        p.logAngularRadius[0][idx(i)] - p.logAngularRadius[1][idx(j)] + y * (1.0 + y * y / 3.0);
    const double variance = config_.sizeSigma * config_.sizeSigma + rim0 + rim1;
    return -logRatio * logRatio / (2.0 * variance);
}

double StereoMatcher::proximity(int i, int j) const {
    if (!inBand(i, j))
        return 0.0;
    // Eq. 4: g_epi (eq. 1) times the neighbourhood term, as one exponential, times the weight of
    // the two blobs' sizes.
    const double dy = prepared_->rectified[0][idx(i)].y() - prepared_->rectified[1][idx(j)].y();
    const double d = neighbourhoodDistance(i, j);
    return std::exp(-dy * dy / (2.0 * config_.sigmaEpipolar_px * config_.sigmaEpipolar_px) -
                    d * d / (2.0 * config_.sigmaSimilarity_px * config_.sigmaSimilarity_px) +
                    sizeExponent(i, j));
}

void StereoMatcher::correspond(BoundedVectorView<IndexPair>& pairs) {
    pairs.clear();
    const Prepared& p = *prepared_;
    blocks_.reset(p.count[0], p.count[1]);
    // Only camera 1 blobs within the epipolar band of a camera 0 blob can link to it.
    for (std::size_t s = 0; s < p.validCount[0]; ++s) {
        const int i = p.byRow[0][s];
        const double y = p.rectified[0][idx(i)].y();
        for (int t = p.lowerBound(1, y - band_px_);
             t < static_cast<int>(p.validCount[1]) && p.rowOf(1, t) <= y + band_px_; ++t) {
            const int j = p.byRow[1][idx(t)];
            if (inBand(i, j))
                blocks_.link(idx(i), idx(j));
        }
    }
    blocks_.build();

    for (std::size_t b = 0; b < blocks_.blockCount(); ++b) {
        const std::span<const int> rows = blocks_.leftOf(b);
        const std::span<const int> cols = blocks_.rightOf(b);
        ++counters_.blocks;
        counters_.largestBlock =
            std::max<std::uint64_t>(counters_.largestBlock, std::max(rows.size(), cols.size()));
        const bool solved = solver_.solve(
            rows, cols, config_.minProximity, [this](int i, int j) { return proximity(i, j); },
            [&pairs](int i, int j) {
                pairs.push_back({i, j});
            });
        if (!solved)
            ++counters_.blockOverflow;
    }
    counters_.correspondences += pairs.size();
}

bool StereoMatcher::checkedMarker(const Ray& ray0, const Ray& ray1, const Vec2& pixel0,
                                  const Vec2& pixel1, StereoMarker& marker) {
    const std::optional<TriangulatedPoint> point = triangulate(ray0, ray1);
    if (!point || point->range0_mm <= 0.0 || point->range1_mm <= 0.0 ||
        point->rayGap_mm > config_.maxRayGap_mm) {
        ++counters_.rejectedRayGap;
        return false;
    }
    double reprojection = 0.0;
    for (int c = 0; c < 2; ++c) {
        const std::optional<Vec2> back = rig_.camera(c).project(point->point_rig_mm);
        const Vec2& measured = c == 0 ? pixel0 : pixel1;
        reprojection = std::max(reprojection, back ? (*back - measured).norm()
                                                   : std::numeric_limits<double>::infinity());
    }
    if (reprojection > config_.maxReprojection_px) {
        ++counters_.rejectedReprojection;
        return false;
    }
    marker.position_rig_mm = point->point_rig_mm;
    marker.rayGap_mm = static_cast<float>(point->rayGap_mm);
    marker.reprojection_px = static_cast<float>(reprojection);
    return true;
}

void StereoMatcher::triangulatePair(int i, int j, BoundedVectorView<StereoMarker>& out) {
    const Prepared& p = *prepared_;
    StereoMarker candidate;
    if (!checkedMarker(p.rays[0][idx(i)], p.rays[1][idx(j)], p.pixel[0][idx(i)], p.pixel[1][idx(j)],
                       candidate))
        return;
    StereoMarker* marker = out.append();
    if (marker == nullptr) {
        ++counters_.markerOverflow;
        return;
    }
    *marker = candidate;
    marker->blob0 = i;
    marker->blob1 = j;
    marker->epipolar_px =
        static_cast<float>(p.rectified[0][idx(i)].y() - p.rectified[1][idx(j)].y());
}

bool StereoMatcher::preparedBlob(int camera, int i, Ray& ray, Vec2& rectified_px) const {
    const Prepared& p = *prepared_;
    const std::size_t c = camera == 0 ? 0 : 1;
    if (!valid_ || i < 0 || idx(i) >= p.count[c] || !p.valid[c][idx(i)])
        return false;
    ray = p.rays[c][idx(i)];
    rectified_px = p.rectified[c][idx(i)];
    return true;
}

bool StereoMatcher::triangulateBlobs(const Blob& blob0, int i, const Blob& blob1, int j,
                                     StereoMarker& marker) {
    const std::optional<Ray> ray0 = rig_.camera(0).ray(blob0.centre_px);
    const std::optional<Ray> ray1 = rig_.camera(1).ray(blob1.centre_px);
    if (!ray0 || !ray1) {
        ++counters_.unrectifiable;
        return false;
    }
    const std::optional<Vec2> rectified0 = rig_.rectifyDirection(ray0->direction_rig);
    const std::optional<Vec2> rectified1 = rig_.rectifyDirection(ray1->direction_rig);
    if (!rectified0 || !rectified1) {
        ++counters_.unrectifiable;
        return false;
    }
    if (!checkedMarker(*ray0, *ray1, blob0.centre_px, blob1.centre_px, marker))
        return false;
    marker.blob0 = i;
    marker.blob1 = j;
    marker.epipolar_px = static_cast<float>(rectified0->y() - rectified1->y());
    return true;
}

void StereoMatcher::match(std::span<const Blob> blobs0, std::span<const Blob> blobs1,
                          BoundedVectorView<StereoMarker>& out) {
    out.clear();
    ++counters_.frames;
    if (!valid_)
        return;
    prepare(blobs0, blobs1);
    correspond(pairs_);
    for (const IndexPair& pair : pairs_)
        triangulatePair(pair.left, pair.right, out);
}

void StereoMatcher::matchEpipolarOnly(std::span<const Blob> blobs0, std::span<const Blob> blobs1,
                                      BoundedVectorView<StereoMarker>& out) {
    out.clear();
    ++counters_.frames;
    if (!valid_)
        return;
    prepare(blobs0, blobs1);
    const Prepared& p = *prepared_;
    for (std::size_t i = 0; i < p.count[0]; ++i)
        for (std::size_t j = 0; j < p.count[1]; ++j) {
            if (!inBand(static_cast<int>(i), static_cast<int>(j)))
                continue;
            const std::optional<TriangulatedPoint> point = triangulate(p.rays[0][i], p.rays[1][j]);
            if (!point)
                continue;
            StereoMarker* marker = out.append();
            if (marker == nullptr) {
                ++counters_.markerOverflow;
                return;
            }
            marker->blob0 = static_cast<int>(i);
            marker->blob1 = static_cast<int>(j);
            marker->position_rig_mm = point->point_rig_mm;
            marker->rayGap_mm = static_cast<float>(point->rayGap_mm);
        }
}

} // namespace edgetrack
