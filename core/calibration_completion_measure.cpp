// Completion, measure step: a body's markers from every frame it was found in, then least squares.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <optional>
#include <utility>

#include "core/calibration_completion.hpp"
#include "core/completion_geometry.hpp"
#include "core/layout_precision.hpp"
#include "core/marker_set.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

using namespace completion_detail;

namespace {

constexpr double kDegree = std::numbers::pi / 180.0;
// A marker seen from directions up to h from their mean is seen beyond them too: a sphere's
// reflection fades only toward grazing views, past what one session's turns happened to show.
// Its cone of viewing directions is taken this much wider than h (degrees).
constexpr double kCoVisibleMargin_deg = 15.0;

// The pairs of n markers that can be seen together: seen so in two frames or more (together, an
// n x n count), or whose cones of viewing directions (seenFrom, body frame) meet. A later session
// shows the object from directions this one did not, and the tracker's search stands only on
// edges; S_min is computed over the same edges, so it stays sound for what the tracker searches.
std::vector<std::pair<std::uint16_t, std::uint16_t>>
coVisiblePairs(std::size_t n, std::span<const std::uint32_t> together,
               std::span<const std::vector<Vec3>> seenFrom) {
    std::vector<ViewCone> cones;
    for (std::size_t k = 0; k < n; ++k)
        cones.push_back(viewCone(seenFrom[k], kCoVisibleMargin_deg * kDegree));
    std::vector<std::pair<std::uint16_t, std::uint16_t>> pairs;
    for (std::size_t i = 0; i < n; ++i)
        for (std::size_t j = i + 1; j < n; ++j)
            if (together[i * n + j] >= 2 || coVisible(cones[i], cones[j]))
                pairs.emplace_back(static_cast<std::uint16_t>(i), static_cast<std::uint16_t>(j));
    return pairs;
}
/// Steps of the joint least squares that place the layouts for the join (refinedMarkers()): one
/// joined the same pieces as four in every sweep, at a quarter of the cost.
constexpr int kJoinRefineIterations = 1;
/// Squared distance from the cameras (mm^2) at which markerResidual_mm2 is in the rig's units.
constexpr double kNoiseDistance2_mm2 = 1000.0 * 1000.0;
/// A place holds points within this many times the median distance of an object's points from
/// its markers: for a 3D normal scatter the median distance is 1.5 sigma, so 3 times it holds all
/// but one point in a thousand.
constexpr double kScatterFactor = 3.0;
/// Frames in which the cameras look at a place as it was seen, less than this apart, are one pass
/// by it (s).
constexpr double kPassGap_s = 0.1;
/// A place where points sat in at least this many frames but too few to be a marker is kept as
/// a glimpse of one (Body::glimpsed_mm).
constexpr std::uint32_t kMinGlimpseFrames = 5;
/// A place seen in fewer frames than minSeenShare of those that look at it is a marker when it
/// was there in at least this share of at least kMinPasses passes.
constexpr std::uint32_t kMinPasses = 3;
constexpr double kPassShare = 2.0 / 3.0;
/// A place is a marker only when the body carried it, while it was seen there, farther through
/// the rig than this many place radii: a point that stands still in the rig (a glint, a screw
/// head) sits at one place of a body's frame too while the body keeps still, but never when it
/// moves farther than twice the place radius.
constexpr double kMinTravelInRadii = 4.0;

} // namespace

// ---------------------------------------------------------------------------------------------
// Measuring a body's markers from every frame it was found in

std::size_t CalibrationCompletion::cellOf(const Vec3& q_mm) const {
    const double cell = 2.0 * placeRadius_mm_;
    const auto ix = static_cast<std::int64_t>(std::floor(q_mm.x() / cell));
    const auto iy = static_cast<std::int64_t>(std::floor(q_mm.y() / cell));
    const auto iz = static_cast<std::int64_t>(std::floor(q_mm.z() / cell));
    const auto h = static_cast<std::uint64_t>(ix * 73856093 ^ iy * 19349663 ^ iz * 83492791);
    return static_cast<std::size_t>(h & (kSiteCells - 1));
}

