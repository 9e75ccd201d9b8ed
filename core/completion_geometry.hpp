// Geometry the completion steps share: extents, transform agreement, layout registration.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <numbers>
#include <optional>
#include <span>
#include <vector>

#include "core/marker_model.hpp"
#include "core/rigid_fit.hpp"
#include "core/rigid_transform.hpp"

namespace edgetrack::completion_detail {

/// Points within this many site radii of a marker's place are that marker when refining.
constexpr double kRefineRadiusFactor = 1.5;

/// A ball that holds a layout (body frame, mm).
struct Extent {
    Vec3 centre = Vec3::Zero();
    double radius_mm = 0.0;
};

/// The centroid of \a markers_mm and the distance of the farthest from it.
Extent extentOf(std::span<const Vec3> markers_mm);

/// How far apart two transforms put the points of a ball (centre, radius): an upper bound (mm).
double disagreement_mm(const RigidTransform& a, const RigidTransform& b, const Extent& ball);

/**
 * \brief How many of \a frames show two bodies as two objects: both found there (\a T_rig_from_a,
 * \a T_rig_from_b, indexed by frame), in places that do not overlap (their balls' centres farther
 * apart than the two radii), at a relative pose that \a T_a_from_b misses by more than
 * \a tolerance_mm (disagreement_mm over \a ballB).
 *
 * Two pieces of one body found at once sit where the tie puts them; a piece of a self-similar
 * body taken for another part of it lies on that part's points, so the two overlap.
 */
std::size_t framesSeenApart(std::span<const RigidTransform> T_rig_from_a,
                            std::span<const RigidTransform> T_rig_from_b,
                            std::span<const std::size_t> frames, const Extent& ballA,
                            const Extent& ballB, const RigidTransform& T_a_from_b,
                            double tolerance_mm);

/// \brief The rigid fit of \a from onto \a to (paired by index), the pair farthest off it
/// dropped from both while any lies more than \a tolerance_mm off: points of something else
/// among a body's. Nothing when fewer than three pairs are left or they lie on one line; \a from
/// and \a to keep the pairs that remain.
std::optional<RigidFit> fitDroppingWorst(std::vector<Vec3>& from, std::vector<Vec3>& to,
                                         double tolerance_mm);

/// Which transform the most others come near, and how many come near it (itself included).
struct Agreement {
    std::size_t index = 0;
    std::size_t agree = 0;
};

/// Of \a transforms at indices 0, \a step, 2 \a step, ..., the one that most of \a transforms
/// put the points of \a ball within \a tolerance_mm of (disagreement_mm); the first of equals.
Agreement mostAgreed(std::span<const RigidTransform> transforms, const Extent& ball,
                     double tolerance_mm, std::size_t step = 1);

/// The placement of one layout in another: which transform, how many markers it puts onto the
/// other's, and how many the best different placement puts there.
struct Registration {
    RigidTransform T_whole_from_part;
    std::size_t matched = 0;
    std::size_t runnerUp = 0;
};

/**
 * \brief The transform that puts the most markers of \a part onto markers of \a whole.
 *
 * Every well-spread triangle of \a part is tried on every triangle of \a whole whose sides agree
 * within \a tolerance_mm; each placement is refitted on all the markers it puts within
 * \a matchTolerance_mm of one. A placement that shares fewer than three of the best's pairs is a
 * different one: its count is Registration::runnerUp (a self-similar layout registers in several
 * ways). Independent of the order of either layout's markers.
 */
Registration registerLayout(std::span<const Vec3> part, std::span<const Vec3> whole,
                            double tolerance_mm, double matchTolerance_mm);

/// Two models' markers are the same marker when one model registered onto the other puts them
/// this close (mm): models are measured over hundreds of frames to well under 0.1 mm, and at 1 mm
/// four markers of one random layout already land on four of another by chance.
inline constexpr double kRegistrationTolerance_mm = 0.5;

/// What a tie of two layouts by one shared triangle must satisfy (soleSharedTriangle).
struct TriangleTieLimits {
    /// The shared triangle's sides agree within this (mm).
    double tolerance_mm;
    /// No other pair of triangles of the two layouts has every side within this (mm).
    double uniqueness_mm;
    /// How exactly the two layouts are known (mm): a floor under the triangle fit's RMS.
    double precision_mm;
    /// The triangle's error, carried over its lever arm, moves the placed layout's farthest
    /// marker by at most this (mm).
    double placement_mm;
    /// Side comparisons at most: large layouts have chance likenesses anyway.
    std::size_t budget;
};

/// The limits completion's joins use. A triangle that is the only tie of two pieces must agree
/// as closely as their layouts are known: the joint least squares measures them to 0.01-0.05 mm,
/// and a triangle shared by two pieces of one body matches within 0.03 mm. At 0.5 mm (a layout
/// registration's tolerance), with its uniqueness judged at 2 mm, a plate's or a star's hundreds
/// of triangles nearly always held a second likeness and the true tie was refused, while chance
/// likenesses of two objects matched at 0.14-0.75 mm. It is unique when no other pair of
/// triangles comes within four times the tolerance on every side, and it must place the far
/// markers of the piece it places within a registration's tolerance. Side comparisons stop at
/// two million (two pieces of 30 markers each have 4,060 triangles).
inline constexpr TriangleTieLimits kTriangleTie{.tolerance_mm = 0.1,
                                                .uniqueness_mm = 0.4,
                                                .precision_mm = 0.05,
                                                .placement_mm = kRegistrationTolerance_mm,
                                                .budget = 2000000};

/**
 * \brief The placement of \a part in \a whole by the one triangle the two layouts share.
 *
 * Two pieces of one body that are never in view together beyond three shared markers are tied by
 * those three alone. A triangle is no identity when another is like it, so this asks that exactly
 * one triangle of \a part has sides within TriangleTieLimits::uniqueness_mm of one of \a whole
 * (every triangle of both counted, flat or not), that the two agree within
 * TriangleTieLimits::tolerance_mm, that the triangle's corners are told apart by its sides and it
 * is not flat (wellShaped at that tolerance), and that it is wide enough for the part's farthest
 * marker: the fit's RMS (at least TriangleTieLimits::precision_mm) turns the placement by about
 * that over the triangle's height, which moves a marker at distance r by r times as much. Gives
 * up (nothing) after TriangleTieLimits::budget side comparisons. Independent of the order of
 * either layout's markers.
 */
std::optional<RigidTransform> soleSharedTriangle(std::span<const Vec3> part,
                                                 std::span<const Vec3> whole,
                                                 const TriangleTieLimits& limits);

/// A marker that moved less than this (mm) since a body was tracked alone, or since its S_min
/// pairs were found, leaves them standing: the tracker matches within 1.5 mm, S_min counts markers
/// within a millimetre or more, and measure() moves markers by hundredths of a millimetre from
/// round to round.
constexpr double kSameMarker_mm = 0.1;

/// Whether \a a and \a b are one layout: markers in the same order within kSameMarker_mm, and
/// the same edges.
bool sameLayout(const MarkerModel& a, const MarkerModel& b);

/// Three markers or points, their corners ordered by the side facing each, shortest first (mm):
/// two congruent scalene triangles list their corresponding corners in the same order.
struct SortedTriangle {
    /// Other bodies a triangle may be alike to and still stand for its own (markAlike()).
    static constexpr std::size_t kMaxAlikeBodies = 4;

