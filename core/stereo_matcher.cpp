// Stereo correspondence of blobs (paper section 3.1, eq. 1-4) and triangulation into 3D markers.
#include "core/stereo_matcher.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/triangulation.hpp"

namespace edgetrack {

namespace {
constexpr std::size_t idx(int i) {
    return static_cast<std::size_t>(i);
}
constexpr std::size_t kMaxNeighbours = 32;
} // namespace

// Per-blob data of one frame, for both cameras, in storage sized once.
struct StereoMatcher::Prepared {
    explicit Prepared(std::size_t maxBlobs) {
        for (int c = 0; c < 2; ++c) {
            rectified[c] = std::make_unique<Vec2[]>(maxBlobs);
            pixel[c] = std::make_unique<Vec2[]>(maxBlobs);
            rays[c] = std::make_unique<Ray[]>(maxBlobs);
            valid[c] = std::make_unique<bool[]>(maxBlobs);
            neighbours[c] = std::make_unique<FixedVector<Vec2, kMaxNeighbours>[]>(maxBlobs);
        }
    }
    std::size_t count[2] = {0, 0};
    std::unique_ptr<Vec2[]> rectified[2];
    std::unique_ptr<Vec2[]> pixel[2];
    std::unique_ptr<Ray[]> rays[2];
    std::unique_ptr<bool[]> valid[2];
    /// Offsets of the other blobs of the same camera inside region R (rectified px).
    std::unique_ptr<FixedVector<Vec2, kMaxNeighbours>[]> neighbours[2];
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
    const double focalBaseline = rig.rectifiedFocal_px() * rig.baseline_mm();
    minDisparity_px_ = focalBaseline / config.maxDepth_mm;
    maxDisparity_px_ = focalBaseline / config.minDepth_mm;
    band_px_ = config.epipolarBand_sigmas * config.sigmaEpipolar_px;
}

StereoMatcher::~StereoMatcher() = default;

void StereoMatcher::prepare(std::span<const Blob> blobs0, std::span<const Blob> blobs1) {
    const std::span<const Blob> blobs[2] = {blobs0, blobs1};
    for (int c = 0; c < 2; ++c) {
        Prepared& p = *prepared_;
        p.count[c] = std::min(blobs[c].size(), maxBlobs_);
        for (std::size_t i = 0; i < p.count[c]; ++i) {
            p.pixel[c][i] = blobs[c][i].centre_px;
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
        }
        collectNeighbours(c);
    }
}

void StereoMatcher::collectNeighbours(int camera) {
    Prepared& p = *prepared_;
    const double half = 0.5 * config_.neighbourhood_px;
    const std::size_t n = p.count[camera];
    for (std::size_t i = 0; i < n; ++i) {
        p.neighbours[camera][i].clear();
        if (!p.valid[camera][i])
            continue;
        for (std::size_t k = 0; k < n; ++k) {
            if (k == i || !p.valid[camera][k])
                continue;
            const Vec2 offset = p.rectified[camera][k] - p.rectified[camera][i];
            if (std::abs(offset.x()) < half && std::abs(offset.y()) < half)
                p.neighbours[camera][i].push_back(offset); // a crowded region keeps the first 32
        }
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
    // Eq. 2: mean distance from each point of the smaller neighbourhood to the closest point of
    // the larger one, both translated so that the candidate pair sits at the origin.
    const auto& a = prepared_->neighbours[0][idx(i)];
    const auto& b = prepared_->neighbours[1][idx(j)];
    const auto& smaller = a.size() <= b.size() ? a : b;
    const auto& larger = a.size() <= b.size() ? b : a;
    if (smaller.empty())
        return 0.0;
    double sum = 0.0;
    for (const Vec2& q : smaller) {
        double closest = std::numeric_limits<double>::infinity();
        for (const Vec2& r : larger)
            closest = std::min(closest, (q - r).squaredNorm());
        sum += std::sqrt(closest);
    }
    return sum / static_cast<double>(smaller.size());
}

double StereoMatcher::proximity(int i, int j) const {
    if (!inBand(i, j))
        return 0.0;
    const double dy = prepared_->rectified[0][idx(i)].y() - prepared_->rectified[1][idx(j)].y();
    const double epipolar =
        std::exp(-dy * dy / (2.0 * config_.sigmaEpipolar_px * config_.sigmaEpipolar_px));
    const double d = neighbourhoodDistance(i, j);
    return epipolar *
           std::exp(-d * d / (2.0 * config_.sigmaSimilarity_px * config_.sigmaSimilarity_px));
}

void StereoMatcher::mutualBestOfLargeBlock(std::span<const int> rows, std::span<const int> cols,
                                           BoundedVectorView<IndexPair>& pairs) {
    // Too big for the fixed-size SVD: pair rows and columns that are each other's best.
    for (const int r : rows) {
        int bestCol = -1;
        double best = config_.minProximity;
        for (const int c : cols)
            if (const double g = proximity(r, c); g >= best) {
                best = g;
                bestCol = c;
            }
        if (bestCol < 0)
            continue;
        bool mutual = true;
        for (const int other : rows)
            if (other != r && proximity(other, bestCol) > best)
                mutual = false;
        if (mutual)
            pairs.push_back({r, bestCol});
    }
}

void StereoMatcher::correspond(BoundedVectorView<IndexPair>& pairs) {
    pairs.clear();
    const Prepared& p = *prepared_;
    blocks_.reset(p.count[0], p.count[1]);
    for (std::size_t i = 0; i < p.count[0]; ++i)
        for (std::size_t j = 0; j < p.count[1]; ++j)
            if (inBand(static_cast<int>(i), static_cast<int>(j)))
                blocks_.link(i, j);
    blocks_.build();

    for (std::size_t b = 0; b < blocks_.blockCount(); ++b) {
        const std::span<const int> rows = blocks_.leftOf(b);
        const std::span<const int> cols = blocks_.rightOf(b);
        ++counters_.blocks;
        counters_.largestBlock =
            std::max<std::uint64_t>(counters_.largestBlock, std::max(rows.size(), cols.size()));
        if (rows.size() > static_cast<std::size_t>(kMaxCorrespondenceBlock) ||
            cols.size() > static_cast<std::size_t>(kMaxCorrespondenceBlock)) {
            ++counters_.blockOverflow;
            mutualBestOfLargeBlock(rows, cols, pairs);
            continue;
        }
        block_.resize(static_cast<Eigen::Index>(rows.size()),
                      static_cast<Eigen::Index>(cols.size()));
        for (std::size_t r = 0; r < rows.size(); ++r)
            for (std::size_t c = 0; c < cols.size(); ++c)
                block_(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) =
                    proximity(rows[r], cols[c]);
        solver_.solve(block_, config_.minProximity, [&](int r, int c) {
            pairs.push_back({rows[idx(r)], cols[idx(c)]});
        });
    }
    counters_.correspondences += pairs.size();
}

void StereoMatcher::triangulatePair(int i, int j, BoundedVectorView<StereoMarker>& out) {
    const Prepared& p = *prepared_;
    const std::optional<TriangulatedPoint> point =
        triangulate(p.rays[0][idx(i)], p.rays[1][idx(j)]);
    if (!point || point->range0_mm <= 0.0 || point->range1_mm <= 0.0 ||
        point->rayGap_mm > config_.maxRayGap_mm) {
        ++counters_.rejectedRayGap;
        return;
    }
    double reprojection = 0.0;
    for (int c = 0; c < 2; ++c) {
        const std::optional<Vec2> back = rig_.camera(c).project(point->point_rig_mm);
        const Vec2& measured = p.pixel[c][idx(c == 0 ? i : j)];
        reprojection = std::max(reprojection, back ? (*back - measured).norm()
                                                   : std::numeric_limits<double>::infinity());
    }
    if (reprojection > config_.maxReprojection_px) {
        ++counters_.rejectedReprojection;
        return;
    }
    StereoMarker* marker = out.append();
    if (marker == nullptr) {
        ++counters_.markerOverflow;
        return;
    }
    marker->blob0 = i;
    marker->blob1 = j;
    marker->position_rig_mm = point->point_rig_mm;
    marker->rayGap_mm = static_cast<float>(point->rayGap_mm);
    marker->reprojection_px = static_cast<float>(reprojection);
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
