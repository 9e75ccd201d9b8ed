// Blob detection in 8-bit IR frames: NEON threshold scan, run-based connected components, moments.
#include "core/blob_detector.hpp"

#include <algorithm>
#include <bit>
#include <cmath>

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
} // namespace

// Sums over a component's pixels; exact integers, so merging components loses nothing.
struct BlobDetector::Moments {
    std::int64_t count = 0;
    std::int64_t sumI = 0, sumIx = 0, sumIy = 0;
    std::int64_t sumX = 0, sumY = 0, sumXX = 0, sumYY = 0, sumXY = 0;
    int left = 0, right = 0, top = 0, bottom = 0;
    int peak = 0;

    void add(const Moments& o) {
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
    candidates_ = BoundedVector<Candidate>(config.maxLabels);
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
    emitBlobs(out, expected_px);
}

void BlobDetector::emitBlobs(BoundedVectorView<Blob>& out, std::span<const Vec2> expected_px) {
    candidates_.clear();
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
        // Shape from the pixel distribution (unweighted: the saturated core carries no shape);
        // +1/12 is each pixel's own extent.
        const double n = static_cast<double>(m.count);
        const double meanX = static_cast<double>(m.sumX) / n;
        const double meanY = static_cast<double>(m.sumY) / n;
        const double xx = static_cast<double>(m.sumXX) / n - meanX * meanX + 1.0 / 12.0;
        const double yy = static_cast<double>(m.sumYY) / n - meanY * meanY + 1.0 / 12.0;
        const double xy = static_cast<double>(m.sumXY) / n - meanX * meanY;
        const double half = 0.5 * (xx + yy);
        const double spread = std::sqrt(0.25 * (xx - yy) * (xx - yy) + xy * xy);
        const double major = half + spread, minor = std::max(half - spread, 1e-9);
        const double elongation = std::sqrt(major / minor);
        // A uniform ellipse with these moments covers 4 pi sqrt(major * minor) pixels.
        const double fill = n / (4.0 * 3.14159265358979323846 * std::sqrt(major * minor));
        if (elongation > config_.maxElongation || fill < config_.minFill) {
            ++counters_.rejectedNotRound;
            continue;
        }
        Candidate* const candidate = candidates_.append(); // it holds as many as there are labels
        if (candidate == nullptr) {
            ++counters_.blobOverflow;
            continue;
        }
        Candidate& c = *candidate;
        Blob& blob = c.blob;
        const double weight = static_cast<double>(m.sumI);
        blob.centre_px = {static_cast<double>(m.sumIx) / weight,
                          static_cast<double>(m.sumIy) / weight};
        blob.area_px = static_cast<float>(n);
        blob.elongation = static_cast<float>(elongation);
        blob.left = static_cast<std::uint16_t>(m.left);
        blob.right = static_cast<std::uint16_t>(m.right);
        blob.top = static_cast<std::uint16_t>(m.top);
        blob.bottom = static_cast<std::uint16_t>(m.bottom);
        blob.peak = static_cast<std::uint8_t>(m.peak);
        c.order = static_cast<std::uint32_t>(label);
    }

    const std::size_t room = out.capacity();
    if (candidates_.size() > room) {
        // More than fit: the blobs near an expected centre first (nearest first), then the
        // roundest; labels break ties, so the choice is a function of the image alone.
        counters_.blobOverflow += candidates_.size() - room;
        const double near2 = config_.keepNear_px * config_.keepNear_px;
        for (Candidate& c : candidates_) {
            double nearest2 = near2;
            for (const Vec2& e : expected_px)
                nearest2 = std::min(nearest2, (c.blob.centre_px - e).squaredNorm());
            c.group = nearest2 < near2 ? 0 : 1;
            c.key = c.group == 0 ? nearest2 : static_cast<double>(c.blob.elongation);
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

} // namespace edgetrack