    std::array<double, 3> sides_mm{};
    std::array<std::uint32_t, 3> corners{};
    /// Whose markers they are, and whether it stands for them: no other triangle of its own body
    /// has the same sides, and those of at most kMaxAlikeBodies other bodies do (alikeBodies).
    std::size_t body = 0;
    bool unique = true;
    std::array<std::uint32_t, kMaxAlikeBodies> alikeBodies{};
    std::uint32_t alikeCount = 0;
};

/// The triangle of \a a, \a b, \a c, whose indices are \a ia, \a ib, \a ic.
SortedTriangle sortedTriangle(const Vec3& a, const Vec3& b, const Vec3& c, std::uint32_t ia,
                              std::uint32_t ib, std::uint32_t ic);

/// The triangle whose corners \a ia, \a ib, \a ic face sides of \a facingA_mm, \a facingB_mm
/// and \a facingC_mm, for callers that have the distances already.
SortedTriangle sortedTriangle(double facingA_mm, double facingB_mm, double facingC_mm,
                              std::uint32_t ia, std::uint32_t ib, std::uint32_t ic);

/// Every triangle of \a layout's markers, appended to \a out with SortedTriangle::body = \a body.
void appendTriangles(std::span<const Vec3> layout, std::size_t body,
                     std::vector<SortedTriangle>& out);

/// Orders triangles by their longest side, so that congruent ones are found by a window search.
inline bool shorterLongestSide(const SortedTriangle& a, const SortedTriangle& b) {
    return a.sides_mm[2] < b.sides_mm[2];
}

/// The bin of a side of \a side_mm when \a perBin bins make a millimetre (bin 0 for a side of
/// zero or less): sides within a bin's width of each other lie in one bin or in two side by side.
inline std::size_t sideBin(double side_mm, double perBin) {
    const double bin = side_mm * perBin;
    return bin > 0.0 ? static_cast<std::size_t>(bin) : 0;
}

/// Marks each of \a triangles that another of them is congruent to within \a tolerance_mm: one
/// of its own body makes it not SortedTriangle::unique, one of another body lists that body in
/// SortedTriangle::alikeBodies (more than kMaxAlikeBodies such bodies make it not unique either).
/// Looks only among triangles whose longest and middle sides lie in the same or neighbouring bins
/// of that width: a scan by longest side alone compared each of the bodies' ten thousands of
/// triangles with hundreds.
void markAlike(std::span<SortedTriangle> triangles, double tolerance_mm);

/**
 * \brief Triangles ordered by their longest side, for finding those near a given one fast.
 *
 * The triangle step looks up every triangle of points of every frame (about a thousand a frame)
 * among thousands of the bodies'. Most match none: a map of which (longest, middle side) cells of
 * \a binWidth_mm hold a triangle within a cell tells so at one look, and the longest sides kept
 * in an array of their own, binned, find the rest without a binary search over the triangles.
 */
class TrianglesByLongestSide {
public:
    /// Whether mayHoldNear() is wanted: its map takes (longest side / bin width)^2 bytes.
    enum class CellMap { None, Built };