std::int32_t CalibrationCompletion::siteNear(const Vec3& q_mm) const {
    const double cell = 2.0 * placeRadius_mm_;
    const double radius2 = placeRadius_mm_ * placeRadius_mm_;
    std::int32_t best = -1;
    double bestDistance2 = radius2;
    for (int dx = -1; dx <= 1; ++dx)
        for (int dy = -1; dy <= 1; ++dy)
            for (int dz = -1; dz <= 1; ++dz) {
                const Vec3 probe = q_mm + cell * Vec3(dx, dy, dz);
                for (std::int32_t s = cellHead_[cellOf(probe)]; s >= 0;
                     s = sites_[static_cast<std::size_t>(s)].next) {
                    const Site& site = sites_[static_cast<std::size_t>(s)];
                    const double d2 =
                        (site.sum_mm / static_cast<double>(site.hits) - q_mm).squaredNorm();
                    if (d2 <= bestDistance2) {
                        bestDistance2 = d2;
                        best = s;
                    }
                }
            }
    return best;
}

std::int32_t CalibrationCompletion::addSite(const Vec3& q_mm) {
    if (sites_.size() == config_.maxSites) {
        ++counters_.siteOverflow;
        return -1;
    }
    const std::size_t cell = cellOf(q_mm);
    Site& site = sites_.emplace_back();
    site.sum_mm = q_mm;
    site.hits = 1;
    site.next = cellHead_[cell];
    cellHead_[cell] = static_cast<std::int32_t>(sites_.size() - 1);
    return cellHead_[cell];
}

double CalibrationCompletion::placeRadiusOf(const SessionBuffer& session, const Body& body) const {
    const double widest = 0.5 * config_.minMarkerSpacing_mm;
    const double lookWithin2 = 4.0 * widest * widest;
    std::vector<double> distances;
    for (std::size_t f = 0; f < session.frames(); ++f) {
        if (!body.posed[f])
            continue;
        const std::span<const Vec3> points = session.points(f);
        for (const Vec3& m : body.markers_mm) {
            const Vec3 there = body.T_rig_from_body[f].apply(m);
            double best2 = lookWithin2;
            for (const Vec3& p : points)
                best2 = std::min(best2, (p - there).squaredNorm());
            if (best2 < lookWithin2)
                distances.push_back(std::sqrt(best2));
        }
    }
    if (distances.empty())
        return config_.siteRadius_mm;
    return std::clamp(kScatterFactor * medianOf(distances), config_.siteRadius_mm,
                      std::max(widest, config_.siteRadius_mm));
}

