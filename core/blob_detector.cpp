// Blob detection in 8-bit IR frames: NEON threshold scan, run-based connected components, moments.
#include "core/blob_detector.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/simd/neon.hpp"

namespace edgetrack {

namespace {
// Labels and run indices are ints (they can be -1); storage is indexed by size_t.
constexpr std::size_t idx(int i) {
    return static_cast<std::size_t>(i);
}

// "Any lane set" from the two 64-bit halves: two moves and an OR on NEON, and cheap through SIMDe,
// where a horizontal byte maximum (vmaxvq_u8) costs a dozen instructions.
inline bool anyLaneSet(uint8x16_t v) {
    const uint64x2_t halves = vreinterpretq_u64_u8(v);
    return (vgetq_lane_u64(halves, 0) | vgetq_lane_u64(halves, 1)) != 0;
}

// The byte maximum of row[0, length), length a multiple of 64; four accumulators keep the loads
// independent.
inline uint8x16_t maximumOf(const std::uint8_t* row, int length) {
    uint8x16_t m0 = vdupq_n_u8(0), m1 = m0, m2 = m0, m3 = m0;
    for (int at = 0; at < length; at += 64) {
        m0 = vmaxq_u8(m0, vld1q_u8(row + at));
        m1 = vmaxq_u8(m1, vld1q_u8(row + at + 16));
        m2 = vmaxq_u8(m2, vld1q_u8(row + at + 32));
        m3 = vmaxq_u8(m3, vld1q_u8(row + at + 48));
    }
    return vmaxq_u8(vmaxq_u8(m0, m1), vmaxq_u8(m2, m3));
}
/// The sum over i < \a count (a multiple of 4) of the smallest of a[i], b[i] and c[i].
float sumOfSmallest(const float* a, const float* b, const float* c, std::size_t count) {
    float32x4_t sum = vdupq_n_f32(0.0F);
    for (std::size_t i = 0; i < count; i += 4)
        sum = vaddq_f32(sum,
                        vminq_f32(vld1q_f32(a + i), vminq_f32(vld1q_f32(b + i), vld1q_f32(c + i))));
    return vaddvq_f32(sum);
}

/// A circle fitted to outline points (px): Kasa's algebraic fit, then Gauss-Newton on the
/// geometric distances, which the algebraic fit biases on a partial arc.
struct Circle {
    Vec2 centre = Vec2::Zero();
    double radius = 0.0;
    double rms = 0.0;
    bool valid = false;
};

// The RMS distance (px) of \a points from the ellipse fitted to them, and its elongation; an
// infinite RMS when no ellipse fits (a hyperbola or parabola, too few points). The conic
// a x^2 + b xy + c y^2 + d x + e y + f = 0 with a + c = 1 is fitted by linear least squares about
// the points' mean; each point's distance is its Sampson distance |F| / |grad F|.
struct EllipseFit {
    double rms = std::numeric_limits<double>::infinity();
    double elongation = 0.0;
};

EllipseFit fitEllipse(const Vec2* points, std::size_t count) {
    EllipseFit fit;
    if (count < 8)
        return fit;
    Vec2 mean = Vec2::Zero();
    for (std::size_t i = 0; i < count; ++i)
        mean += points[i];
    mean /= static_cast<double>(count);
    // Unknowns (a, b, d, e, f) with c = 1 - a: a (x^2 - y^2) + b xy + d x + e y + f = -y^2.
    Eigen::Matrix<double, 5, 5> normal = Eigen::Matrix<double, 5, 5>::Zero();
    Eigen::Matrix<double, 5, 1> rhs = Eigen::Matrix<double, 5, 1>::Zero();
    for (std::size_t i = 0; i < count; ++i) {
        const Vec2 p = points[i] - mean;
        Eigen::Matrix<double, 5, 1> row;
        row << p.x() * p.x() - p.y() * p.y(), p.x() * p.y(), p.x(), p.y(), 1.0;
        normal += row * row.transpose();
        rhs -= row * (p.y() * p.y());
    }
    const Eigen::Matrix<double, 5, 1> q = normal.ldlt().solve(rhs);
    const double a = q(0), b = q(1), c = 1.0 - q(0), d = q(2), e = q(3), f = q(4);
    if (!q.allFinite() || !(4.0 * a * c - b * b > 0.0))
        return fit;
    double sum = 0.0;
    for (std::size_t i = 0; i < count; ++i) {
        const Vec2 p = points[i] - mean;
        const double value =
            a * p.x() * p.x() + b * p.x() * p.y() + c * p.y() * p.y() + d * p.x() + e * p.y() + f;
        const Vec2 gradient(2.0 * a * p.x() + b * p.y() + d, b * p.x() + 2.0 * c * p.y() + e);
        const double length2 = gradient.squaredNorm();
        if (!(length2 > 1e-18))
            return fit;
        sum += value * value / length2;
    }
    // The semi-axes go as 1 / sqrt of the eigenvalues of [[a, b/2], [b/2, c]].
    const double mid = 0.5 * (a + c), half = std::sqrt(0.25 * (a - c) * (a - c) + 0.25 * b * b);
    if (!(mid - half > 0.0))
        return fit;
    fit.rms = std::sqrt(sum / static_cast<double>(count));
    fit.elongation = std::sqrt((mid + half) / (mid - half));
    return fit;
}

Circle fitCircle(const Vec2* points, const std::uint8_t* use, std::size_t count) {
    Circle c;
    Eigen::Matrix3d normal = Eigen::Matrix3d::Zero();
    Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
    std::size_t n = 0;
    for (std::size_t i = 0; i < count; ++i) {
        if (!use[i])
            continue;
        const Eigen::Vector3d row(points[i].x(), points[i].y(), 1.0);
        normal += row * row.transpose();
        rhs -= row * points[i].squaredNorm();
        ++n;
    }
    if (n < 5)
        return c;
    const Eigen::Vector3d def = normal.ldlt().solve(rhs);
    c.centre = Vec2(-0.5 * def.x(), -0.5 * def.y());
    const double r2 = c.centre.squaredNorm() - def.z();
    if (!(r2 > 0.0))
        return c;
    c.radius = std::sqrt(r2);
    for (int iteration = 0; iteration < 5; ++iteration) {
        Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
        Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
        for (std::size_t i = 0; i < count; ++i) {
            if (!use[i])
                continue;
            const Vec2 d = points[i] - c.centre;
            const double length = d.norm();
            if (length < 1e-9)
                continue;
            const Eigen::Vector3d j(-d.x() / length, -d.y() / length, -1.0);
            const double r = length - c.radius;
            jtj += j * j.transpose();
            jtr += j * r;
        }
        const Eigen::Vector3d step = jtj.ldlt().solve(-jtr);
        c.centre += step.head<2>();
        c.radius += step.z();
        if (step.squaredNorm() < 1e-12)
            break;
    }
    double sum2 = 0.0;
    for (std::size_t i = 0; i < count; ++i)
        if (use[i]) {
            const double r = (points[i] - c.centre).norm() - c.radius;
            sum2 += r * r;
        }
    c.rms = std::sqrt(sum2 / static_cast<double>(n));
    c.valid = c.radius > 0.0 && std::isfinite(c.rms);
    return c;
}
} // namespace

// Sums over a component's pixels; exact integers, so merging components loses nothing.
struct BlobDetector::Moments {
    std::int64_t count = 0;
    std::int64_t sumI = 0, sumIx = 0, sumIy = 0;
    std::int64_t sumX = 0, sumY = 0, sumXX = 0, sumYY = 0, sumXY = 0;
    int left = 0, right = 0, top = 0, bottom = 0;
    int peak = 0;
    /// One pixel of the component (the start of its first run): where splitIntoDiscs starts.
    int seedX = 0, seedY = 0;

