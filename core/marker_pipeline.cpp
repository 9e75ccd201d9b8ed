// The marker front end: both cameras' blob detection and stereo correspondence, images to 3D
// points.
#include "core/marker_pipeline.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <optional>

#include "core/triangulation.hpp"

namespace edgetrack {

MarkerPipeline::MarkerPipeline(const StereoRig& rig, const MarkerPipelineConfig& config)
    : config_(config)
    , width_px_(rig.camera(0).intrinsics().width_px)
    , height_px_(rig.camera(0).intrinsics().height_px)
    , detectors_{BlobDetector(config.blobs, width_px_, height_px_),
                 BlobDetector(config.blobs, width_px_, height_px_)}
    , blobs_{BoundedVector<Blob>(config.blobs.maxBlobs), BoundedVector<Blob>(config.blobs.maxBlobs)}
    , expected_px_{BoundedVector<Vec2>(config.blobs.maxBlobs),
                   BoundedVector<Vec2>(config.blobs.maxBlobs)}
    , stereo_(rig, config.stereo, config.blobs.maxBlobs)
    , markers_(config.stereo.maxMarkers)
    , points_rig_mm_(config.stereo.maxMarkers)
    , last_(config.stereo.maxMarkers)
    , current_(config.stereo.maxMarkers)
    , continuation_mm_(config.stereo.maxMarkers)
    , rectified_px_{BoundedVector<Vec2>(config.blobs.maxBlobs),
                    BoundedVector<Vec2>(config.blobs.maxBlobs)}
    , lastContinued_(config.stereo.maxMarkers)
    , lastStep_(config.stereo.maxMarkers)
    , continuesLast_(config.stereo.maxMarkers)
    , unpairedRays_{BoundedVector<UnpairedRay>(config.blobs.maxBlobs),
                    BoundedVector<UnpairedRay>(config.blobs.maxBlobs)}
    , markerOfBlob_{std::make_unique<int[]>(config.blobs.maxBlobs),
                    std::make_unique<int[]>(config.blobs.maxBlobs)} {
    if (rig.camera(1).intrinsics().width_px != width_px_ ||
        rig.camera(1).intrinsics().height_px != height_px_)
        error_ = "the rig's two cameras must have the same image size";
    else if (!detectors_[0].isValid())
        error_ = "[blobs] settings are unusable for the rig's image size";
    else if (!stereo_.isValid())
        error_ = "[stereo] settings are unusable for the rig";
}

void MarkerPipeline::detectBlobs(int camera, const std::uint8_t* pixels, int stride_bytes) {
    detectors_[index(camera)].detect(pixels, stride_bytes, blobs_[index(camera)],
                                     expected_px_[index(camera)].span());
}

void MarkerPipeline::clearExpected() {
    for (BoundedVector<Vec2>& expected : expected_px_)
        expected.clear();
}

void MarkerPipeline::expect(const Vec3& marker_rig_mm) {
    for (std::size_t camera = 0; camera < 2; ++camera)
        if (const std::optional<Vec2> pixel =
                stereo_.rig().camera(static_cast<int>(camera)).project(marker_rig_mm))
            expected_px_[camera].push_back(*pixel);
}

void MarkerPipeline::matchStereo(StereoMethod method, const std::array<ImageView, 2>& images) {
    if (method == StereoMethod::EpipolarOnly)
        stereo_.matchEpipolarOnly(blobs_[0].span(), blobs_[1].span(), markers_);
    else
        stereo_.match(blobs_[0].span(), blobs_[1].span(), markers_);
    indexMarkersByBlob();
    if (method == StereoMethod::Svd && config_.stereo.continuity_mm > 0.0)
        preferContinuingPairs(false);
    if (method == StereoMethod::Svd && config_.blobs.splitMerged && images[0].pixels != nullptr &&
        images[1].pixels != nullptr)
        splitOnEpipolarLines(images);
    // The split pass pairs the discs of merged blobs, two markers on one epipolar line in both
    // images crosswise as readily as the matcher does: its pairs are looked at again.
    if (method == StereoMethod::Svd && config_.stereo.continuity_mm > 0.0)
        preferContinuingPairs(true);
    if (config_.stereo.continuity_mm > 0.0)
        noteContinuedPoints();
    if (method == StereoMethod::Svd && config_.stereo.continuity_mm > 0.0 &&
        config_.stereo.seekExpectedMarkers && config_.blobs.splitMerged &&
        images[0].pixels != nullptr && images[1].pixels != nullptr)
        splitWhereMarkersAreExpected(images);
    if (method == StereoMethod::Svd && config_.stereo.continuity_mm > 0.0 &&
        config_.stereo.maxCarriedFrames > 0)
        carryHiddenMarkers(images);
    points_rig_mm_.clear();
    for (const StereoMarker& marker : markers_)
        points_rig_mm_.push_back(marker.position_rig_mm);
    if (config_.stereo.continuity_mm > 0.0)
        rememberForContinuity();
}

void MarkerPipeline::rememberForContinuity() {
    // How long each point has continued a point of the frame before, and where it is expected in
    // the next; then this frame becomes the last one, in order of expected x.
    current_.clear();
    for (std::size_t m = 0; m < points_rig_mm_.size(); ++m) {
        const Vec3& point = points_rig_mm_[m];
        LastPoint next{point, point, 0, 0, 0, markerSize(m)};
        if (const int at = continuesLast_[m]; at >= 0) {
            const LastPoint& last = last_[static_cast<std::size_t>(at)];
            next.age = last.age + 1;
            if (last.missing == 0)
                next.expected_rig_mm = point + (point - last.position_rig_mm);
            next.carried = markers_[m].carried ? last.carried + 1 : 0;
            if (next.size_mm == 0.0)
                next.size_mm = last.size_mm;
        }
        current_.push_back(next);
    }
    // A point nothing continues is kept for kMaxMissingFrames, moved as its neighbours move, so
    // that a marker found again after hiding in both images goes on with its age.
    for (std::size_t i = 0; i < last_.size(); ++i) {
        const LastPoint& last = last_[i];
        if (lastContinued_[i] != 0 || last.missing >= kMaxMissingFrames ||
            current_.size() == current_.capacity())
            continue;
        LastPoint vanished = last;
        vanished.position_rig_mm += neighboursStep(i);
        vanished.expected_rig_mm = vanished.position_rig_mm;
        vanished.carried = 0;
        ++vanished.missing;
        current_.push_back(vanished);
    }
    std::sort(current_.begin(), current_.end(), [](const LastPoint& a, const LastPoint& b) {
        return a.expected_rig_mm.x() < b.expected_rig_mm.x();
    });
    std::swap(last_, current_);
}

template <typename Visit>
void MarkerPipeline::forEachUnpaired(int camera, Visit visit) const {
    const std::size_t own = index(camera);
    for (std::size_t u = 0; u < blobs_[own].size(); ++u) {
        Ray ray;
        Vec2 rectified;
        if (markerOfBlob_[own][u] < 0 &&
            stereo_.preparedBlob(camera, static_cast<int>(u), ray, rectified))
            visit(static_cast<int>(u), rectified);
    }
}

double MarkerPipeline::crossingOff(int camera, const Vec2& rectified_px,
                                   const Vec2& targetRectified_px, double rowReach_px,
                                   double disparityMargin_px) const {
    const double off = std::abs(targetRectified_px.y() - rectified_px.y());
    const double disparity = camera == 0 ? rectified_px.x() - targetRectified_px.x()
                                         : targetRectified_px.x() - rectified_px.x();
    return off <= rowReach_px && stereo_.admissibleDisparity(disparity, disparityMargin_px)
               ? off
               : std::numeric_limits<double>::infinity();
}

void MarkerPipeline::indexMarkersByBlob() {
    for (std::size_t c = 0; c < 2; ++c)
        std::fill_n(markerOfBlob_[c].get(), blobs_[c].size(), -1);
    for (std::size_t m = 0; m < markers_.size(); ++m) {
        markerOfBlob_[0][static_cast<std::size_t>(markers_[m].blob0)] = static_cast<int>(m);
        markerOfBlob_[1][static_cast<std::size_t>(markers_[m].blob1)] = static_cast<int>(m);
    }
}

double MarkerPipeline::distanceToLastFrame(const Vec3& point_rig_mm,
                                           std::size_t* nearestIndex) const {
    // Only points within reach count: those expected within reach in x, a window of the sorted
    // list.
    const double reach_mm = config_.stereo.continuity_mm;
    const auto first =
        std::lower_bound(last_.begin(), last_.end(), point_rig_mm.x() - reach_mm,
                         [](const LastPoint& p, double x) { return p.expected_rig_mm.x() < x; });
    double nearest = std::numeric_limits<double>::infinity();
    for (auto it = first;
         it != last_.end() && it->expected_rig_mm.x() <= point_rig_mm.x() + reach_mm; ++it) {
        const double d = (it->expected_rig_mm - point_rig_mm).squaredNorm();
        if (d < nearest) {
            nearest = d;
            if (nearestIndex != nullptr)
                *nearestIndex = static_cast<std::size_t>(it - last_.begin());
        }
    }
    return std::sqrt(nearest);
}

bool MarkerPipeline::pairBlobs(int camera, const Blob& blob, int at, const Blob& otherBlob,
                               int otherAt, StereoMarker& marker) {
    return camera == 0 ? stereo_.triangulateBlobs(blob, at, otherBlob, otherAt, marker)
                       : stereo_.triangulateBlobs(otherBlob, otherAt, blob, at, marker);
}

bool MarkerPipeline::pairBlobs(int camera, int blob, int otherBlob, StereoMarker& marker) {
    return pairBlobs(camera, blobs_[index(camera)][static_cast<std::size_t>(blob)], blob,
                     blobs_[index(1 - camera)][static_cast<std::size_t>(otherBlob)], otherBlob,
                     marker);
}

double MarkerPipeline::continuedDistance(const Vec3& point_rig_mm, std::size_t m, int n) const {
    constexpr double kNone = std::numeric_limits<double>::infinity();
    std::size_t last = 0;
    const double distance_mm = distanceToLastFrame(point_rig_mm, &last);
    if (!(distance_mm <= config_.stereo.continuity_mm) || last_[last].age + 1 < kMinContinuedFrames)
        return kNone;
    // A point of the last frame that another of this frame's markers continues is taken: two
    // markers continuing one would be one marker and a ghost beside it.
    const Vec3& predicted_mm = last_[last].expected_rig_mm;
    for (std::size_t other = 0; other < markers_.size(); ++other)
        if (other != m && static_cast<int>(other) != n &&
            (markers_[other].position_rig_mm - predicted_mm).norm() <= distance_mm)
            return kNone;
    return distance_mm;
}

void MarkerPipeline::preferContinuingPairs(bool afterSplit) {
    if (last_.empty())
        return;
    const double reach_mm = config_.stereo.continuity_mm;
    const double band_px = config_.stereo.epipolarBand_sigmas * config_.stereo.sigmaEpipolar_px;
    // What a marker costs the frame's continuity: how far it lies from where a point of the last
    // frame was expected, or the whole reach for one that continues none.
    const auto cost = [&](double distance_mm) { return std::min(distance_mm, reach_mm); };
    continuation_mm_.clear();
    for (const StereoMarker& marker : markers_)
        continuation_mm_.push_back(cost(distanceToLastFrame(marker.position_rig_mm)));
    // Every blob's place in rectified coordinates: stereo's, which it prepared from the blobs as
    // they stand right after it; after the split pass, from each centre now, as stereo has
    // prepared none for the parts the split added and a member centred anew has left its own.
    for (int camera = 0; camera < 2; ++camera) {
        BoundedVector<Vec2>& rectified = rectified_px_[index(camera)];
        rectified.clear();
        for (std::size_t b = 0; b < blobs_[index(camera)].size(); ++b) {
            Ray ray;
            Vec2 prepared;
            std::optional<Vec2> place;
            if (!afterSplit) {
                if (stereo_.preparedBlob(camera, static_cast<int>(b), ray, prepared))
                    place = prepared;
            } else if (const std::optional<Ray> fresh =
                           stereo_.rig().camera(camera).ray(blobs_[index(camera)][b].centre_px)) {
                place = stereo_.rig().rectifyDirection(fresh->direction_rig);
            }
            rectified.push_back(place ? *place
                                      : Vec2::Constant(std::numeric_limits<double>::quiet_NaN()));
        }
    }
    const auto placeOf = [&](int camera, int blob) -> const Vec2& {
        return rectified_px_[index(camera)][static_cast<std::size_t>(blob)];
    };
    for (std::size_t m = 0; m < markers_.size(); ++m) {
        // An exchange must gain more than kContinuityMargin_mm over both markers' costs, so one
        // whose cost is below half of it is left to its partner in the exchange to look at.
        if (continuation_mm_[m] <= 0.5 * kContinuityMargin_mm)
            continue;
        // In either camera, another blob on the epipolar line of its blob in the other camera
        // may be the partner that continues a point better: a blob without a partner, or the
        // blob of another marker, which then takes this marker's blob in exchange (two markers
        // on one line, paired crosswise: a ghost in front and one behind, which may go on from
        // frame to frame as smoothly as markers do, but not as closely as the two markers).
        struct Choice {
            double gain_mm = kContinuityMargin_mm;
            double cost_mm = 0.0, otherCost_mm = 0.0;
            StereoMarker marker, other;
            int camera = -1, given = -1, taken = -1, n = -1;
        } best;
        for (int camera = 0; camera < 2; ++camera) {
            const StereoMarker& marker = markers_[m];
            const int own = camera == 0 ? marker.blob0 : marker.blob1;
            const int kept = camera == 0 ? marker.blob1 : marker.blob0;
            const Vec2& keptRectified = placeOf(1 - camera, kept);
            if (!keptRectified.allFinite())
                continue;
            for (std::size_t u = 0; u < blobs_[index(camera)].size(); ++u) {
                const int blob = static_cast<int>(u);
                const Vec2& rectified = placeOf(camera, blob);
                const int n = markerOfBlob_[index(camera)][u];
                if (blob == own || !rectified.allFinite() ||
                    !(crossingOff(camera, rectified, keptRectified, band_px, 0.0) <
                      std::numeric_limits<double>::infinity()))
                    continue;
                Choice choice;
                if (!pairBlobs(camera, blob, kept, choice.marker))
                    continue;
                choice.cost_mm = continuedDistance(choice.marker.position_rig_mm, m, n);
                if (!(choice.cost_mm <= reach_mm))
                    continue; // the new pair must continue a point
                double before_mm = continuation_mm_[m];
                if (n >= 0) {
                    const StereoMarker& other = markers_[static_cast<std::size_t>(n)];
                    if (!pairBlobs(camera, own, camera == 0 ? other.blob1 : other.blob0,
                                   choice.other))
                        continue;
                    // The other marker need not continue anything: it may have come into
                    // view as this one's partner hid it.
                    choice.otherCost_mm =
                        cost(continuedDistance(choice.other.position_rig_mm,
                                               static_cast<std::size_t>(n), static_cast<int>(m)));
                    before_mm += continuation_mm_[static_cast<std::size_t>(n)];
                }
                choice.gain_mm = before_mm - choice.cost_mm - choice.otherCost_mm;
                if (choice.gain_mm > best.gain_mm) {
                    choice.camera = camera;
                    choice.given = own;
                    choice.taken = blob;
                    choice.n = n;
                    best = choice;
                }
            }
        }
        if (best.camera < 0)
            continue;
        const std::size_t own = index(best.camera);
        markers_[m] = best.marker;
        markerOfBlob_[own][static_cast<std::size_t>(best.taken)] = static_cast<int>(m);
        markerOfBlob_[own][static_cast<std::size_t>(best.given)] = best.n;
        continuation_mm_[m] = best.cost_mm;
        ++pairsForContinuity_;
        if (best.n >= 0) {
            markers_[static_cast<std::size_t>(best.n)] = best.other;
            continuation_mm_[static_cast<std::size_t>(best.n)] = best.otherCost_mm;
            ++pairsForContinuity_;
        }
    }
}

bool MarkerPipeline::mergedBlobAt(int camera, const Vec2& pixel_px, int& blob, Blob* cover) const {
    // Parts of a split blob keep the whole blob's bounds.
    const BoundedVector<Blob>& blobs = blobs_[index(camera)];
    for (std::size_t b = 0; b < blobs.size(); ++b)
        if (blobs[b].split && boundsHold(blobs[b], pixel_px)) {
            blob = static_cast<int>(b);
            if (cover != nullptr)
                *cover = blobs[b];
            return true;
        }
    blob = -1;
    for (const Blob& refused : detectors_[index(camera)].refused())
        if (boundsHold(refused, pixel_px)) {
            if (cover != nullptr)
                *cover = refused;
            return true;
        }
    return false;
}

bool MarkerPipeline::nearerMarkerCovers(int camera, const Vec2& pixel_px, const Vec3& point_rig_mm,
                                        double size_mm, int& blob) const {
    const BoundedVector<Blob>& blobs = blobs_[index(camera)];
    const Vec3 centre_rig_mm = stereo_.rig().camera(camera).centre_rig_mm();
    const double range_mm = (point_rig_mm - centre_rig_mm).norm();
    // Of unknown size (size_mm 0), the point's centre at least must lie so within the disc.
    const double radius_px = radiusAt(size_mm, point_rig_mm, camera);
    for (std::size_t b = 0; b < blobs.size(); ++b) {
        const int marker = markerOfBlob_[index(camera)][b];
        if (marker < 0 || blobs[b].split ||
            (blobs[b].centre_px - pixel_px).norm() + radius_px >
                blobs[b].discRadius_px() + kHiddenDiscMargin_px)
            continue;
        const StereoMarker& front = markers_[static_cast<std::size_t>(marker)];
        if (!front.carried && (front.position_rig_mm - centre_rig_mm).norm() < range_mm) {
            blob = static_cast<int>(b);
            return true;
        }
    }
    return false;
}

Vec3 MarkerPipeline::neighboursStep(std::size_t hidden) const {
    // Weighted by nearness, so that the markers of its own object count most where objects pass
    // each other.
    const Vec3& from_rig_mm = last_[hidden].position_rig_mm;
    Vec3 sum_mm = Vec3::Zero();
    double weights = 0.0;
    for (std::size_t j = 0; j < last_.size(); ++j) {
        const double distance_mm = (last_[j].position_rig_mm - from_rig_mm).norm();
        if (lastContinued_[j] == 0 || distance_mm > kNeighbourhood_mm)
            continue;
        const double weight = 1.0 / (distance_mm + 5.0);
        sum_mm += weight * lastStep_[j];
        weights += weight;
    }
    return weights > 0.0 ? Vec3(sum_mm / weights) : Vec3::Zero();
}

void MarkerPipeline::noteContinuedPoints() {
    lastContinued_.clear();
    lastStep_.clear();
    for (std::size_t i = 0; i < last_.size(); ++i) {
        lastContinued_.push_back(0);
        lastStep_.push_back(Vec3::Zero());
    }
    continuesLast_.clear();
    for (const StereoMarker& marker : markers_) {
        std::size_t at = 0;
        const bool continues =
            distanceToLastFrame(marker.position_rig_mm, &at) <= config_.stereo.continuity_mm;
        continuesLast_.push_back(continues ? static_cast<int>(at) : -1);
        if (continues) {
            lastContinued_[at] = 1;
            lastStep_[at] = marker.position_rig_mm - last_[at].position_rig_mm;
        }
    }
}

void MarkerPipeline::carryHiddenMarkers(const std::array<ImageView, 2>& images) {
    const double reach_mm = config_.stereo.continuity_mm;
    const std::size_t before = markers_.size();
    // The rays of the blobs without a partner, from their centres now: stereo prepared none for
    // the parts that the splits added after it ran, and a part centred anew has left its own.
    for (int camera = 0; camera < 2; ++camera) {
        BoundedVector<UnpairedRay>& rays = unpairedRays_[index(camera)];
        rays.clear();
        const BoundedVector<Blob>& blobs = blobs_[index(camera)];
        for (std::size_t u = 0; u < blobs.size(); ++u)
            if (markerOfBlob_[index(camera)][u] < 0)
                if (const std::optional<Ray> ray =
                        stereo_.rig().camera(camera).ray(blobs[u].centre_px))
                    rays.push_back({static_cast<int>(u), *ray});
    }
    for (std::size_t i = 0; i < last_.size(); ++i) {
        const LastPoint& last = last_[i];
        // A point missing from the last frame is not carried: where it is now is a guess from
        // steps over several frames, and carried on that guess 13 points of touching seed 1 lay
        // 3-5 mm off (gap of up to 5 frames).
        if (lastContinued_[i] != 0 || last.missing > 0 || last.age + 1 < kMinContinuedFrames ||
            last.carried >= config_.stereo.maxCarriedFrames)
            continue;
        const Vec3 expected_rig_mm = last.position_rig_mm + neighboursStep(i);
        // The blob without a partner, in either camera, on whose ray the point is expected.
        double bestDistance_mm = reach_mm;
        int bestCamera = -1, bestBlob = -1;
        Vec3 bestPoint_rig_mm = Vec3::Zero();
        for (int camera = 0; camera < 2; ++camera)
            for (const auto& [u, ray] : unpairedRays_[index(camera)]) {
                if (markerOfBlob_[index(camera)][static_cast<std::size_t>(u)] >= 0)
                    continue; // carried on already
                const double along_mm =
                    (expected_rig_mm - ray.origin_rig_mm).dot(ray.direction_rig);
                const Vec3 onRay_rig_mm = ray.origin_rig_mm + along_mm * ray.direction_rig;
                const double distance_mm = (onRay_rig_mm - expected_rig_mm).norm();
                if (along_mm > 0.0 && distance_mm <= bestDistance_mm) {
                    bestDistance_mm = distance_mm;
                    bestCamera = camera;
                    bestBlob = u;
                    bestPoint_rig_mm = onRay_rig_mm;
                }
            }
        if (bestCamera < 0 || markers_.size() == markers_.capacity())
            continue;
        // Hidden in the other image: a blob of several discs (and, given the image, a lit pixel)
        // lies where the point projects there, or a nearer marker's round blob covers its whole
        // disc. Any other single disc there is a marker of its own (a spurious pair of
        // reflections that had lasted 20 frames was carried on the crowd).
        const std::optional<Vec2> hidden_px =
            stereo_.rig().camera(1 - bestCamera).project(bestPoint_rig_mm);
        int cover = -1;
        if (!hidden_px || (!mergedBlobAt(1 - bestCamera, *hidden_px, cover) &&
                           !nearerMarkerCovers(1 - bestCamera, *hidden_px, bestPoint_rig_mm,
                                               last.size_mm, cover)))
            continue;
        if (const ImageView& image = images[index(1 - bestCamera)]; image.pixels != nullptr) {
            const long x = std::lround(hidden_px->x()), y = std::lround(hidden_px->y());
            if (x < 0 || y < 0 || x >= width_px_ || y >= height_px_ ||
                image.pixels[y * image.stride_bytes + x] < config_.blobs.threshold)
                continue;
        }
        // A marker of this frame within reach is this one, paired after all (by a step longer
        // than continuity_mm).
        bool taken = false;
        for (const StereoMarker& marker : markers_)
            taken = taken || (marker.position_rig_mm - bestPoint_rig_mm).norm() <= reach_mm;
        if (taken)
            continue;
        StereoMarker carried;
        carried.blob0 = bestCamera == 0 ? bestBlob : cover;
        carried.blob1 = bestCamera == 0 ? cover : bestBlob;
        carried.position_rig_mm = bestPoint_rig_mm;
        carried.carried = true;
        markers_.push_back(carried);
        continuesLast_.push_back(static_cast<int>(i));
        markerOfBlob_[index(bestCamera)][static_cast<std::size_t>(bestBlob)] =
            static_cast<int>(markers_.size() - 1);
        ++carriedMarkers_;
    }
    // Marked only now: the neighbours' steps above are those of markers stereo found. From here
    // on (the missing points moved in rememberForContinuity()) a carried point steps too.
    for (std::size_t m = before; m < markers_.size(); ++m) {
        const auto at = static_cast<std::size_t>(continuesLast_[m]);
        lastContinued_[at] = 1;
        lastStep_[at] = markers_[m].position_rig_mm - last_[at].position_rig_mm;
    }
}

void MarkerPipeline::splitOnEpipolarLines(const std::array<ImageView, 2>& images) {
    // Blobs with a partner first, each blob split into parts once (from its first part with a
    // partner): their discs are markers already. Then blobs refused as not round, then blobs
    // without a partner, which in a burst of reflections are many and mostly no marker's; the
    // frame's budget of attempts goes to them last.
    splitAttemptsLeft_ = kMaxSplitAttempts;
    for (int camera = 0; camera < 2; ++camera) {
        const std::size_t other = index(1 - camera);
        for (std::size_t b = 0; b < blobs_[other].size(); ++b) {
            const Blob& blob = blobs_[other][b];
            if (blob.cut || markerOfBlob_[other][b] < 0)
                continue;
            bool seen = false;
            for (std::size_t e = 0; e < b && !seen; ++e)
                seen = markerOfBlob_[other][e] >= 0 && partsOfOneBlob(blobs_[other][e], blob);
            if (!seen)
                splitWithUnpaired(images[other], camera, static_cast<int>(b));
        }
    }
    for (int camera = 0; camera < 2; ++camera)
        for (const Blob& refused : detectors_[index(1 - camera)].refused())
            splitUnpaired(images[index(1 - camera)], camera, refused, -1);
    for (int camera = 0; camera < 2; ++camera) {
        const std::size_t other = index(1 - camera);
        for (std::size_t b = 0; b < blobs_[other].size(); ++b) {
            const Blob& blob = blobs_[other][b];
            if (!blob.cut && !blob.split && markerOfBlob_[other][b] < 0)
                splitUnpaired(images[other], camera, Blob(blob), static_cast<int>(b));
        }
    }
}

std::optional<MarkerPipeline::LineNear>
MarkerPipeline::epipolarLineNear(int camera, int blob, const Ray& otherRay) const {
    Ray ray;
    Vec2 unused;
    if (!stereo_.preparedBlob(camera, blob, ray, unused))
        return std::nullopt;
    const std::optional<TriangulatedPoint> near = triangulate(ray, otherRay);
    if (!near || near->range0_mm <= 0.0 || near->range1_mm <= 0.0)
        return std::nullopt;
    // The image of the ray around its point nearest the other ray, 2% of the range either side.
    const CameraModel& otherCamera = stereo_.rig().camera(1 - camera);
    const std::optional<Vec2> from =
        otherCamera.project(ray.origin_rig_mm + 0.98 * near->range0_mm * ray.direction_rig);
    const std::optional<Vec2> to =
        otherCamera.project(ray.origin_rig_mm + 1.02 * near->range0_mm * ray.direction_rig);
    if (!from || !to || !((*to - *from).norm() > 1e-6))
        return std::nullopt;
    // A sphere's image radius is R / range times the camera's pixelsPerRadian() where it lies.
    const double ownScale = stereo_.rig().camera(camera).pixelsPerRadian(ray.direction_rig);
    const double otherScale = otherCamera.pixelsPerRadian(otherRay.direction_rig);
    if (!(ownScale > 0.0) || !(otherScale > 0.0))
        return std::nullopt;
    return LineNear{PixelLine{*from, (*to - *from).normalized()},
                    near->range0_mm / near->range1_mm * otherScale / ownScale};
}

void MarkerPipeline::splitWithUnpaired(const ImageView& image, int camera, int shared) {
    if (splitAttemptsLeft_ == 0) {
        ++splitAttemptsSkipped_;
        return;
    }
    const std::size_t own = index(camera), other = index(1 - camera);
    const BoundedVector<Blob>& otherBlobs = blobs_[other];
    const Blob& sharedBlob = otherBlobs[static_cast<std::size_t>(shared)];
    constexpr std::size_t kMaxDiscs = BlobDetector::kMaxLineDiscs;
    // The blob's discs as it stands: the blob itself, or every part it was split into.
    std::array<int, kMaxDiscs> member{};
    std::size_t members = 0;
    for (std::size_t b = 0; b < otherBlobs.size(); ++b) {
        if (static_cast<int>(b) != shared && !partsOfOneBlob(otherBlobs[b], sharedBlob))
            continue;
        if (members + 1 == kMaxDiscs)
            return;
        member[members++] = static_cast<int>(b);
    }

    // The unpaired blobs of this camera whose epipolar lines cross one of its discs at a
    // disparity of the working volume, nearest a disc's row first.
    Candidates candidates;
    forEachUnpaired(camera, [&](int u, const Vec2& rectified) {
        double off = std::numeric_limits<double>::infinity();
        for (std::size_t k = 0; k < members; ++k) {
            Ray partRay;
            Vec2 partRectified;
            if (!stereo_.preparedBlob(1 - camera, member[k], partRay, partRectified))
                continue;
            const double radius = otherBlobs[static_cast<std::size_t>(member[k])].discRadius_px();
            off =
                std::min(off, crossingOff(camera, rectified, partRectified, radius + 1.0, radius));
        }
        candidates.offer(off, u);
    });
    if (candidates.count == 0)
        return;

    // Each part with a partner has its centre on the partner's epipolar line, and keeps its size
    // (a blob not split yet takes its partner's, as its own is that of several discs); a part
    // without one stays where it is.
    Ray sharedRay;
    Vec2 unused;
    if (!stereo_.preparedBlob(1 - camera, shared, sharedRay, unused))
        return;
    std::array<DiscOnLine, kMaxDiscs> discs{};
    std::array<int, kMaxDiscs> source{};
    for (std::size_t k = 0; k < members; ++k) {
        const Blob& part = otherBlobs[static_cast<std::size_t>(member[k])];
        const int marker = markerOfBlob_[other][static_cast<std::size_t>(member[k])];
        discs[k].start_px = part.centre_px;
        discs[k].radius_px = part.discRadius_px();
        source[k] = -1;
        Ray partRay;
        if (marker < 0 || !stereo_.preparedBlob(1 - camera, member[k], partRay, unused)) {
            discs[k].fixed = true;
            continue;
        }
        const StereoMarker& paired = markers_[static_cast<std::size_t>(marker)];
        source[k] = camera == 0 ? paired.blob0 : paired.blob1;
        const std::optional<LineNear> near = epipolarLineNear(camera, source[k], partRay);
        if (!near)
            return;
        discs[k].line = near->line;
        if (!part.split)
            discs[k].radius_px =
                near->scale * blobs_[own][static_cast<std::size_t>(source[k])].discRadius_px();
    }
    trySplits(image, camera, {sharedBlob, std::span(member.data(), members), -1}, sharedRay, discs,
              source, candidates, 1);
}

void MarkerPipeline::splitUnpaired(const ImageView& image, int camera, const Blob& refused,
                                   int replaces) {
    if (splitAttemptsLeft_ == 0) {
        ++splitAttemptsSkipped_;
        return;
    }
    const std::optional<Ray> ray = stereo_.rig().camera(1 - camera).ray(refused.centre_px);
    if (!ray)
        return;
    const std::optional<Vec2> rectified = stereo_.rig().rectifyDirection(ray->direction_rig);
    if (!rectified)
        return;
    // The unpaired blobs of this camera whose epipolar lines cross the blob's rows at a disparity
    // of the working volume, nearest its middle row first.
    const double halfHeight = 0.5 * (refused.bottom - refused.top + 1);
    const double halfWidth = 0.5 * (refused.right - refused.left + 1);
    Candidates candidates;
    forEachUnpaired(camera, [&](int u, const Vec2& unpairedRectified) {
        candidates.offer(
            crossingOff(camera, unpairedRectified, *rectified, halfHeight + 1.0, halfWidth), u);
    });
    if (candidates.count < 2)
        return;
    std::array<DiscOnLine, BlobDetector::kMaxLineDiscs> discs{};
    std::array<int, BlobDetector::kMaxLineDiscs> source{};
    trySplits(image, camera, {refused, {}, replaces}, *ray, discs, source, candidates, 2);
}

void MarkerPipeline::Candidates::offer(double off, int blob) {
    if (!(off < std::numeric_limits<double>::infinity()))
        return;
    std::size_t at = std::min(count, nearest.size() - 1);
    if (count == nearest.size() && off >= nearest[at].first)
        return;
    for (; at > 0 && nearest[at - 1].first > off; --at)
        nearest[at] = nearest[at - 1];
    nearest[at] = {off, blob};
    count = std::min(count + 1, nearest.size());
}

bool MarkerPipeline::trySplits(const ImageView& image, int camera, const SplitTarget& target,
                               const Ray& targetRay, std::span<DiscOnLine> discs,
                               std::span<int> source, const Candidates& candidates,
                               std::size_t minAdded) {
    // The candidates' discs, of unknown place on their epipolar lines near the target.
    const std::size_t own = index(camera);
    std::array<DiscOnLine, BlobDetector::kMaxLineDiscs> added{};
    for (std::size_t a = 0; a < candidates.count; ++a) {
        const int blob = candidates.nearest[a].second;
        const std::optional<LineNear> near = epipolarLineNear(camera, blob, targetRay);
        if (!near)
            return false;
        added[a] = {near->line, Vec2::Zero(),
                    near->scale * blobs_[own][static_cast<std::size_t>(blob)].discRadius_px(),
                    false, false};
    }
    // Every added disc, then every one but one: a line of a blob whose disc is elsewhere (at
    // another depth) spoils the fit of all. The nearest lines are kept where room is short.
    const std::size_t members = target.member.size();
    const std::size_t offered = std::min(candidates.count, discs.size() - members);
    for (std::size_t attempt = 0; attempt <= offered; ++attempt) {
        // Attempt 0 leaves none out; attempt a leaves out added disc a - 1.
        const std::size_t skip = attempt == 0 ? offered : attempt - 1;
        const std::size_t count = members + offered - (attempt == 0 ? 0 : 1);
        if (count - members < minAdded)
            continue;
        std::size_t at = members;
        for (std::size_t a = 0; a < offered; ++a)
            if (a != skip) {
                discs[at] = added[a];
                source[at] = candidates.nearest[a].second;
                ++at;
            }
        if (splitAndPair(image, camera, target, discs.first(count), source.first(count)))
            return true;
    }
    return false;
}

bool MarkerPipeline::splitAndPair(const ImageView& image, int camera, const SplitTarget& target,
                                  std::span<const DiscOnLine> discs, std::span<const int> source) {
    const std::size_t own = index(camera), other = index(1 - camera);
    BoundedVector<Blob>& otherBlobs = blobs_[other];
    constexpr std::size_t kMaxDiscs = BlobDetector::kMaxLineDiscs;
    const std::size_t members = target.member.size(), count = discs.size();
    if (splitAttemptsLeft_ == 0) {
        ++splitAttemptsSkipped_;
        return false;
    }
    --splitAttemptsLeft_;
    std::array<Blob, kMaxDiscs> parts{};
    std::array<bool, kMaxDiscs> placed{};
    if (detectors_[other].splitOnLines(image.pixels, image.stride_bytes, target.blob, discs,
                                       std::span(parts.data(), count),
                                       std::span(placed.data(), count)) == 0)
        return false;

    // A blob without a partner is no case for one new disc: stereo declined that pair already.
    std::size_t placedNew = 0;
    for (std::size_t k = members; k < count; ++k)
        placedNew += placed[k] && source[k] >= 0 ? 1U : 0U;
    if (placedNew < (members == 0 ? 2U : 1U))
        return false;

    // Each placed disc with a partner is triangulated: a new one into a new marker, in the place
    // of the blob it replaces or after the last; then, if one was, each member again from its
    // new centre (it keeps its old one when that fails stereo's checks). A blob that gave no new
    // marker keeps its centres: the scan found no disc hidden in it.
    bool added = false;
    const auto pairDisc = [&](std::size_t k) {
        if (!placed[k] || source[k] < 0)
            return;
        const bool isMember = k < members;
        const bool replacing = !isMember && !added && target.replaces >= 0;
        if (!isMember && (markers_.size() == markers_.capacity() ||
                          (!replacing && otherBlobs.size() == otherBlobs.capacity())))
            return;
        const int at = isMember    ? target.member[k]
                       : replacing ? target.replaces
                                   : static_cast<int>(otherBlobs.size());
        const Blob& partner = blobs_[own][static_cast<std::size_t>(source[k])];
        StereoMarker marker;
        if (!pairBlobs(camera, partner, source[k], parts[k], at, marker))
            return;
        const auto place = static_cast<std::size_t>(at);
        if (isMember) {
            otherBlobs[place] = parts[k];
            markers_[static_cast<std::size_t>(markerOfBlob_[other][place])] = marker;
            return;
        }
        if (replacing)
            otherBlobs[place] = parts[k];
        else
            otherBlobs.push_back(parts[k]);
        markers_.push_back(marker);
        markerOfBlob_[own][static_cast<std::size_t>(source[k])] =
            static_cast<int>(markers_.size() - 1);
        markerOfBlob_[other][place] = static_cast<int>(markers_.size() - 1);
        added = true;
    };
    for (std::size_t k = members; k < count; ++k)
        pairDisc(k);
    for (std::size_t k = 0; k < members && added; ++k)
        pairDisc(k);
    return added;
}

std::span<const Vec3> MarkerPipeline::process(const std::uint8_t* pixels0, int stride0_bytes,
                                              const std::uint8_t* pixels1, int stride1_bytes) {
    detectBlobs(0, pixels0, stride0_bytes);
    detectBlobs(1, pixels1, stride1_bytes);
    matchStereo(StereoMethod::Svd, {{{pixels0, stride0_bytes}, {pixels1, stride1_bytes}}});
    return points_rig_mm();
}

MarkerPipelineCounters MarkerPipeline::counters() const {
    MarkerPipelineCounters c;
    for (std::size_t camera = 0; camera < 2; ++camera) {
        c.rejectedNotRound += detectors_[camera].counters().rejectedNotRound;
        c.splitBlobs += detectors_[camera].counters().splitBlobs;
        c.splitRefused += detectors_[camera].counters().splitRefused;
        c.cutDiscs += detectors_[camera].counters().cutDiscs;
        c.ellipses += detectors_[camera].counters().ellipses;
        c.splitOnLines += detectors_[camera].counters().splitOnLines;
        c.labelOverflow += detectors_[camera].counters().labelOverflow;
        // The detector chooses which blobs fit and counts the rest; the blob vectors count blobs
        // given from outside (blobs level) that did not fit.
        c.blobOverflow +=
            detectors_[camera].counters().blobOverflow + blobs_[camera].overflowCount();
    }
    c.markerOverflow = stereo_.counters().markerOverflow;
    c.splitAttemptsSkipped = splitAttemptsSkipped_;
    c.pairsForContinuity = pairsForContinuity_;
    c.carriedMarkers = carriedMarkers_;
    c.markersSplitWhereExpected = markersSplitWhereExpected_;
    return c;
}

} // namespace edgetrack
