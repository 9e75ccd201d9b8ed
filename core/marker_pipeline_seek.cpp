// The marker front end's search for markers of the frame before in blobs of several discs,
// where they are expected.
#include <algorithm>
#include <optional>

#include "core/marker_pipeline.hpp"

namespace edgetrack {

double MarkerPipeline::markerSize(std::size_t m) const {
    const StereoMarker& marker = markers_[m];
    if (marker.carried || marker.blob0 < 0 || marker.blob1 < 0)
        return 0.0;
    double sum = 0.0;
    for (int camera = 0; camera < 2; ++camera) {
        const int blob = camera == 0 ? marker.blob0 : marker.blob1;
        const CameraModel& model = stereo_.rig().camera(camera);
        const Vec3 toPoint = marker.position_rig_mm - model.centre_rig_mm();
        const double pixelsPerRadian = model.pixelsPerRadian(toPoint);
        if (!(pixelsPerRadian > 0.0))
            return 0.0;
        sum += blobs_[index(camera)][static_cast<std::size_t>(blob)].discRadius_px() *
               toPoint.norm() / pixelsPerRadian;
    }
    return 0.5 * sum;
}

double MarkerPipeline::radiusAt(double size_mm, const Vec3& point_rig_mm, int camera) const {
    const CameraModel& model = stereo_.rig().camera(camera);
    const Vec3 toPoint = point_rig_mm - model.centre_rig_mm();
    return size_mm * model.pixelsPerRadian(toPoint) / toPoint.norm();
}

void MarkerPipeline::splitWhereMarkersAreExpected(const std::array<ImageView, 2>& images) {
    constexpr std::size_t kMaxDiscs = BlobDetector::kMaxLineDiscs;
    constexpr int kNone = -1, kNoBlob = -2;
    struct Sought {
        std::size_t last = 0;
        Vec3 expected_rig_mm = Vec3::Zero();
        std::array<Vec2, 2> pixel_px{};
        std::array<double, 2> radius_px{};
        /// Per camera: its blob (its own unpaired one, or a disc placed for it), kNone while
        /// sought, kNoBlob when none is to be had (no blob of several discs where expected).
        std::array<int, 2> blob{kNone, kNone};
        std::array<bool, 2> placed{};
    };
    FixedVector<Sought, kMaxSoughtMarkers> sought;
    // Point last_[i], where it is expected in both images.
    const auto seek = [&](std::size_t i) {
        const LastPoint& last = last_[i];
        if (last.age == 0 || !(last.size_mm > 0.0))
            return;
        for (const Sought& s : sought)
            if (s.last == i)
                return;
        if (sought.size() == sought.capacity()) {
            ++splitAttemptsSkipped_; // not sought for the frame's budget
            return;
        }
        Sought s;
        s.last = i;
        // Its own last step carried on (markers closing in on each other converge), or where its
        // neighbours' steps moved it while it was missing.
        s.expected_rig_mm = last.missing == 0 ? last.expected_rig_mm
                                              : Vec3(last.position_rig_mm + neighboursStep(i));
        for (int camera = 0; camera < 2; ++camera) {
            const CameraModel& model = stereo_.rig().camera(camera);
            const std::optional<Vec2> pixel = model.project(s.expected_rig_mm);
            if (!pixel)
                return;
            s.pixel_px[index(camera)] = *pixel;
            s.radius_px[index(camera)] = radiusAt(last.size_mm, s.expected_rig_mm, camera);
        }
        sought.push_back(s);
    };
    // Any point that continued one before and that no marker continues now, those missing for a
    // few frames too: the disc is measured where it is, the guess only starts the fit.
    const auto seekLost = [&] {
        sought.clear();
        for (std::size_t i = 0; i < last_.size(); ++i)
            if (lastContinued_[i] == 0)
                seek(i);
    };
    seekLost();
    if (sought.empty())
        return;

    // A blob that passed as one disc (\a b of \a camera) and holds a sought point within its
    // radius.
    const auto wholeBlobHolds = [&](std::size_t c, std::size_t b, const Vec2& pixel) {
        const Blob& blob = blobs_[c][b];
        return !blob.split && !blob.cut && (blob.centre_px - pixel).norm() < blob.discRadius_px();
    };
    // A marker whose blob passed as one disc, is larger than the marker was, and holds a sought
    // point is the middle of several discs: it continues no point (its step would move the
    // sought points' neighbours), the point it continued is sought too, and it goes when a disc
    // in its blob is found.
    const auto largerThanItsMarker = [&](std::size_t c, std::size_t b, int m, const Sought& s) {
        const int l = continuesLast_[static_cast<std::size_t>(m)];
        if (l < 0 || !(last_[static_cast<std::size_t>(l)].size_mm > 0.0))
            return blobs_[c][b].discRadius_px() > kOwnBlobSize * s.radius_px[c]; // a new marker
        return blobs_[c][b].discRadius_px() >
               kOwnBlobSize * radiusAt(last_[static_cast<std::size_t>(l)].size_mm,
                                       markers_[static_cast<std::size_t>(m)].position_rig_mm,
                                       static_cast<int>(c));
    };
    FixedVector<int, kMaxSoughtMarkers> wholeMarkers;
    for (const Sought& s : sought)
        for (std::size_t c = 0; c < 2; ++c)
            for (std::size_t b = 0; b < blobs_[c].size(); ++b) {
                const int m = markerOfBlob_[c][b];
                if (m < 0 || !wholeBlobHolds(c, b, s.pixel_px[c]) ||
                    !largerThanItsMarker(c, b, m, s) ||
                    std::find(wholeMarkers.begin(), wholeMarkers.end(), m) != wholeMarkers.end() ||
                    wholeMarkers.size() == wholeMarkers.capacity())
                    continue;
                wholeMarkers.push_back(m);
                if (const int l = continuesLast_[static_cast<std::size_t>(m)]; l >= 0) {
                    lastContinued_[static_cast<std::size_t>(l)] = 0;
                    lastStep_[static_cast<std::size_t>(l)] = Vec3::Zero();
                }
            }
    if (!wholeMarkers.empty())
        seekLost();

    // Per camera and sought marker, the whole marker whose blob its disc was placed in.
    std::array<std::array<int, kMaxSoughtMarkers>, 2> wholeMarkerOf{};
    for (auto& of : wholeMarkerOf)
        of.fill(kNone);
    std::size_t attemptsLeft = kMaxSplitAttempts;
    for (int camera = 0; camera < 2; ++camera) {
        const std::size_t c = index(camera);
        BoundedVector<Blob>& blobs = blobs_[c];
        // The blob that may hide sought marker \a s: parts of a split blob (one of them into
        // \a at), a blob refused as not round (\a at -1), or a blob that passed as one disc.
        const auto coverAt = [&](const Sought& s, Blob& cover, int& at) {
            const Vec2& pixel = s.pixel_px[c];
            if (mergedBlobAt(camera, pixel, at, &cover))
                return true;
            // A blob that passed as one disc holds several when it is larger than its marker
            // (wholeMarkers) or, without one, than the marker sought in it.
            for (std::size_t b = 0; b < blobs.size(); ++b) {
                const int m = markerOfBlob_[c][b];
                if (wholeBlobHolds(c, b, pixel) &&
                    (m >= 0 ? std::find(wholeMarkers.begin(), wholeMarkers.end(), m) !=
                                  wholeMarkers.end()
                            : blobs[b].discRadius_px() > kOwnBlobSize * s.radius_px[c])) {
                    cover = blobs[b];
                    at = static_cast<int>(b);
                    return true;
                }
            }
            return false;
        };
        // Its own unpaired blob where it is expected, no larger than it was (two discs far over
        // each other make one blob larger than either), or a blob that may hide it.
        for (Sought& s : sought) {
            const double near_px = 0.5 * s.radius_px[c];
            for (std::size_t b = 0; b < blobs.size() && s.blob[c] == kNone; ++b)
                if (markerOfBlob_[c][b] < 0 &&
                    (blobs[b].centre_px - s.pixel_px[c]).norm() < near_px &&
                    blobs[b].discRadius_px() < kOwnBlobSize * s.radius_px[c])
                    s.blob[c] = static_cast<int>(b);
            Blob cover;
            int at = kNone;
            if (s.blob[c] == kNone && !coverAt(s, cover, at))
                s.blob[c] = kNoBlob;
        }
        // Each such blob, fitted once with all the sought markers in it.
        for (std::size_t first = 0; first < sought.size(); ++first) {
            if (sought[first].blob[c] != kNone)
                continue;
            Blob target;
            int at = kNone;
            coverAt(sought[first], target, at);
            std::array<DiscOnLine, kMaxDiscs> discs{};
            std::array<std::size_t, kMaxDiscs> soughtOf{};
            std::array<std::size_t, kMaxDiscs> memberBlob{};
            std::size_t count = 0;
            // A split blob's parts and the sought markers in it, each free to move: a part's
            // centre was pulled by the disc hidden in it.
            for (std::size_t b = 0; target.split && b < blobs.size() && count < kMaxDiscs; ++b)
                if (partsOfOneBlob(blobs[b], target)) {
                    discs[count].start_px = blobs[b].centre_px;
                    discs[count].radius_px = blobs[b].discRadius_px();
                    discs[count].free = true;
                    memberBlob[count] = b;
                    soughtOf[count++] = sought.size();
                }
            const std::size_t members = count;
            for (std::size_t k = first; k < sought.size() && count < kMaxDiscs; ++k) {
                Sought& s = sought[k];
                if (s.blob[c] != kNone || !boundsHold(target, s.pixel_px[c]))
                    continue;
                s.blob[c] = kNoBlob; // fitted now, placed or not
                discs[count].start_px = s.pixel_px[c];
                discs[count].radius_px = s.radius_px[c];
                discs[count].free = true;
                soughtOf[count++] = k;
            }
            if (count == members || attemptsLeft == 0) {
                splitAttemptsSkipped_ += count > members && attemptsLeft == 0 ? 1U : 0U;
                continue;
            }
            --attemptsLeft;
            std::array<Blob, kMaxDiscs> parts{};
            std::array<bool, kMaxDiscs> placed{};
            if (detectors_[c].splitOnLines(images[c].pixels, images[c].stride_bytes, target,
                                           std::span(discs.data(), count),
                                           std::span(parts.data(), count),
                                           std::span(placed.data(), count)) == 0)
                continue;
            // The marker of a blob taken as one disc, which goes if a disc in it is found.
            int whole = kNone;
            if (!target.split && at >= 0)
                if (const auto w = std::find(wholeMarkers.begin(), wholeMarkers.end(),
                                             markerOfBlob_[c][static_cast<std::size_t>(at)]);
                    w != wholeMarkers.end())
                    whole = static_cast<int>(w - wholeMarkers.begin());
            bool added = false;
            for (std::size_t k = members; k < count; ++k) {
                if (!placed[k] || blobs.size() == blobs.capacity())
                    continue;
                Sought& s = sought[soughtOf[k]];
                blobs.push_back(parts[k]);
                markerOfBlob_[c][blobs.size() - 1] = kNone;
                s.blob[c] = static_cast<int>(blobs.size() - 1);
                s.placed[c] = true;
                if (whole >= 0)
                    wholeMarkerOf[c][soughtOf[k]] = whole;
                added = true;
            }
            // With a disc found in it, each part is centred anew; its marker follows when it
            // still passes stereo's checks.
            for (std::size_t k = 0; k < members && added; ++k) {
                const std::size_t b = memberBlob[k];
                const int m = markerOfBlob_[c][b];
                if (!placed[k])
                    continue;
                if (m < 0) {
                    blobs[b] = parts[k];
                    continue;
                }
                StereoMarker& marker = markers_[static_cast<std::size_t>(m)];
                const int partner = camera == 0 ? marker.blob1 : marker.blob0;
                StereoMarker moved;
                if (partner < 0 ||
                    !pairBlobs(camera, parts[k], static_cast<int>(b),
                               blobs_[index(1 - camera)][static_cast<std::size_t>(partner)],
                               partner, moved))
                    continue;
                blobs[b] = parts[k];
                marker = moved;
            }
        }
    }

    // Each sought marker with a disc placed in one image and a blob in the other, when it lands
    // where it was expected and no other marker is there (but one that goes).
    const double reach_mm = config_.stereo.continuity_mm;
    const std::size_t before = markers_.size();
    std::array<bool, kMaxSoughtMarkers> dropWhole{};
    const auto goes = [&](std::size_t m) {
        return std::find(wholeMarkers.begin(), wholeMarkers.end(), static_cast<int>(m)) !=
               wholeMarkers.end();
    };
    for (std::size_t k = 0; k < sought.size(); ++k) {
        const Sought& s = sought[k];
        if (!(s.placed[0] || s.placed[1]) || s.blob[0] < 0 || s.blob[1] < 0 ||
            markers_.size() == markers_.capacity() ||
            markerOfBlob_[0][static_cast<std::size_t>(s.blob[0])] >= 0 ||
            markerOfBlob_[1][static_cast<std::size_t>(s.blob[1])] >= 0)
            continue;
        StereoMarker marker;
        if (!pairBlobs(0, s.blob[0], s.blob[1], marker) ||
            (marker.position_rig_mm - s.expected_rig_mm).norm() > reach_mm)
            continue;
        const bool inWholeBlob = wholeMarkerOf[0][k] >= 0 || wholeMarkerOf[1][k] >= 0;
        bool taken = false;
        for (std::size_t m = 0; m < markers_.size(); ++m)
            taken = taken ||
                    ((markers_[m].position_rig_mm - marker.position_rig_mm).norm() <= reach_mm &&
                     !(inWholeBlob && m < before && goes(m)));
        if (taken)
            continue;
        for (const auto& of : wholeMarkerOf)
            if (of[k] >= 0)
                dropWhole[static_cast<std::size_t>(of[k])] = true;
        markers_.push_back(marker);
        markerOfBlob_[0][static_cast<std::size_t>(s.blob[0])] =
            static_cast<int>(markers_.size() - 1);
        markerOfBlob_[1][static_cast<std::size_t>(s.blob[1])] =
            static_cast<int>(markers_.size() - 1);
        continuesLast_.push_back(static_cast<int>(s.last));
        ++markersSplitWhereExpected_;
    }
    // The markers that were blobs of several discs go; the others continue their points again.
    bool dropped = false;
    for (std::size_t w = 0; w < wholeMarkers.size(); ++w) {
        const auto m = static_cast<std::size_t>(wholeMarkers[w]);
        if (dropWhole[w]) {
            continuesLast_[m] = kDroppedMarker;
            dropped = true;
        } else if (const int at = continuesLast_[m]; at >= 0) {
            lastContinued_[static_cast<std::size_t>(at)] = 1;
            lastStep_[static_cast<std::size_t>(at)] =
                markers_[m].position_rig_mm - last_[static_cast<std::size_t>(at)].position_rig_mm;
        }
    }
    for (std::size_t m = before; m < markers_.size(); ++m) {
        const auto at = static_cast<std::size_t>(continuesLast_[m]);
        lastContinued_[at] = 1;
        lastStep_[at] = markers_[m].position_rig_mm - last_[at].position_rig_mm;
    }
    if (!dropped)
        return;
    std::size_t kept = 0;
    for (std::size_t m = 0; m < markers_.size(); ++m)
        if (continuesLast_[m] != kDroppedMarker) {
            markers_[kept] = markers_[m];
            continuesLast_[kept++] = continuesLast_[m];
        }
    markers_.resize(kept);
    continuesLast_.resize(kept);
    indexMarkersByBlob();
}

} // namespace edgetrack
