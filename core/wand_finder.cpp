// Finds a straight calibration wand among one camera's blobs by collinearity and perspective.
#include "core/wand_finder.hpp"

#include <algorithm>
#include <cmath>

namespace edgetrack {

WandSpec WandSpec::fromSpacings(std::span<const double> spacings_mm) {
    WandSpec wand;
    if (spacings_mm.empty() || spacings_mm.size() > wand.spacing_mm.size())
        return wand;
    std::copy(spacings_mm.begin(), spacings_mm.end(), wand.spacing_mm.begin());
    wand.markerCount = spacings_mm.size() + 1;
    return wand;
}

bool WandSpec::isValid() const {
    if (markerCount < 2 || markerCount > kMaxWandMarkers)
        return false;
    for (std::size_t k = 0; k + 1 < markerCount; ++k)
        if (!(spacing_mm[k] > 0.0) || !std::isfinite(spacing_mm[k]))
            return false;
    return true;
}

double WandSpec::offset_mm(std::size_t k) const {
    double offset = 0.0;
    for (std::size_t i = 0; i < k && i + 1 < markerCount; ++i)
        offset += spacing_mm[i];
    return offset;
}

bool WandSpec::isSymmetric() const {
    // Within 2% of the length: closer than that, perspective alone can swap the reading.
    const double tolerance = 0.02 * length_mm();
    for (std::size_t k = 0; k + 1 < markerCount; ++k)
        if (std::abs(spacing_mm[k] - spacing_mm[markerCount - 2 - k]) > tolerance)
            return false;
    return true;
}

WandFinder::WandFinder(const WandSpec& wand, const WandFinderConfig& config)
    : wand_(wand)
    , config_(config) {
    valid_ = wand_.isValid() && config_.lineTolerance_px > 0.0 && config_.maxDepthRatio >= 1.0 &&
             config_.depthRatioAgreement >= 1.0 && config_.maxBlobs >= wand_.markerCount &&
             config_.maxBlobs <= ideal_px_.size();
}

std::optional<double> WandFinder::depthRatio(std::span<const double> t, bool reversed) const {
    const double length = wand_.length_mm();
    double lowest = 0.0;
    double highest = 0.0;
    double logSum = 0.0;
    for (std::size_t i = 0; i < t.size(); ++i) {
        const std::size_t k = i + 1;
        // Reversed, the image's first end is the wand's last marker.
        const double s = reversed ? 1.0 - wand_.offset_mm(wand_.markerCount - 1 - k) / length
                                  : wand_.offset_mm(k) / length;
        // From t = s / (s + (1 - s) rho).
        const double rho = s * (1.0 - t[i]) / (t[i] * (1.0 - s));
        if (!(rho > 0.0) || !std::isfinite(rho))
            return std::nullopt;
        lowest = i == 0 ? rho : std::min(lowest, rho);
        highest = i == 0 ? rho : std::max(highest, rho);
        logSum += std::log(rho);
    }
    if (t.empty())
        return 1.0;
    if (highest > lowest * config_.depthRatioAgreement)
        return std::nullopt;
    const double rho = std::exp(logSum / static_cast<double>(t.size()));
    if (rho > config_.maxDepthRatio || rho * config_.maxDepthRatio < 1.0)
        return std::nullopt;
    return rho;
}

std::optional<WandFinder::Candidate>
WandFinder::tryEnds(std::span<const Vec2> ideal_px, std::size_t first, std::size_t last) const {
    const Vec2 a = ideal_px[first];
    const Vec2 along = ideal_px[last] - a;
    const double length_px = along.norm();
    if (length_px < 2.0 * config_.lineTolerance_px)
        return std::nullopt;
    const Vec2 direction = along / length_px;
    const std::size_t inner = wand_.markerCount - 2;

    // The inner markers, sorted by their fraction along the line (insertion: at most six).
    std::array<double, kMaxWandMarkers> t{};
    std::array<std::uint16_t, kMaxWandMarkers> index{};
    std::size_t found = 0;
    for (std::size_t b = 0; b < ideal_px.size(); ++b) {
        if (b == first || b == last)
            continue;
        const Vec2 d = ideal_px[b] - a;
        const double along_px = d.dot(direction);
        const double across_px = std::abs(d.x() * direction.y() - d.y() * direction.x());
        if (across_px > config_.lineTolerance_px || along_px <= 0.0 || along_px >= length_px)
            continue;
        if (found == inner)
            return std::nullopt; // more blobs on the line than the wand has markers
        std::size_t at = found++;
        const double fraction = along_px / length_px;
        for (; at > 0 && t[at - 1] > fraction; --at) {
            t[at] = t[at - 1];
            index[at] = index[at - 1];
        }
        t[at] = fraction;
        index[at] = static_cast<std::uint16_t>(b);
    }
    if (found != inner)
        return std::nullopt;

    const std::span<const double> fractions(t.data(), inner);
    const bool forward = depthRatio(fractions, false).has_value();
    const bool backward = depthRatio(fractions, true).has_value();
    if (!forward && !backward)
        return std::nullopt;

    Candidate candidate;
    candidate.endsAmbiguous = forward && backward;
    // In wand order: forward reads first -> inner -> last; backward the other way.
    const std::size_t n = wand_.markerCount;
    for (std::size_t k = 0; k < n; ++k) {
        std::uint16_t blob;
        if (k == 0)
            blob = static_cast<std::uint16_t>(first);
        else if (k == n - 1)
            blob = static_cast<std::uint16_t>(last);
        else
            blob = index[k - 1];
        candidate.blobIndex[forward ? k : n - 1 - k] = blob;
    }
    return candidate;
}

std::optional<WandSighting> WandFinder::find(const CameraModel& camera, std::span<const Blob> blobs,
                                             WandMiss* miss) {
    ++counters_.images;
    auto refuse = [this, miss](WandMiss why) -> std::optional<WandSighting> {
        if (miss)
            *miss = why;
        switch (why) {
        case WandMiss::TooManyBlobs:
            ++counters_.tooManyBlobs;
            break;
        case WandMiss::Ambiguous:
            ++counters_.ambiguous;
            break;
        default:
            ++counters_.notFound;
            break;
        }
        return std::nullopt;
    };
    if (!valid_ || !camera.isValid())
        return refuse(WandMiss::NotFound);
    if (blobs.size() > config_.maxBlobs)
        return refuse(WandMiss::TooManyBlobs);
    if (blobs.size() < wand_.markerCount)
        return refuse(WandMiss::NotFound);

    // Undistorted, in pixels of the focal length, so that the line tolerance reads in pixels.
    const double focal_px = camera.intrinsics().fx_px;
    std::size_t count = 0;
    for (const Blob& blob : blobs) {
        const std::optional<Vec2> normalized = camera.undistortPixel(blob.centre_px);
        // A blob outside the lens model's range is put far away, each at its own place, so it
        // lies on no line with the others.
        const double away = 1e9 * static_cast<double>(count + 1);
        ideal_px_[count] = normalized ? Vec2(*normalized * focal_px) : Vec2(away, away * away);
        ++count;
    }
    const std::span<const Vec2> ideal(ideal_px_.data(), count);

    std::optional<Candidate> chosen;
    for (std::size_t first = 0; first < count; ++first) {
        for (std::size_t last = first + 1; last < count; ++last) {
            const std::optional<Candidate> candidate = tryEnds(ideal, first, last);
            if (!candidate)
                continue;
            if (chosen)
                return refuse(WandMiss::Ambiguous);
            chosen = candidate;
        }
    }
    if (!chosen)
        return refuse(WandMiss::NotFound);

    WandSighting sighting;
    sighting.markerCount = wand_.markerCount;
    sighting.endsAmbiguous = chosen->endsAmbiguous;
    for (std::size_t k = 0; k < wand_.markerCount; ++k)
        sighting.pixels[k] = blobs[chosen->blobIndex[k]].centre_px;
    ++counters_.found;
    if (miss)
        *miss = WandMiss::None;
    return sighting;
}

} // namespace edgetrack