    /// Orders \a triangles by longest side, stably (those of equal sides keep their order).
    TrianglesByLongestSide(std::span<const SortedTriangle> triangles, double binWidth_mm,
                           CellMap map = CellMap::Built);

    /// The bin of a side of \a side_mm: sides within one bin width of each other lie in the same
    /// bin or in bins side by side.
    std::size_t binOf(double side_mm) const { return sideBin(side_mm, perBin_); }

    /// False only when no triangle's longest and middle sides lie within a bin of the bins
    /// \a longestBin and \a middleBin (so a triangle whose sides lie in those bins is like none
    /// within the bin width). Always false without a CellMap.
    bool mayHoldNear(std::size_t longestBin, std::size_t middleBin) const {
        return longestBin < cells_ && middleBin < cells_ &&
               nearCell_[longestBin * cells_ + middleBin] != 0;
    }

    /// Those whose longest side lies within [\a from_mm, \a to_mm], in order.
    std::span<const SortedTriangle> within(double from_mm, double to_mm) const;

    std::span<const SortedTriangle> all() const { return triangles_; }

private:
    std::vector<SortedTriangle> triangles_;
    std::vector<double> longest_mm_;
    /// binStart_[b]: the first triangle whose longest side is at least b bins; one past the last
    /// bin, the count.
    std::vector<std::uint32_t> binStart_;
    /// Per (longest, middle) cell, row by longest, whether a triangle lies in it or a cell beside.
    std::vector<std::uint8_t> nearCell_;
    std::size_t cells_ = 0;
    double perBin_ = 1.0;
};

/// The median of \a values (the upper one of an even count); reorders them. Not empty.
double medianOf(std::vector<double>& values);

/// Whether any of \a points lies within sqrt(\a radius2_mm2) of \a p.
bool nearAny(std::span<const Vec3> points, const Vec3& p, double radius2_mm2);

/// Whether every side of \a a is within \a tolerance_mm of the same side of \a b. Inline: the
/// triangle steps compare millions of pairs.
inline bool congruent(const SortedTriangle& a, const SortedTriangle& b, double tolerance_mm) {
    return std::abs(a.sides_mm[2] - b.sides_mm[2]) <= tolerance_mm &&
           std::abs(a.sides_mm[1] - b.sides_mm[1]) <= tolerance_mm &&
           std::abs(a.sides_mm[0] - b.sides_mm[0]) <= tolerance_mm;
}

/// Its height over its longest side (mm).
double triangleHeight(const SortedTriangle& t);

/// Whether its corners can be told apart by its sides at \a tolerance_mm, and it is tall enough
/// over its longest side to fix a turn about it.
bool wellShaped(const SortedTriangle& t, double tolerance_mm);

/// Directions one place was seen from (body frame, unit vectors) that are kept at most.
constexpr std::size_t kMaxViewDirections = 256;

/// \brief \a view kept among \a directions unless one of them lies within the angle whose cosine is
/// \a thinning, or kMaxViewDirections are kept already.
inline void keepViewDirection(std::vector<Vec3>& directions, const Vec3& view, double thinning) {
    if (directions.size() < kMaxViewDirections &&
        std::none_of(directions.begin(), directions.end(),
                     [&](const Vec3& d) { return d.dot(view) >= thinning; }))
        directions.push_back(view);
}

/// \brief Whether one of \a directions lies within the angle whose cosine is \a sameView of \a
/// view.
inline bool seenFromNear(std::span<const Vec3> directions, const Vec3& view, double sameView) {
    return std::any_of(directions.begin(), directions.end(),
                       [&](const Vec3& d) { return d.dot(view) >= sameView; });
}

/// \brief The cone of directions a marker can be seen from, from those it was seen from: its axis
/// the mean of \a directions (unit vectors, body frame), its half-angle the widest of them from
/// the axis widened by \a margin_rad. A marker seen only from within a hemisphere sits on a
/// surface, which hides it from behind: its cone stays within that hemisphere (pi / 2). One seen
/// from wider has at most pi (a sphere on a post, seen from everywhere).
/// A marker seen from no direction has a negative half-angle: seen with nothing.
struct ViewCone {
    Vec3 axis = Vec3::UnitZ();
    double halfAngle_rad = -1.0;
};

inline ViewCone viewCone(std::span<const Vec3> directions, double margin_rad) {
    ViewCone cone;
    Vec3 sum = Vec3::Zero();
    for (const Vec3& d : directions)
        sum += d;
    if (directions.empty())
        return cone;
    if (!(sum.norm() > 1e-9 * static_cast<double>(directions.size()))) {
        cone.halfAngle_rad = std::numbers::pi; // seen from opposite sides alike
        return cone;
    }
    cone.axis = sum.normalized();
    double widest = 0.0;
    for (const Vec3& d : directions)
        widest = std::max(widest, std::acos(std::clamp(d.dot(cone.axis), -1.0, 1.0)));
    const double limit =
        widest < 0.5 * std::numbers::pi ? 0.5 * std::numbers::pi : std::numbers::pi;
    cone.halfAngle_rad = std::min(limit, widest + margin_rad);
    return cone;
}

/// \brief Whether one viewing direction lies inside both cones: two markers that can be seen
/// together, though a session may never have shown them so. Cones that only touch (markers on
/// opposite faces, each seen from its hemisphere) do not count.
inline bool coVisible(const ViewCone& a, const ViewCone& b) {
    if (a.halfAngle_rad < 0.0 || b.halfAngle_rad < 0.0)
        return false;
    const double apart = std::acos(std::clamp(a.axis.dot(b.axis), -1.0, 1.0));
    return apart < a.halfAngle_rad + b.halfAngle_rad - 1e-9;
}

/// The point of \a points_mm nearest to \a there_mm within \a radius_mm (of equally near ones,
/// the last), or null.
inline const Vec3* nearestPoint(std::span<const Vec3> points_mm, const Vec3& there_mm,
                                double radius_mm) {
    double best2 = radius_mm * radius_mm;
    const Vec3* match = nullptr;
    for (const Vec3& p : points_mm) {
        const double d2 = (p - there_mm).squaredNorm();
        if (d2 <= best2) {
            best2 = d2;
            match = &p;
        }
    }
    return match;
}

/// \a body's pose at \a t_s carried on from its poses at \a t0_s and \a t1_s (t0 < t1): its
/// centre \a centre_body (body frame) moves on at its speed, and it turns on at its turn rate.
RigidTransform extrapolate(const RigidTransform& at0, double t0_s, const RigidTransform& at1,
                           double t1_s, double t_s, const Vec3& centre_body);

/// A set of a layout's markers (up to 128), one bit each.
using MarkerBits = std::array<std::uint64_t, 2>;
inline bool holds(const MarkerBits& set, std::size_t marker) {
    return ((set[marker / 64] >> (marker % 64)) & 1U) != 0;
}
inline void add(MarkerBits& set, std::size_t marker) {
    set[marker / 64] |= std::uint64_t{1} << (marker % 64);
}

/**
 * \brief The rigid groups of \a layout (body frame, mm) seen in \a views (the markers matched in
 * each frame): sets of markers seen together, merged while two share three or more markers that
 * lie at least \a minSpread_mm off one line. A frame fixes the shape of what it shows; two such
 * shapes that share three markers off a line fix each other; markers of different groups are
 * tied by markers on one line at most, about which one group may turn against the other.
 */
std::vector<MarkerBits> rigidGroupsOf(std::vector<MarkerBits> views, std::span<const Vec3> layout,
                                      double minSpread_mm);

} // namespace edgetrack::completion_detail