bool CalibrationCompletion::measure(const SessionBuffer& session, Body& body) {
    const std::size_t frames = session.frames();
    body.placeRadius_mm = placeRadiusOf(session, body);
    placeRadius_mm_ = body.placeRadius_mm;
    sites_.clear();
    std::fill(cellHead_.begin(), cellHead_.end(), -1);

    const Extent extent = extentOf(body.markers_mm);
    const double reach = extent.radius_mm + config_.placeReach_mm;
    const double reach2 = reach * reach;
    // A point on a marker of another object found in the same frame is that object's: markers of
    // one that sat still against this one for a while (objects turning slowly side by side) are
    // no markers of this one. Only objects known to move apart from it: a piece of this body
    // holds markers this one has yet to learn.
    std::vector<Vec3> claimed;
    const double claim2 = placeRadius_mm_ * placeRadius_mm_;
    for (std::size_t f = 0; f < frames; ++f) {
        if (!body.posed[f])
            continue;
        markersOfOthersAt(f, body, OtherBodies::KnownApart, claimed);
        const RigidTransform T_body_from_rig = body.T_rig_from_body[f].inverse();
        for (const Vec3& p : session.points(f)) {
            const Vec3 q = T_body_from_rig.apply(p);
            if ((q - extent.centre).squaredNorm() > reach2)
                continue;
            if (nearAny(claimed, p, claim2))
                continue;
            std::int32_t s = siteNear(q);
            if (s < 0) {
                s = addSite(q);
                if (s < 0)
                    continue;
                Site& fresh = sites_[static_cast<std::size_t>(s)];
                fresh.lastFrame = static_cast<std::uint32_t>(f);
                continue;
            }
            Site& site = sites_[static_cast<std::size_t>(s)];
            if (site.lastFrame == f)
                continue;
            site.lastFrame = static_cast<std::uint32_t>(f);
            ++site.hits;
            site.sum_mm += q;
        }
    }

    // Places seen long enough, strongest first; of two closer than a marker's size, the stronger.
    const auto minHits = static_cast<std::uint32_t>(std::ceil(config_.minSeen_s * frameRate_hz_));
    // The places seen in [fewest, most) frames, most often seen first (ties by position, so that
    // the order of points in a frame does not matter).
    auto strongestSites = [&](std::uint32_t fewest, std::uint32_t most) {
        std::vector<std::size_t> sites;
        for (std::size_t s = 0; s < sites_.size(); ++s)
            if (sites_[s].hits >= fewest && sites_[s].hits < most)
                sites.push_back(s);
        std::sort(sites.begin(), sites.end(), [&](std::size_t a, std::size_t b) {
            if (sites_[a].hits != sites_[b].hits)
                return sites_[a].hits > sites_[b].hits;
            return canonicallyBefore(sites_[a].sum_mm, sites_[b].sum_mm);
        });
        return sites;
    };
    const std::vector<std::size_t> candidates =
        strongestSites(std::max<std::uint32_t>(minHits, 2), UINT32_MAX);
    std::vector<Vec3> place;
    const double spacing2 = config_.minMarkerSpacing_mm * config_.minMarkerSpacing_mm;
    for (const std::size_t s : candidates) {
        const Vec3 mean = sites_[s].sum_mm / static_cast<double>(sites_[s].hits);
        const bool near = std::any_of(place.begin(), place.end(), [&](const Vec3& p) {
            return (p - mean).squaredNorm() < spacing2;
        });
        if (near)
            continue;
        if (place.size() == 2 * config_.maxMarkersPerModel) {
            ++counters_.markerOverflow;
            break;
        }
        place.push_back(mean);
    }

    // Seen again whenever the cameras look at it as they once saw it? First the directions each
    // place was seen from (body frame, thinned), then, in every frame, whether the cameras look
    // from one of them and it is there.
    const std::size_t n = place.size();
    std::vector<std::uint32_t> expected(n, 0), seenWhenExpected(n, 0), seen(n, 0);
    std::vector<std::uint32_t> together(n * n, 0);
    std::vector<std::vector<Vec3>> seenFrom(n);
    std::vector<std::uint8_t> hit(n);
    std::vector<std::size_t> hitNow;
    // Each posed frame's places hit, one after another (frameHitsEnd: where each frame's end).
    std::vector<std::uint32_t> frameHits, frameHitsEnd;
    const double sameView = std::cos(config_.sameViewAngle_deg * kDegree);
    const double thinning = std::cos(0.5 * config_.sameViewAngle_deg * kDegree);
    const double radius2 = placeRadius_mm_ * placeRadius_mm_;
    // The stretches of frames in which the cameras look at a place as they once saw it (gaps of
    // up to passGap frames bridged), and in how many of them it was there at all.
    struct Passes {
        std::uint32_t lastFrame = UINT32_MAX;
        std::uint32_t count = 0;
        std::uint32_t seen = 0;
        bool seenInThis = false;
    };
    std::vector<Passes> passes(n);
    // Where in the rig each place was while it was seen there: the box its positions span.
    std::vector<Vec3> lowest(n, Vec3::Constant(std::numeric_limits<double>::infinity()));
    std::vector<Vec3> highest(n, Vec3::Constant(-std::numeric_limits<double>::infinity()));
    const auto passGap = static_cast<std::size_t>(std::ceil(kPassGap_s * frameRate_hz_));
    std::vector<Vec3> nearPoints;
    const double placeReach2 = (reach + placeRadius_mm_) * (reach + placeRadius_mm_);
    for (int pass = 0; pass < 2; ++pass) {
        for (std::size_t f = 0; f < frames; ++f) {
            if (!body.posed[f])
                continue;
            const RigidTransform& T_rig_from_body = body.T_rig_from_body[f];
            const Vec3 viewpoint = T_rig_from_body.inverse().apply(config_.viewpoint_rig_mm);
            // Only points within reach of the body can be on a place (every place lies within
            // reach of its centre): the other objects' points are most of a frame's.
            const Vec3 centre = T_rig_from_body.apply(extent.centre);
            nearPoints.clear();
            for (const Vec3& p : session.points(f))
                if ((p - centre).squaredNorm() <= placeReach2)
                    nearPoints.push_back(p);
            hitNow.clear();
            for (std::size_t k = 0; k < n; ++k) {
                const Vec3 there = T_rig_from_body.apply(place[k]);
                const bool isHit =
                    std::any_of(nearPoints.begin(), nearPoints.end(), [&](const Vec3& p) {
                        return (p - there).squaredNorm() <= radius2;
                    });
                const Vec3 view = (viewpoint - place[k]).normalized();
                std::vector<Vec3>& directions = seenFrom[k];
                if (pass == 0) {
                    if (!isHit)
                        continue;
                    ++seen[k];
                    lowest[k] = lowest[k].cwiseMin(there);
                    highest[k] = highest[k].cwiseMax(there);
                    hitNow.push_back(k);
                    keepViewDirection(directions, view, thinning);
                    continue;
                }
                if (seenFromNear(directions, view, sameView)) {
                    ++expected[k];
                    seenWhenExpected[k] += isHit ? 1U : 0U;
                    Passes& p = passes[k];
                    if (p.lastFrame == UINT32_MAX || f > p.lastFrame + passGap) {
                        ++p.count;
                        p.seenInThis = false;
                    }
                    if (isHit && !p.seenInThis) {
                        p.seenInThis = true;
                        ++p.seen;
                    }
                    p.lastFrame = static_cast<std::uint32_t>(f);
                }
            }
            for (std::size_t i = 0; i < hitNow.size(); ++i)
                for (std::size_t j = i + 1; j < hitNow.size(); ++j)
                    ++together[hitNow[i] * n + hitNow[j]];
            if (pass == 0) {
                for (const std::size_t k : hitNow)
                    frameHits.push_back(static_cast<std::uint32_t>(k));
                frameHitsEnd.push_back(static_cast<std::uint32_t>(frameHits.size()));
            }
        }
    }
    std::vector<std::size_t> accepted;
    for (std::size_t k = 0; k < n; ++k) {
        if (seen[k] < minHits ||
            (highest[k] - lowest[k]).norm() < kMinTravelInRadii * placeRadius_mm_)
            continue;
        // Seen whenever the cameras look at it as before: in minSeenShare of those frames, or,
        // for a marker at the edge of its view (one camera sees it, the other not) or often
        // behind a passing hand, in most of several passes by it. A point that rode along for a
        // while is there in one pass and missing in the others.
        const bool seenInShare = static_cast<double>(seenWhenExpected[k]) >=
                                 config_.minSeenShare * static_cast<double>(expected[k]);
        const bool seenInPasses =
            passes[k].count >= kMinPasses && static_cast<double>(passes[k].seen) >=
                                                 kPassShare * static_cast<double>(passes[k].count);
        if (expected[k] > 0 && !seenInShare && !seenInPasses)
            continue;
        if (accepted.size() == config_.maxMarkersPerModel) {
            ++counters_.markerOverflow;
            break;
        }
        accepted.push_back(k);
    }

    std::vector<Vec3> markers;
    for (const std::size_t k : accepted)
        markers.push_back(place[k]);
    // The most of its markers seen in one frame.
    std::vector<std::uint8_t> isAccepted(n, 0);
    for (const std::size_t k : accepted)
        isAccepted[k] = 1;
    body.mostSeenTogether = 0;
    for (std::size_t f = 0, begin = 0; f < frameHitsEnd.size(); begin = frameHitsEnd[f++]) {
        std::size_t count = 0;
        for (std::size_t i = begin; i < frameHitsEnd[f]; ++i)
            count += isAccepted[frameHits[i]];
        body.mostSeenTogether = std::max(body.mostSeenTogether, count);
    }
    // Glimpses: places seen in a few frames, too few for a marker, away from every marker.
    std::vector<Vec3> glimpses;
    for (const std::size_t s : strongestSites(kMinGlimpseFrames, minHits)) {
        const Vec3 mean = sites_[s].sum_mm / static_cast<double>(sites_[s].hits);
        const auto near = [&](const Vec3& p) { return (p - mean).squaredNorm() < spacing2; };
        if (std::none_of(markers.begin(), markers.end(), near) &&
            std::none_of(glimpses.begin(), glimpses.end(), near))
            glimpses.push_back(mean);
    }
    const bool glimpsesChanged = glimpses.size() != body.glimpsed_mm.size();
    body.glimpsed_mm = std::move(glimpses);
    auto covered = [](std::span<const Vec3> set, const Vec3& p) {
        return std::any_of(set.begin(), set.end(),
                           [&](const Vec3& q) { return (q - p).squaredNorm() < 0.25; });
    };
    std::size_t added = 0, removed = 0;
    for (const Vec3& m : markers)
        added += covered(body.markers_mm, m) ? 0U : 1U;
    for (const Vec3& m : body.markers_mm)
        removed += covered(markers, m) ? 0U : 1U;
    counters_.markersAdded += added;
    counters_.markersRemoved += removed;
    body.markers_mm = std::move(markers);
    {
        std::vector<std::uint32_t> acceptedTogether(accepted.size() * accepted.size(), 0);
        std::vector<std::vector<Vec3>> acceptedSeenFrom;
        for (std::size_t a = 0; a < accepted.size(); ++a) {
            acceptedSeenFrom.push_back(seenFrom[accepted[a]]);
            for (std::size_t b = a + 1; b < accepted.size(); ++b)
                acceptedTogether[a * accepted.size() + b] =
                    together[std::min(accepted[a], accepted[b]) * n +
                             std::max(accepted[a], accepted[b])];
        }
        body.edges = coVisiblePairs(accepted.size(), acceptedTogether, acceptedSeenFrom);
    }
    return added > 0 || removed > 0 || glimpsesChanged;
}