    void add(const Moments& o) {
        if (count == 0) { // an empty label's bounds would otherwise take in the origin
            *this = o;
            return;
        }
        count += o.count;
        sumI += o.sumI;
        sumIx += o.sumIx;
        sumIy += o.sumIy;
        sumX += o.sumX;
        sumY += o.sumY;
        sumXX += o.sumXX;
        sumYY += o.sumYY;
        sumXY += o.sumXY;
        left = std::min(left, o.left);
        right = std::max(right, o.right);
        top = std::min(top, o.top);
        bottom = std::max(bottom, o.bottom);
        peak = std::max(peak, o.peak);
    }
};

struct BlobDetector::Run {
    int x0 = 0;
    int x1 = 0;
    int label = -1;
};

BlobDetector::BlobDetector(const BlobDetectorConfig& config, int width_px, int height_px)
    : config_(config)
    , width_(width_px)
    , height_(height_px) {
    valid_ = width_px > 0 && height_px > 0 && width_px <= 65535 && height_px <= 65535 &&
             config.maxLabels > 0 && config.maxLabels < (1u << 30) && config.minArea_px >= 1 &&
             config.maxArea_px >= config.minArea_px && config.threshold > 0;
    if (!valid_)
        return;
    moments_ = std::make_unique<Moments[]>(config.maxLabels);
    // A split blob gives up to kMaxSplitParts candidates in place of one; blobs of more than three
    // discs are rare enough that three a label is room (beyond it, overflow is counted).
    candidates_ = BoundedVector<Candidate>(3 * config.maxLabels);
    notRound_ = BoundedVector<std::uint32_t>(config.maxLabels);
    maybeMerged_ = BoundedVector<std::uint32_t>(config.maxLabels);
    refused_ = BoundedVector<Blob>(config.maxBlobs);
    constexpr auto kSplitPixels = static_cast<std::size_t>(kSplitSide * kSplitSide);
    splitMask_ = std::make_unique<std::uint8_t[]>(kSplitPixels);
    splitDistance_ = std::make_unique<std::uint16_t[]>(kSplitPixels);
    splitStack_ = std::make_unique<std::uint16_t[]>(kSplitPixels);
    splitEdge_ = std::make_unique<Vec2[]>(kSplitPixels);
    lineResidual_ = std::make_unique<float[]>(kLinePoints * (1 + 2 * kLineSteps));
    labels_ = DisjointSets(config.maxLabels);
    // At most one run per two pixels of a row.
    const auto runsPerRow = static_cast<std::size_t>(width_px / 2 + 1);
    previousRuns_ = std::make_unique<Run[]>(runsPerRow);
    currentRuns_ = std::make_unique<Run[]>(runsPerRow);
}

BlobDetector::~BlobDetector() = default;

int BlobDetector::newLabel() {
    if (!labels_.add()) {
        labelsExhausted_ = true;
        return -1;
    }
    const std::size_t label = labels_.size() - 1;
    moments_[label] = Moments{};
    return static_cast<int>(label);
}

int BlobDetector::findRoot(int label) {
    return static_cast<int>(labels_.find(idx(label)));
}

int BlobDetector::unite(int a, int b) {
    const std::size_t ra = labels_.find(idx(a)), rb = labels_.find(idx(b));
    if (ra == rb)
        return static_cast<int>(ra);
    // The smaller label stays the root (DisjointSets), and holds the moments of both.
    moments_[std::min(ra, rb)].add(moments_[std::max(ra, rb)]);
    return static_cast<int>(labels_.unite(ra, rb));
}

void BlobDetector::closeRun(int y, int x0, int x1, const std::uint8_t* row) {
    Moments m;
    std::int64_t sumI = 0, sumIx = 0;
    int peak = 0;
    for (int x = x0; x <= x1; ++x) {
        const int intensity = row[x];
        sumI += intensity;
        sumIx += static_cast<std::int64_t>(intensity) * x;
        peak = std::max(peak, intensity);
    }
    // Sums of x and x^2 over x0..x1 in closed form.
    const std::int64_t count = x1 - x0 + 1;
    auto sumOfSquaresTo = [](std::int64_t n) { return n * (n + 1) * (2 * n + 1) / 6; };
    const std::int64_t sumX = (static_cast<std::int64_t>(x0) + x1) * count / 2;
    const std::int64_t sumXX = sumOfSquaresTo(x1) - sumOfSquaresTo(x0 - 1);
    m.count = count;
    m.sumI = sumI;
    m.sumIx = sumIx;
    m.sumIy = sumI * y;
    m.sumX = sumX;
    m.sumY = count * y;
    m.sumXX = sumXX;
    m.sumYY = count * y * y;
    m.sumXY = sumX * y;
    m.left = x0;
    m.right = x1;
    m.top = m.bottom = y;
    m.peak = peak;
    m.seedX = x0;
    m.seedY = y;

    // 8-connectivity: a previous run touches this one if their x ranges overlap when widened by 1.
    // Runs of a row come left to right, so a previous run that ends before this one starts can
    // touch no later run either: the scan resumes where the last one left off.
    while (previousScan_ < previousCount_ && previousRuns_[idx(previousScan_)].x1 < x0 - 1)
        ++previousScan_;
    int label = -1;
    for (int i = previousScan_; i < previousCount_; ++i) {
        const Run& p = previousRuns_[idx(i)];
        if (p.x0 > x1 + 1)
            break;
        if (p.label < 0)
            continue;
        label = label < 0 ? findRoot(p.label) : unite(label, p.label);
    }
    if (label < 0)
        label = newLabel();
    if (label >= 0)
        moments_[idx(label)].add(m);
    currentRuns_[idx(currentCount_++)] = {x0, x1, label};
}

void BlobDetector::finishRow() {
    std::swap(previousRuns_, currentRuns_);
    previousCount_ = currentCount_;
    previousScan_ = 0;
    currentCount_ = 0;
}

void BlobDetector::detect(const std::uint8_t* pixels, int stride_bytes,
                          BoundedVectorView<Blob>& out, std::span<const Vec2> expected_px) {
    out.clear();
    ++counters_.images;
    traced_ = {}; // the image may be new at the same address
    if (!valid_)
        return;
    labels_.reset(0);
    labelsExhausted_ = false;
    previousCount_ = 0;
    previousScan_ = 0;
    currentCount_ = 0;

    const std::uint8_t threshold = config_.threshold;
    const uint8x16_t thresholdVector = vdupq_n_u8(threshold);
    // Lanes >= threshold stay non-zero after a saturating subtraction of threshold - 1.
    const uint8x16_t belowThreshold = vdupq_n_u8(static_cast<std::uint8_t>(threshold - 1));
    auto anyBright = [&](uint8x16_t maximum) {
        return anyLaneSet(vqsubq_u8(maximum, belowThreshold));
    };
    const int wholePieces = width_ & ~63;
    for (int y = 0; y < height_; ++y) {
        const std::uint8_t* row = pixels + static_cast<std::ptrdiff_t>(y) * stride_bytes;
        int runStart = -1;
        int x = 0;
        auto scalarPixel = [&](int at) {
            if (row[at] >= threshold) {
                if (runStart < 0)
                    runStart = at;
            } else if (runStart >= 0) {
                closeRun(y, runStart, at - 1, row);
                runStart = -1;
            }
        };
        // A 16-byte piece with both bright and dark pixels: run edges from a 4-bits-per-pixel
        // mask (the NEON stand-in for a movemask), so the loop steps per edge, not per pixel.
        auto scanEdges = [&](int piece, uint8x16_t v) {
            const std::uint64_t bright =
                vget_lane_u64(vreinterpret_u64_u8(vshrn_n_u16(
                                  vreinterpretq_u16_u8(vcgeq_u8(v, thresholdVector)), 4)),
                              0);
            int offset = 0;
            while (offset < 16) {
                const std::uint64_t wanted = runStart < 0 ? bright : ~bright;
                const std::uint64_t rest = wanted >> (4 * offset);
                if (rest == 0)
                    return;
                offset += std::countr_zero(rest) / 4;
                if (runStart < 0) {
                    runStart = piece + offset;
                } else {
                    closeRun(y, runStart, piece + offset - 1, row);
                    runStart = -1;
                }
            }
        };
        auto closeOpenRun = [&](int end) {
            if (runStart >= 0) {
                closeRun(y, runStart, end - 1, row);
                runStart = -1;
            }
        };
        // One 64-byte piece: skipped when all dark, else its four 16-byte pieces by their edges.
        auto scan64 = [&](int at) {
            const uint8x16_t a = vld1q_u8(row + at);
            const uint8x16_t b = vld1q_u8(row + at + 16);
            const uint8x16_t c = vld1q_u8(row + at + 32);
            const uint8x16_t d = vld1q_u8(row + at + 48);
            if (!anyBright(vmaxq_u8(vmaxq_u8(a, b), vmaxq_u8(c, d)))) {
                closeOpenRun(at);
                return;
            }
            scanEdges(at, a);
            scanEdges(at + 16, b);
            scanEdges(at + 32, c);
            scanEdges(at + 48, d);
        };
        // Most rows of an IR frame are dark all along: one load per byte and a single test per
        // row, as cheap as a plain read. A row with something bright is read again from L1: dark
        // stretches skipped 256 bytes at a time, pieces with anything bright 64 bytes at a time.
        if (!anyBright(maximumOf(row, wholePieces)))
            x = wholePieces;
        while (x + 256 <= width_) {
            if (!anyBright(maximumOf(row + x, 256))) {
                closeOpenRun(x);
            } else {
                for (int at = x; at < x + 256; at += 64)
                    scan64(at);
            }
            x += 256;
        }
        for (; x + 64 <= width_; x += 64)
            scan64(x);
        for (; x < width_; ++x)
            scalarPixel(x);
        if (runStart >= 0)
            closeRun(y, runStart, width_ - 1, row);
        finishRow();
    }
    if (labelsExhausted_)
        ++counters_.labelOverflow;
    emitBlobs(pixels, stride_bytes, out, expected_px);
}

namespace {

/// Squared distance (px^2) from \a centre to the nearest of \a expected_px, at most \a limit2.
double nearestExpected2(const Vec2& centre, std::span<const Vec2> expected_px, double limit2) {
    double nearest2 = limit2;
    for (const Vec2& e : expected_px)
        nearest2 = std::min(nearest2, (centre - e).squaredNorm());
    return nearest2;
}

} // namespace

Blob BlobDetector::framedBlob(const Moments& m) {
    Blob blob;
    blob.left = static_cast<std::uint16_t>(m.left);
    blob.right = static_cast<std::uint16_t>(m.right);
    blob.top = static_cast<std::uint16_t>(m.top);
    blob.bottom = static_cast<std::uint16_t>(m.bottom);
    blob.peak = static_cast<std::uint8_t>(m.peak);
    return blob;
}

bool BlobDetector::addCandidate(const Blob& blob, std::uint32_t order) {
    Candidate* const c = candidates_.append();
    if (c == nullptr) {
        ++counters_.blobOverflow;
        return false;
    }
    c->blob = blob;
    c->order = order;
    return true;
}

void BlobDetector::emitBlobs(const std::uint8_t* pixels, int stride_bytes,
                             BoundedVectorView<Blob>& out, std::span<const Vec2> expected_px) {
    candidates_.clear();
    refused_.clear();
    notRound_.clear();
    maybeMerged_.clear();
    for (std::size_t label = 0; label < labels_.size(); ++label) {
        if (!labels_.isRoot(label))
            continue;
        const Moments& m = moments_[label];
        if (m.count < config_.minArea_px) {
            ++counters_.rejectedSmall;
            continue;
        }
        if (m.count > config_.maxArea_px) {
            ++counters_.rejectedLarge;
            continue;
        }
        const auto [elongation, fill] = shapeOf(m);
        // Candidates keep the order of their labels (top rows first); the parts of a split blob
        // take the places after it.
        const auto order = static_cast<std::uint32_t>(label) * kOrderStride;
        if (elongation > config_.maxElongation || fill < config_.minFill) {
            ++counters_.rejectedNotRound;
            if (config_.splitMerged)
                notRound_.push_back(static_cast<std::uint32_t>(label));
            continue;
        }
        if (config_.splitMerged &&
            (elongation > kMaybeMergedElongation || fill < kMaybeMergedFill)) {
            maybeMerged_.push_back(static_cast<std::uint32_t>(label));
            continue;
        }
        addCandidate(roundBlob(m), order);
    }

    // Blobs of touching discs split into their discs, after the round ones: when those already
    // fill the room (a burst of reflections), only the blobs near an expected marker are worth
    // the work, as only they could take a place.
    const double near2 = config_.keepNear_px * config_.keepNear_px;
    const bool crowded = candidates_.size() >= out.capacity();
    const auto worthSplitting = [&](const Moments& m) {
        if (!crowded)
            return true;
        const Vec2 centre(static_cast<double>(m.sumX) / static_cast<double>(m.count),
                          static_cast<double>(m.sumY) / static_cast<double>(m.count));
        // A blob of two discs lies off either disc's centre by up to about its own size.
        const double reach2 = near2 + 0.25 * static_cast<double>(m.count);
        return nearestExpected2(centre, expected_px, reach2) < reach2;
    };
    for (const std::uint32_t label : notRound_) {
        const Moments& m = moments_[label];
        if (!worthSplitting(m))
            continue;
        if (!splitOrEllipse(m, pixels, stride_bytes, label * kOrderStride, 1)) {
            ++counters_.splitRefused;
            refused_.push_back(roundBlob(m));
        }
    }
    // Two discs far over each other pass the roundness tests; their outline is still two arcs.
    // Such a blob stays one blob unless two discs fit it.
    for (const std::uint32_t label : maybeMerged_) {
        const Moments& m = moments_[label];
        if (!worthSplitting(m) || !splitOrEllipse(m, pixels, stride_bytes, label * kOrderStride, 2))
            addCandidate(roundBlob(m), label * kOrderStride);
    }

    const std::size_t room = out.capacity();
    if (candidates_.size() > room) {
        // More than fit: the blobs near an expected centre first (nearest first), then the
        // roundest; labels break ties, so the choice is a function of the image alone.
        counters_.blobOverflow += candidates_.size() - room;
        for (Candidate& c : candidates_) {
            const double nearest2 = nearestExpected2(c.blob.centre_px, expected_px, near2);
            c.group = nearest2 < near2 ? 0 : 1;
            // Split parts and cut discs rank after the round blobs: their circles are round by
            // construction.
            c.key = c.group == 0 ? nearest2
                    : c.blob.split || c.blob.cut
                        ? config_.maxElongation + static_cast<double>(c.blob.fitRms_px)
                        : static_cast<double>(c.blob.elongation);
        }
        const auto before = [](const Candidate& a, const Candidate& b) {
            if (a.group != b.group)
                return a.group < b.group;
            if (a.key != b.key)
                return a.key < b.key;
            return a.order < b.order;
        };
        const auto kept = candidates_.begin() + static_cast<std::ptrdiff_t>(room);
        std::nth_element(candidates_.begin(), kept, candidates_.end(), before);
        // Out in the order their top rows appear, as when all fit.
        std::sort(candidates_.begin(), kept,
                  [](const Candidate& a, const Candidate& b) { return a.order < b.order; });
        while (candidates_.size() > room)
            candidates_.pop_back();
    }
    for (const Candidate& c : candidates_) {
        *out.append() = c.blob;
        ++counters_.accepted;
    }
}

BlobDetector::Shape BlobDetector::shapeOf(const Moments& m) {
    // From the pixel distribution (unweighted: the saturated core carries no shape); +1/12 is
    // each pixel's own extent.
    const double n = static_cast<double>(m.count);
    const double meanX = static_cast<double>(m.sumX) / n;
    const double meanY = static_cast<double>(m.sumY) / n;
    const double xx = static_cast<double>(m.sumXX) / n - meanX * meanX + 1.0 / 12.0;
    const double yy = static_cast<double>(m.sumYY) / n - meanY * meanY + 1.0 / 12.0;
    const double xy = static_cast<double>(m.sumXY) / n - meanX * meanY;
    const double half = 0.5 * (xx + yy);
    const double spread = std::sqrt(0.25 * (xx - yy) * (xx - yy) + xy * xy);
    const double major = half + spread, minor = std::max(half - spread, 1e-9);
    // A uniform ellipse with these moments covers 4 pi sqrt(major * minor) pixels.
    return {std::sqrt(major / minor),
            n / (4.0 * 3.14159265358979323846 * std::sqrt(major * minor))};
}

Blob BlobDetector::roundBlob(const Moments& m) {
    Blob blob = framedBlob(m);
    const double weight = static_cast<double>(m.sumI);
    blob.centre_px = {static_cast<double>(m.sumIx) / weight, static_cast<double>(m.sumIy) / weight};
    blob.area_px = static_cast<float>(m.count);
    blob.elongation = static_cast<float>(shapeOf(m).elongation);
    return blob;
}

std::size_t BlobDetector::traceOutline(int left, int top, int right, int bottom, int seedX,
                                       int seedY, const std::uint8_t* pixels, int stride_bytes) {
    const int w = right - left + 1, h = bottom - top + 1;
    if (w + 2 > kSplitSide || h + 2 > kSplitSide || left <= 0 || top <= 0 || right >= width_ - 1 ||
        bottom >= height_ - 1 || seedX < left || seedX > right || seedY < top || seedY > bottom)
        return 0;
    traced_ = {pixels, left, top, right, bottom, seedX, seedY};
    const int gw = w + 2, gh = h + 2;
    const auto cell = [gw](int gx, int gy) { return static_cast<std::size_t>(gy * gw + gx); };
    const auto level = [&](int gx, int gy) {
        return static_cast<int>(
            pixels[static_cast<std::ptrdiff_t>(top - 1 + gy) * stride_bytes + (left - 1 + gx)]);
    };
    std::uint8_t* mask = splitMask_.get();
    std::fill_n(mask, static_cast<std::size_t>(gw * gh), std::uint8_t{0});
    // Its own pixels: 8-connected from its seed (another blob may reach into the box).
    const int threshold = config_.threshold;
    std::size_t stacked = 0;
    const auto push = [&](int gx, int gy) {
        if (gx < 1 || gy < 1 || gx > w || gy > h || mask[cell(gx, gy)] || level(gx, gy) < threshold)
            return;
        mask[cell(gx, gy)] = 1;
        splitStack_[stacked++] = static_cast<std::uint16_t>(cell(gx, gy));
    };
    push(seedX - left + 1, seedY - top + 1);
    while (stacked > 0) {
        const int at = splitStack_[--stacked];
        const int gx = at % gw, gy = at / gw;
        for (int dy = -1; dy <= 1; ++dy)
            for (int dx = -1; dx <= 1; ++dx)
                push(gx + dx, gy + dy);
    }

    // Outline points: where the level crosses the threshold between a pixel of the blob and its
    // outside neighbour, by linear interpolation. The outline of touching discs is arcs of each
    // disc's own circle, concentric with it whatever the blur and the peak level.
    Vec2* edge = splitEdge_.get();
    std::size_t edges = 0;
    const std::size_t edgeRoom = static_cast<std::size_t>(kSplitSide * kSplitSide);
    for (int gy = 1; gy <= h; ++gy)
        for (int gx = 1; gx <= w; ++gx) {
            if (!mask[cell(gx, gy)])
                continue;
            const int inside = level(gx, gy);
            const int steps[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
            for (const auto& step : steps) {
                const int ox = gx + step[0], oy = gy + step[1];
                if (mask[cell(ox, oy)] || edges == edgeRoom)
                    continue;
                const int outside = level(ox, oy);
                const double t = inside > outside ? static_cast<double>(inside - threshold) /
                                                        static_cast<double>(inside - outside)
                                                  : 0.5;
                edge[edges++] = Vec2(gx + t * step[0], gy + t * step[1]);
            }
        }
    tracedEdges_ = edges;
    return edges;
}

bool BlobDetector::splitOrEllipse(const Moments& m, const std::uint8_t* pixels, int stride_bytes,
                                  std::uint32_t order, std::size_t minParts) {
    const std::size_t edges =
        traceOutline(m.left, m.top, m.right, m.bottom, m.seedX, m.seedY, pixels, stride_bytes);
    const EllipseFit ellipse = fitEllipse(splitEdge_.get(), edges);
    const bool oneMarker =
        ellipse.rms <= kSplitFitRms_px && ellipse.elongation <= config_.maxMarkerElongation;
    const std::size_t before = candidates_.size();
    const BlobCounters countersBefore = counters_;
    if (splitIntoDiscs(m, edges, order, minParts)) {
        double splitRms = 0.0;
        for (std::size_t k = before; k < candidates_.size(); ++k)
            splitRms = std::max(splitRms, static_cast<double>(candidates_[k].blob.fitRms_px));
        if (!oneMarker || splitRms < ellipse.rms)
            return true;
        // The ellipse explains the outline better: the split is undone.
        while (candidates_.size() > before)
            candidates_.pop_back();
        counters_ = countersBefore;
    } else if (!oneMarker) {
        return false;
    }
    ++counters_.ellipses;
    addCandidate(roundBlob(m), order);
    return true;
}

bool BlobDetector::splitIntoDiscs(const Moments& m, std::size_t edges, std::uint32_t order,
                                  std::size_t minParts) {
    // The blob on a grid of its bounding box with a frame of one pixel: a cut disc at the image's
    // border is no disc to fit (no outline).
    if (edges == 0)
        return false;
    const int w = m.right - m.left + 1, h = m.bottom - m.top + 1;
    const int gw = w + 2, gh = h + 2;
    const auto cell = [gw](int gx, int gy) { return static_cast<std::size_t>(gy * gw + gx); };
    std::uint8_t* mask = splitMask_.get();
    const Vec2* edge = splitEdge_.get();

    // Chamfer distance to the outside (3 a step, 4 a diagonal step): a disc's centre is a peak.
    std::uint16_t* distance = splitDistance_.get();
    for (int gy = 0; gy < gh; ++gy)
        for (int gx = 0; gx < gw; ++gx)
            distance[cell(gx, gy)] = mask[cell(gx, gy)] ? std::uint16_t{0xFFFF} : std::uint16_t{0};
    const auto relax = [&](int gx, int gy, int dx, int dy, int cost) {
        std::uint16_t& d = distance[cell(gx, gy)];
        d = static_cast<std::uint16_t>(std::min<int>(d, distance[cell(gx + dx, gy + dy)] + cost));
    };
    for (int gy = 1; gy <= h; ++gy)
        for (int gx = 1; gx <= w; ++gx)
            if (mask[cell(gx, gy)]) {
                relax(gx, gy, -1, 0, 3);
                relax(gx, gy, 0, -1, 3);
                relax(gx, gy, -1, -1, 4);
                relax(gx, gy, 1, -1, 4);
            }
    for (int gy = h; gy >= 1; --gy)
        for (int gx = w; gx >= 1; --gx)
            if (mask[cell(gx, gy)]) {
                relax(gx, gy, 1, 0, 3);
                relax(gx, gy, 0, 1, 3);
                relax(gx, gy, 1, 1, 4);
                relax(gx, gy, -1, 1, 4);
            }

    // Disc centres: peaks of the distance, strongest first, each outside the discs already taken.
    struct Peak {
        Vec2 at;
        int depth;
    };
    FixedVector<Peak, kMaxSplitParts + 1> discs;
    for (std::size_t round = 0; round <= kMaxSplitParts; ++round) {
        Peak best{Vec2::Zero(), 0};
        for (int gy = 1; gy <= h; ++gy)
            for (int gx = 1; gx <= w; ++gx) {
                const int d = distance[cell(gx, gy)];
                if (d <= best.depth || d < 4)
                    continue;
                bool peak = true;
                for (int dy = -1; dy <= 1 && peak; ++dy)
                    for (int dx = -1; dx <= 1 && peak; ++dx)
                        peak = distance[cell(gx + dx, gy + dy)] <= d;
                const Vec2 here(gx, gy);
                for (const Peak& taken : discs)
                    peak = peak && (here - taken.at).norm() * 3.0 > taken.depth + 1.5;
                if (peak)
                    best = {here, d};
            }
        if (best.depth == 0)
            break;
        discs.push_back(best);
    }
    if (discs.empty() || discs.size() > kMaxSplitParts)
        return false;

    // The discs: a circle from each peak of the distance, then from the outline points that no
    // circle explains yet (a smaller disc overlapping a larger one makes a shoulder, no peak).
    // A disc's own points lie near its circle and away from the other discs, whose light adds up
    // at the neck between them.
    std::array<Circle, kMaxSplitParts> circle{};
    std::size_t count = 0;
    std::uint8_t* use = mask; // the mask is no longer needed: reused as per-point flags

    // A circle rests on its own outline points when they cover at least half of it (their unit
    // vectors from its centre sum to less than 0.7 of their number: 0.64 for a half circle, 0.83
    // for a third) and fit it within kSplitFitRms_px, or cover a third of it and fit it within
    // kShortArcFitRms_px: a disc with neighbours on several sides, or cut by an edge, keeps only
    // a short arc of its own.
    const auto restsOnItsArc = [](const Circle& c, std::size_t n, const Vec2& resultant) {
        const double share = resultant.norm() / static_cast<double>(std::max<std::size_t>(n, 1));
        const bool covered = share < 0.7 || (share < kShortArcShare && c.rms <= kShortArcFitRms_px);
        return n >= 8 && covered && c.rms <= kSplitFitRms_px && c.radius >= 1.0;
    };
    // A disc of this blob centred by circle \a c (grid coordinates).
    const auto discBlob = [&](const Circle& c) {
        Blob part = framedBlob(m);
        part.centre_px = {c.centre.x() + m.left - 1, c.centre.y() + m.top - 1};
        part.area_px = static_cast<float>(3.14159265358979323846 * c.radius * c.radius);
        part.elongation = 1.0F;
        part.fitRms_px = static_cast<float>(c.rms);
        return part;
    };

    // One peak: perhaps one disc with a piece cut off by an edge in front of it (a hand, the
    // object's body). Its outline is an arc of the disc's circle and a cut that runs inside the
    // circle, never outside it; its own pixels would pull its centre towards what is left of it.
    // Fitted to every outline point, the circle is drawn inside; the points well inside it are
    // left out and it is fitted again, until only the arc is left. The disc is centred by that
    // circle when it rests on the arc, no point lies outside it (which would be another disc or a
    // reflection beside it) and the points inside it are one run, the cut: a circle round two
    // discs far over each other also leaves every point on or inside it, but their necks are two
    // runs, one on either side.
    if (discs.size() == 1) {
        std::fill_n(use, edges, std::uint8_t{1});
        Circle arc{};
        for (int pass = 0; pass < 8; ++pass) {
            const Circle fitted = fitCircle(edge, use, edges);
            if (!fitted.valid)
                break;
            arc = fitted;
            bool changed = false;
            for (std::size_t i = 0; i < edges; ++i) {
                const std::uint8_t onArc =
                    (edge[i] - arc.centre).norm() - arc.radius > -kCutInside_px ? 1 : 0;
                changed = changed || onArc != use[i];
                use[i] = onArc;
            }
            if (!changed)
                break;
        }
        // The points on the arc, and those on the cut (flagged for the run below).
        constexpr std::uint8_t kOnCut = 2, kReached = 3;
        Vec2 resultant = Vec2::Zero();
        std::size_t onArc = 0, inside = 0, first = edges;
        bool outside = false;
        for (std::size_t i = 0; i < edges && arc.valid; ++i) {
            const double residual = (edge[i] - arc.centre).norm() - arc.radius;
            outside = outside || residual > 1.0;
            if (residual > -kCutInside_px) {
                resultant += (edge[i] - arc.centre).normalized();
                ++onArc;
                use[i] = 0;
            } else {
                use[i] = kOnCut;
                first = std::min(first, i);
                ++inside;
            }
        }
        if (arc.valid && inside > 0 && !outside && restsOnItsArc(arc, onArc, resultant)) {
            // Grow the run from its first point by steps of at most 2 px.
            std::size_t reached = 1;
            use[first] = kReached;
            for (bool grew = true; grew;) {
                grew = false;
                for (std::size_t i = 0; i < edges; ++i) {
                    if (use[i] != kOnCut)
                        continue;
                    for (std::size_t j = 0; j < edges; ++j)
                        if (use[j] == kReached && (edge[i] - edge[j]).squaredNorm() <= 4.0) {
                            use[i] = kReached;
                            ++reached;
                            grew = true;
                            break;
                        }
                }
            }
            if (reached == inside) {
                Blob part = discBlob(arc);
                part.cut = true;
                addCandidate(part, order + 1);
                ++counters_.cutDiscs;
                return true;
            }
        }
    }
    // Within a pixel of disc j's circle or inside it.
    const auto byDisc = [&](std::size_t i, std::size_t j) {
        return (edge[i] - circle[j].centre).norm() <= circle[j].radius + 1.0;
    };
    const auto ownPoint = [&](std::size_t i, std::size_t k) {
        if (std::abs((edge[i] - circle[k].centre).norm() - circle[k].radius) > 1.0)
            return false;
        for (std::size_t j = 0; j < count; ++j)
            if (j != k && byDisc(i, j))
                return false;
        return true;
    };
    const auto refit = [&](std::size_t k) {
        for (int pass = 0; pass < 3; ++pass) {
            for (std::size_t i = 0; i < edges; ++i)
                use[i] = ownPoint(i, k) ? 1 : 0;
            const Circle fitted = fitCircle(edge, use, edges);
            if (!fitted.valid)
                return false;
            circle[k] = fitted;
        }
        return true;
    };
    for (const Peak& peak : discs) {
        circle[count].centre = peak.at;
        circle[count].radius = peak.depth / 3.0 + 0.5;
        ++count;
        if (!refit(count - 1))
            --count;
    }
    while (count > 0 && count < kMaxSplitParts) {
        std::size_t left = 0;
        for (std::size_t i = 0; i < edges; ++i) {
            bool explained = false;
            for (std::size_t k = 0; k < count && !explained; ++k)
                explained = byDisc(i, k);
            use[i] = explained ? 0 : 1;
            left += explained ? 0U : 1U;
        }
        if (left < 8)
            break;
        const Circle fitted = fitCircle(edge, use, edges);
        if (!fitted.valid || fitted.radius < 1.0 || fitted.radius > kSplitSide)
            break;
        circle[count++] = fitted;
        if (!refit(count - 1)) {
            --count;
            break;
        }
    }
    // A circle that fits its points poorly may be two discs far over each other, which make one
    // peak of the distance and no shoulder: the outline no other circle explains is cut in two
    // across its longest spread and each half fitted with a circle; then, eight times, each circle
    // is fitted again to the points on it and away from the other circle.
    const auto unexplainedByOthers = [&](std::size_t i, std::size_t k) {
        for (std::size_t j = 0; j < count; ++j)
            if (j != k && byDisc(i, j))
                return false;
        return true;
    };
    const auto splitInTwo = [&](std::size_t k) {
        Vec2 mean = Vec2::Zero();
        std::size_t n = 0;
        for (std::size_t i = 0; i < edges; ++i)
            if (unexplainedByOthers(i, k)) {
                mean += edge[i];
                ++n;
            }
        if (n < 16)
            return false;
        mean /= static_cast<double>(n);
        Eigen::Matrix2d spread = Eigen::Matrix2d::Zero();
        for (std::size_t i = 0; i < edges; ++i)
            if (unexplainedByOthers(i, k))
                spread += (edge[i] - mean) * (edge[i] - mean).transpose();
        const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> axes(spread);
        const Vec2 across = axes.eigenvectors().col(1);
        std::array<Circle, 2> halves{};
        for (int pass = 0; pass < 8; ++pass) {
            for (std::size_t side = 0; side < 2; ++side) {
                const Circle& other = halves[1 - side];
                for (std::size_t i = 0; i < edges; ++i) {
                    bool mine = unexplainedByOthers(i, k);
                    if (mine && pass == 0)
                        mine = ((edge[i] - mean).dot(across) < 0.0) == (side == 0);
                    else if (mine)
                        mine = std::abs((edge[i] - halves[side].centre).norm() -
                                        halves[side].radius) <= 1.0 &&
                               (edge[i] - other.centre).norm() > other.radius + 1.0;
                    use[i] = mine ? 1 : 0;
                }
                const Circle fitted = fitCircle(edge, use, edges);
                if (!fitted.valid || fitted.radius < 1.0 || fitted.radius > kSplitSide)
                    return false;
                halves[side] = fitted;
            }
        }
        if (halves[0].rms > kSplitFitRms_px || halves[1].rms > kSplitFitRms_px ||
            (halves[0].centre - halves[1].centre).norm() < 1.0)
            return false;
        circle[k] = halves[0];
        circle[count++] = halves[1];
        return true;
    };
    for (std::size_t k = 0; k < count && count < kMaxSplitParts; ++k)
        if (circle[k].rms > kSplitFitRms_px)
            splitInTwo(k);
    if (count < 2)
        return false;
    // A circle left without points of its own (another took them) was no disc: drop it, and fit
    // the others again without it.
    for (std::size_t k = 0; k < count;) {
        if (refit(k)) {
            ++k;
            continue;
        }
        std::copy(circle.begin() + static_cast<std::ptrdiff_t>(k + 1),
                  circle.begin() + static_cast<std::ptrdiff_t>(count),
                  circle.begin() + static_cast<std::ptrdiff_t>(k));
        --count;
        k = 0;
    }
    // One circle is no explanation of a blob that is not round (a streak, an oval glint).
    if (count < 2)
        return false;

    // A part is kept when its circle rests on its own outline points.
    std::array<bool, kMaxSplitParts> trusted{};
    std::size_t parts = 0;
    for (std::size_t k = 0; k < count; ++k) {
        Vec2 resultant = Vec2::Zero();
        std::size_t n = 0;
        for (std::size_t i = 0; i < edges; ++i)
            if (ownPoint(i, k)) {
                resultant += (edge[i] - circle[k].centre).normalized();
                ++n;
            }
        trusted[k] = restsOnItsArc(circle[k], n, resultant);
        parts += trusted[k] ? 1U : 0U;
    }
    if (parts == 0 || parts < minParts)
        return false;
    for (std::size_t k = 0; k < count; ++k) {
        if (!trusted[k])
            continue;
        Blob part = discBlob(circle[k]);
        part.split = true;
        addCandidate(part, order + 1 + static_cast<std::uint32_t>(k));
    }
    ++counters_.splitBlobs;
    counters_.splitParts += parts;
    return true;
}

std::size_t BlobDetector::splitOnLines(const std::uint8_t* pixels, int stride_bytes,
                                       const Blob& blob, std::span<const DiscOnLine> discs,
                                       std::span<Blob> parts, std::span<bool> placed) {
    if (discs.empty() || (discs.size() == 1 && !discs[0].free) || discs.size() > kMaxLineDiscs ||
        parts.size() < discs.size() || placed.size() < discs.size())
        return 0;
    std::fill_n(placed.begin(), discs.size(), false);
    // The blob's own pixels grow from its brightest pixel next to its centre.
    const auto level = [&](int x, int y) {
        return static_cast<int>(pixels[static_cast<std::ptrdiff_t>(y) * stride_bytes + x]);
    };
    int seedX = -1, seedY = -1, seedLevel = config_.threshold - 1;
    const int cx = static_cast<int>(std::lround(blob.centre_px.x()));
    const int cy = static_cast<int>(std::lround(blob.centre_px.y()));
    for (int y = cy - 1; y <= cy + 1; ++y)
        for (int x = cx - 1; x <= cx + 1; ++x)
            if (x >= blob.left && x <= blob.right && y >= blob.top && y <= blob.bottom &&
                level(x, y) > seedLevel) {
                seedX = x;
                seedY = y;
                seedLevel = level(x, y);
            }
    if (seedX < 0)
        return 0;
    // Tried again with other discs, the same blob keeps its outline.
    const Traced key{pixels, blob.left, blob.top, blob.right, blob.bottom, seedX, seedY};
    const std::size_t edges = key == traced_
                                  ? tracedEdges_
                                  : traceOutline(blob.left, blob.top, blob.right, blob.bottom,
                                                 seedX, seedY, pixels, stride_bytes);
    if (edges < 8 * discs.size())
        return 0;
    // Grid coordinates, as traceOutline's; a centre on a line is onLine + at * along.
    const Vec2 origin(blob.left - 1, blob.top - 1);
    const Vec2* edge = splitEdge_.get();
    const std::size_t count = discs.size();
    // A free disc's centre is onLine + at * along + across * normal, from its start along x and y;
    // a line's disc keeps across at zero.
    std::array<Vec2, kMaxLineDiscs> onLine{}, along{};
    std::array<double, kMaxLineDiscs> at{}, across{};
    std::array<Circle, kMaxLineDiscs> circle{};
    const auto movable = [&](std::size_t k) { return !discs[k].fixed && !discs[k].free; };
    const auto placeOf = [&](std::size_t k) {
        return Vec2(onLine[k] + at[k] * along[k] + across[k] * Vec2(-along[k].y(), along[k].x()));
    };
    for (std::size_t k = 0; k < count; ++k) {
        const bool onItsLine = movable(k);
        const double length = discs[k].line.direction.norm();
        if ((onItsLine && !(length > 1e-9)) || !(discs[k].radius_px >= 1.0) ||
            !(discs[k].radius_px < kSplitSide))
            return 0;
        const Vec2 start =
            (discs[k].known || !onItsLine ? discs[k].start_px : blob.centre_px) - origin;
        onLine[k] = onItsLine ? Vec2(discs[k].line.point_px - origin) : start;
        along[k] = onItsLine ? Vec2(discs[k].line.direction / length) : Vec2::UnitX();
        at[k] = onItsLine ? (start - onLine[k]).dot(along[k]) : 0.0;
        circle[k].centre = placeOf(k);
        circle[k].radius = discs[k].radius_px;
    }

    // A disc of unknown place must own some of the outline: points more than a pixel outside
    // every disc already known. A blob that its known discs explain (one disc, with a line of
    // another blob merely crossing it) is left as it is, before the costly scans.
    bool anyKnown = false, anyUnknown = false;
    std::size_t outsideKnown = 0;
    for (std::size_t k = 0; k < count; ++k) {
        const bool known = discs[k].known || !movable(k);
        anyKnown = anyKnown || known;
        anyUnknown = anyUnknown || !known;
    }
    for (std::size_t i = 0; i < edges && anyKnown && anyUnknown; ++i) {
        bool outside = true;
        for (std::size_t k = 0; k < count && outside; ++k)
            outside = !(discs[k].known || !movable(k)) ||
                      (edge[i] - circle[k].centre).norm() > circle[k].radius + 1.0;
        outsideKnown += outside ? 1U : 0U;
    }
    if (anyKnown && anyUnknown && outsideKnown < 5)
        return 0;

    // Each movable centre's place on its line, first by scans over the blob's extent: a place is
    // scored by the outline points' robust residuals (squared, capped at 1 px^2), each point
    // taking the smallest of all circles'. A disc of unknown place is scanned together with the
    // movable disc whose line runs nearest its own (two discs far over each other: one of them
    // alone would sit on both), then every movable disc alone again, so that a guess biased by a
    // disc it hid is set right.
    const int w = blob.right - blob.left + 1, h = blob.bottom - blob.top + 1;
    const Vec2 middle = blob.centre_px - origin;
    const double reach = 0.5 * std::hypot(w, h) + 1.0;
    const std::size_t every = (edges + kLinePoints - 1) / kLinePoints;
    const std::size_t sampled = (edges + every - 1) / every;
    // Rows are scored four points at a time; the points beyond the last score nothing.
    const std::size_t padded = (sampled + 3) & ~std::size_t{3};
    const auto robust = [](double off) { return static_cast<float>(std::min(off * off, 1.0)); };
    // Scratch: the points' smallest residual from the circles not scanned, then one row of
    // residuals for each place of each scanned circle.
    float* others = lineResidual_.get();
    const auto row = [&](std::size_t which, int place) {
        return others + kLinePoints * (1 + which * kLineSteps + static_cast<std::size_t>(place));
    };
    const auto scan = [&](std::size_t k, std::size_t pairedWith) {
        const bool pair = pairedWith < count;
        const int steps = pair ? kPairSteps : kLineSteps;
        const double step = std::max(0.25, 2.0 * reach / (steps - 1));
        std::array<std::size_t, 2> scanned{k, pair ? pairedWith : k};
        std::array<double, 2> first{};
        for (std::size_t which = 0; which < (pair ? 2U : 1U); ++which) {
            const std::size_t d = scanned[which];
            first[which] = (middle - onLine[d]).dot(along[d]) - reach;
            for (int place = 0; place < steps; ++place) {
                const Vec2 centre = onLine[d] + (first[which] + place * step) * along[d];
                float* r = row(which, place);
                for (std::size_t i = 0; i < sampled; ++i)
                    r[i] = robust((edge[i * every] - centre).norm() - circle[d].radius);
                std::fill(r + sampled, r + padded, 0.0F);
            }
        }
        for (std::size_t i = 0; i < sampled; ++i) {
            float smallest = 1.0F;
            for (std::size_t j = 0; j < count; ++j)
                if (j != scanned[0] && j != scanned[1])
                    smallest =
                        std::min(smallest, robust((edge[i * every] - circle[j].centre).norm() -
                                                  circle[j].radius));
            others[i] = smallest;
        }
        std::fill(others + sampled, others + padded, 0.0F);
        float bestCost = std::numeric_limits<float>::infinity();
        std::array<int, 2> best{0, 0};
        for (int p0 = 0; p0 < steps; ++p0)
            for (int p1 = 0; p1 < (pair ? steps : 1); ++p1) {
                const float* r0 = row(0, p0);
                const float* r1 = pair ? row(1, p1) : others;
                const float cost = sumOfSmallest(others, r0, r1, padded);
                if (cost < bestCost) {
                    bestCost = cost;
                    best = {p0, p1};
                }
            }
        for (std::size_t which = 0; which < (pair ? 2U : 1U); ++which) {
            const std::size_t d = scanned[which];
            at[d] = first[which] + best[which] * step;
            circle[d].centre = onLine[d] + at[d] * along[d];
        }
    };
    for (std::size_t k = 0; k < count; ++k) {
        if (discs[k].known || !movable(k))
            continue;
        // The movable disc whose line passes nearest this one's centre guess, if near enough
        // for the two discs to overlap.
        std::size_t nearest = count;
        double nearestOff = std::numeric_limits<double>::infinity();
        const Vec2 guess = onLine[k] + (middle - onLine[k]).dot(along[k]) * along[k];
        for (std::size_t j = 0; j < count; ++j) {
            if (j == k || !movable(j))
                continue;
            const Vec2 toLine = guess - onLine[j];
            const double off = std::abs(toLine.x() * along[j].y() - toLine.y() * along[j].x());
            if (off < discs[k].radius_px + discs[j].radius_px && off < nearestOff) {
                nearestOff = off;
                nearest = j;
            }
        }
        scan(k, nearest);
    }
    for (std::size_t k = 0; k < count; ++k)
        if (movable(k))
            scan(k, count);

    // Then each movable circle is fitted (its place on the line and its radius) to its own
    // points: on it (within 1 px) and outside every other (by more than 1 px). A point is at most
    // one circle's own; its owner is found once a pass.
    constexpr std::uint8_t kNoOwner = 0xFF;
    std::uint8_t* owner = splitMask_.get(); // traceOutline's mask is no longer needed
    const auto findOwners = [&] {
        for (std::size_t i = 0; i < edges; ++i) {
            std::size_t near = 0, nearest = 0;
            double offNearest = 0.0;
            for (std::size_t j = 0; j < count; ++j) {
                const double off = (edge[i] - circle[j].centre).norm() - circle[j].radius;
                if (off <= 1.0) {
                    ++near;
                    nearest = j;
                    offNearest = off;
                }
            }
            // A free disc may be cut by an edge in front of it: its own points are never inside
            // its circle, where a cut runs (see kCutInside_px).
            const double inside = discs[nearest].free ? kFreeDiscInside_px : 1.0;
            owner[i] =
                near == 1 && offNearest >= -inside ? static_cast<std::uint8_t>(nearest) : kNoOwner;
        }
    };
    // The normal equations of circle k's place (along its line, and across it for a free disc)
    // and radius over its own points.
    struct Normal {
        Eigen::Matrix3d jtj = Eigen::Matrix3d::Zero();
        Eigen::Vector3d jtr = Eigen::Vector3d::Zero();
        double sum2 = 0.0;
        std::size_t n = 0;
    };
    const auto normalOf = [&](std::size_t k) {
        Normal e;
        const Vec2 normal(-along[k].y(), along[k].x());
        for (std::size_t i = 0; i < edges; ++i) {
            if (owner[i] != k)
                continue;
            const Vec2 d = edge[i] - circle[k].centre;
            const double length = d.norm();
            if (length < 1e-9)
                continue;
            const Eigen::Vector3d j(-d.dot(along[k]) / length, -d.dot(normal) / length, -1.0);
            const double off = length - circle[k].radius;
            e.jtj += j * j.transpose();
            e.jtr += j * off;
            e.sum2 += off * off;
            ++e.n;
        }
        // The other camera's size of the disc holds the radius where a short arc would trade it
        // for the place on the line.
        e.jtj(2, 2) += kRadiusPrior;
        e.jtr(2) += kRadiusPrior * (circle[k].radius - discs[k].radius_px);
        return e;
    };
    // A disc on its line has no place across it: its normal equations are those of its place
    // along the line and its radius.
    const auto onLineSystem = [](const Normal& e) {
        Eigen::Matrix2d jtj;
        jtj << e.jtj(0, 0), e.jtj(0, 2), e.jtj(2, 0), e.jtj(2, 2);
        return jtj;
    };
    // The change of a disc's place and radius.
    const auto stepOf = [&](std::size_t k, const Normal& e) {
        if (discs[k].free)
            return Eigen::Vector3d(e.jtj.ldlt().solve(-e.jtr));
        const Eigen::Vector2d change =
            onLineSystem(e).ldlt().solve(-Eigen::Vector2d(e.jtr(0), e.jtr(2)));
        return Eigen::Vector3d(change.x(), 0.0, change.y());
    };
    // The variance of its place per unit of its points' variance: along its line, or the larger
    // of x and y for a free disc.
    const auto placeVariance = [&](std::size_t k, const Normal& e) {
        if (!discs[k].free)
            return onLineSystem(e).inverse()(0, 0);
        const Eigen::Matrix3d inverse = e.jtj.inverse();
        return std::max(inverse(0, 0), inverse(1, 1));
    };
    for (int pass = 0; pass < 6; ++pass) {
        findOwners();
        for (std::size_t k = 0; k < count; ++k)
            for (int iteration = 0; iteration < 3 && !discs[k].fixed; ++iteration) {
                const Normal e = normalOf(k);
                if (e.n < 5)
                    break; // judged below
                const Eigen::Vector3d change = stepOf(k, e);
                if (!change.allFinite())
                    return 0;
                at[k] += change.x();
                across[k] += change.y();
                circle[k].radius += change.z();
                circle[k].centre = placeOf(k);
                if (change.squaredNorm() < 1e-8)
                    break;
            }
    }

    // A disc is placed when it rests on an arc of its own and is of about the size expected; each
    // is judged on its own. The discs need not explain the whole outline: a blob of many discs
    // may hold one whose blob in the other image is not among those given (paired elsewhere, or
    // cut), and a disc the detector split off badly may fail; the others are no less sure.
    findOwners();
    std::size_t placedCount = 0;
    for (std::size_t k = 0; k < count; ++k) {
        if (discs[k].fixed)
            continue;
        const Normal e = normalOf(k);
        circle[k].rms = std::sqrt(e.sum2 / static_cast<double>(std::max<std::size_t>(e.n, 1)));
        // The standard error of the place on the line, from the points' scatter (no less than
        // kLineNoise_px) and how the arc's points constrain it.
        const double spread = std::max(circle[k].rms, kLineNoise_px);
        const double placeError = spread * std::sqrt(placeVariance(k, e));
        // A free disc that wandered off its start took another disc's arc.
        bool strayed =
            discs[k].free && std::hypot(at[k], across[k]) > kFreeDiscReach * discs[k].radius_px;
        for (std::size_t j = 0; j < count && discs[k].free; ++j)
            strayed = strayed || (j != k && (circle[j].centre - circle[k].centre).norm() < 1.0);
        if (e.n < 5 || circle[k].rms > kSplitFitRms_px || !(placeError <= kLinePlaceError_px) ||
            circle[k].radius < 0.75 * discs[k].radius_px ||
            circle[k].radius > 1.33 * discs[k].radius_px || strayed)
            continue;
        Blob& part = parts[k];
        part = blob;
        part.centre_px = circle[k].centre + origin;
        part.area_px =
            static_cast<float>(3.14159265358979323846 * circle[k].radius * circle[k].radius);
        part.elongation = 1.0F;
        part.split = true;
        part.cut = false;
        part.fitRms_px = static_cast<float>(circle[k].rms);
        placed[k] = true;
        ++placedCount;
    }
    // Fits of free discs are counted by their caller (MarkerPipeline: markers found where
    // expected); these are splits on lines.
    if (placedCount > 0 &&
        std::none_of(discs.begin(), discs.end(), [](const DiscOnLine& d) { return d.free; }))
        ++counters_.splitOnLines;
    return placedCount;
}

} // namespace edgetrack