// ---------------------------------------------------------------------------------------------
// Least squares over every pose

std::vector<Vec3> CalibrationCompletion::refinedMarkers(const SessionBuffer& session,
                                                        const Body& body) {
    // What refine() reads; the rest of a body (its lone track, its model) is not copied.
    Body refined;
    refined.markers_mm = body.markers_mm;
    refined.T_rig_from_body = body.T_rig_from_body;
    refined.posed = body.posed;
    refined.placeRadius_mm = body.placeRadius_mm;
    refine(session, refined, kJoinRefineIterations);
    return std::move(refined.markers_mm);
}

void CalibrationCompletion::refine(const SessionBuffer& session, Body& body, int iterations,
                                   bool judge, double maxFrameResidual_mm2) {
    const std::size_t frames = session.frames();
    const std::size_t n = body.markers_mm.size();
    if (n < 3)
        return;
    const double radius =
        kRefineRadiusFactor * std::max(config_.siteRadius_mm, body.placeRadius_mm);
    std::vector<std::uint32_t> counts(n);
    std::vector<std::uint32_t> together(n * n, 0);
    std::vector<std::vector<Vec3>> seenFrom(n);
    const double thinning = std::cos(0.5 * config_.sameViewAngle_deg * kDegree);
    body.framesInFour.assign(n, 0);
    std::vector<std::vector<double>> residuals(n);
    std::vector<double> scaled;
    std::vector<MarkerBits> viewSets;
    std::size_t previousPosed = SIZE_MAX - 1;
    MarkerBits previousSeen{};
    body.worstFrameResidual_mm2 = 0.0;
    struct Claim {
        const Vec3* point;
        std::size_t marker;
        double distance2_mm2;
    };
    std::vector<Claim> claims;
    std::vector<Vec3> from, to;
    std::vector<std::size_t> which;
    // The normal equations of all poses and markers at once, poses eliminated (Schur complement):
    // a marker step that accounts for how every pose moves with the markers. Marker means alone
    // (block coordinate descent) straighten a chain of sides only slowly.
    const auto dimension = static_cast<Eigen::Index>(3 * n);
    Eigen::MatrixXd reduced(dimension, dimension);
    Eigen::VectorXd rhs(dimension);
    double squaredResiduals_mm2 = 0.0;
    double degreesOfFreedom = 0.0;
    for (int iteration = 0; iteration < iterations; ++iteration) {
        const bool last = iteration + 1 == iterations;
        std::fill(counts.begin(), counts.end(), 0U);
        reduced.setZero();
        rhs.setZero();
        for (std::size_t f = 0; f < frames; ++f) {
            if (!body.posed[f])
                continue;
            const std::span<const Vec3> points = session.points(f);
            from.clear();
            to.clear();
            which.clear();
            claims.clear();
            for (std::size_t k = 0; k < n; ++k) {
                const Vec3 there = body.T_rig_from_body[f].apply(body.markers_mm[k]);
                if (const Vec3* match = nearestPoint(points, there, radius))
                    claims.push_back({match, k, (*match - there).squaredNorm()});
            }
            // One point is one marker: of two markers that claim it, the nearer has it.
            for (const Claim& c : claims) {
                const bool nearerClaim =
                    std::any_of(claims.begin(), claims.end(), [&](const Claim& o) {
                        return o.point == c.point &&
                               (o.distance2_mm2 < c.distance2_mm2 ||
                                (o.distance2_mm2 == c.distance2_mm2 && o.marker < c.marker));
                    });
                if (nearerClaim)
                    continue;
                from.push_back(body.markers_mm[c.marker]);
                to.push_back(*c.point);
                which.push_back(c.marker);
            }
            const std::optional<RigidFit> fit = fitRigid(from, to);
            if (!fit || fit->rms_mm > config_.tracking.maxRms_mm) {
                body.posed[f] = 0;
                continue;
            }
            // Each marker's share: a rigid fit of k points takes up 6 of their 3k residual
            // degrees of freedom, 2/k of each point's on average. And in units of the rig's
            // noise where the point is: a stereo point's error along the line of sight, which
            // dominates, grows with the square of its distance from the cameras.
            const auto matched = static_cast<double>(which.size());
            scaled.clear();
            double frameScaled = 0.0;
            const bool judged = judge && (last || maxFrameResidual_mm2 > 0.0);
            for (std::size_t i = 0; judged && i < which.size(); ++i) {
                const double r2 = (fit->transform.apply(from[i]) - to[i]).squaredNorm();
                const double distance2 =
                    config_.noiseGrowsWithDistance
                        ? (to[i] - config_.viewpoint_rig_mm).squaredNorm() / kNoiseDistance2_mm2
                        : 1.0;
                scaled.push_back(r2 / (1.0 - 2.0 / matched) / (distance2 * distance2));
                frameScaled += scaled.back();
            }
            if (maxFrameResidual_mm2 > 0.0 && frameScaled / matched > maxFrameResidual_mm2) {
                body.posed[f] = 0;
                continue;
            }
            if (last)
                body.worstFrameResidual_mm2 =
                    std::max(body.worstFrameResidual_mm2, frameScaled / matched);
            body.T_rig_from_body[f] = fit->transform;
            for (const std::size_t k : which)
                ++counts[k];
            addToReducedSystem(fit->transform, from, to, which, reduced, rhs);
            if (!last)
                continue;
            squaredResiduals_mm2 += fit->rms_mm * fit->rms_mm * matched;
            degreesOfFreedom += 3.0 * matched - 6.0;
            for (std::size_t i = 0; i < scaled.size(); ++i)
                residuals[which[i]].push_back(scaled[i]);
            if (judge && last) {
                MarkerBits seen{};
                for (const std::size_t k : which)
                    add(seen, k);
                // A handover: the frame before, posed too, carries the pose on by continuity.
                if (previousPosed + 1 == f) {
                    MarkerBits joined = previousSeen;
                    joined[0] |= seen[0];
                    joined[1] |= seen[1];
                    viewSets.push_back(joined);
                } else
                    viewSets.push_back(seen);
                previousPosed = f;
                previousSeen = seen;
            }
            for (std::size_t i = 0; i < which.size(); ++i)
                for (std::size_t j = i + 1; j < which.size(); ++j)
                    ++together[which[i] * n + which[j]];
            const Vec3 viewpoint = fit->transform.inverse().apply(config_.viewpoint_rig_mm);
            for (const std::size_t k : which)
                keepViewDirection(seenFrom[k], (viewpoint - body.markers_mm[k]).normalized(),
                                  thinning);
            if (which.size() >= 4)
                for (const std::size_t k : which)
                    ++body.framesInFour[k];
        }
        if (last && judge)
            body.precision =
                layoutPrecision(reduced, counts, squaredResiduals_mm2, degreesOfFreedom);
        // Markers no frame saw keep their place; the rest take the joint step. The step cannot
        // move the layout as a whole (poses follow), so that freedom is held by a small damping.
        for (std::size_t k = 0; k < n; ++k)
            if (counts[k] == 0) {
                const auto at = static_cast<Eigen::Index>(3 * k);
                reduced.block<3, 3>(at, at).setIdentity();
                rhs.segment<3>(at).setZero();
            }
        const double damping = 1e-9 * std::max(1.0, reduced.diagonal().mean());
        reduced.diagonal().array() += damping;
        const Eigen::VectorXd step = reduced.ldlt().solve(rhs);
        if (step.allFinite())
            for (std::size_t k = 0; k < n; ++k)
                body.markers_mm[k] += step.segment<3>(static_cast<Eigen::Index>(3 * k));
    }
    // A marker's typical squared residual: the median, which a few frames that matched it to
    // a wrong point do not move.
    body.markerFrames = counts;
    // Shared markers tie two groups when they lie as far off one line as the tracker asks of a
    // pose's markers.
    if (judge)
        body.rigidGroups =
            rigidGroupsOf(viewSets, body.markers_mm, config_.tracking.minPoseSpread_mm);
    body.markerResidual_mm2.assign(n, 0.0);
    for (std::size_t k = 0; k < n && judge; ++k)
        if (!residuals[k].empty())
            body.markerResidual_mm2[k] = medianOf(residuals[k]);
    body.edges = coVisiblePairs(n, together, seenFrom);
}

} // namespace edgetrack
