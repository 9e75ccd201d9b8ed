// Geometry the completion steps share: extents, transform agreement, layout registration.
#include "core/completion_geometry.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <optional>
#include <utility>
#include <vector>

#include "core/rigid_fit.hpp"

namespace edgetrack::completion_detail {

namespace {

/// Congruent triangle pairs a registration tries at most: a self-similar layout (a sphere of many
/// markers) has thousands, and the first few hundred already show that it registers several ways.
constexpr std::size_t kRegistrationCandidates = 20000;
/// Triangles of a part lower than this (mm, twice the area over the longest side) leave the turn
/// about their long side too loosely held to place a layout by.
constexpr double kMinTriangleHeight_mm = 8.0;

/// The indices 0 .. \a count - 1 ordered by their key (stably) into \a order, and where each key's
/// run starts into \a start (\a keys + 1 entries, the last \a count); every key below \a keys.
template <typename KeyOf>
void countingSort(std::size_t count, std::size_t keys, KeyOf keyOf,
                  std::vector<std::uint32_t>& start, std::vector<std::uint32_t>& order) {
    start.assign(keys + 1, 0);
    for (std::size_t i = 0; i < count; ++i)
        ++start[keyOf(i) + 1];
    for (std::size_t k = 0; k < keys; ++k)
        start[k + 1] += start[k];
    order.resize(count);
    std::vector<std::uint32_t> next(start.begin(), start.end() - 1);
    for (std::size_t i = 0; i < count; ++i)
        order[next[keyOf(i)]++] = static_cast<std::uint32_t>(i);
}

} // namespace

Extent extentOf(std::span<const Vec3> markers_mm) {
    Extent e;
    if (markers_mm.empty())
        return e;
    for (const Vec3& m : markers_mm)
        e.centre += m;
    e.centre /= static_cast<double>(markers_mm.size());
    for (const Vec3& m : markers_mm)
        e.radius_mm = std::max(e.radius_mm, (m - e.centre).norm());
    return e;
}

double disagreement_mm(const RigidTransform& a, const RigidTransform& b, const Extent& ball) {
    return (a.apply(ball.centre) - b.apply(ball.centre)).norm() +
           ball.radius_mm * rotationAngleBetween_rad(a.rotation, b.rotation);
}

std::size_t framesSeenApart(std::span<const RigidTransform> T_rig_from_a,
                            std::span<const RigidTransform> T_rig_from_b,
                            std::span<const std::size_t> frames, const Extent& ballA,
                            const Extent& ballB, const RigidTransform& T_a_from_b,
                            double tolerance_mm) {
    std::size_t apart = 0;
    for (const std::size_t f : frames) {
        const double centres_mm =
            (T_rig_from_a[f].apply(ballA.centre) - T_rig_from_b[f].apply(ballB.centre)).norm();
        if (centres_mm <= ballA.radius_mm + ballB.radius_mm)
            continue;
        const RigidTransform relative = T_rig_from_a[f].inverse() * T_rig_from_b[f];
        apart += disagreement_mm(relative, T_a_from_b, ballB) > tolerance_mm ? 1U : 0U;
    }
    return apart;
}

std::optional<RigidFit> fitDroppingWorst(std::vector<Vec3>& from, std::vector<Vec3>& to,
                                         double tolerance_mm) {
    while (from.size() >= 3) {
        std::optional<RigidFit> fit = fitRigid(from, to);
        if (!fit)
            return std::nullopt;
        std::size_t worst = 0;
        double worstResidual = 0.0;
        for (std::size_t i = 0; i < from.size(); ++i) {
            const double r = (fit->transform.apply(from[i]) - to[i]).norm();
            if (r > worstResidual) {
                worstResidual = r;
                worst = i;
            }
        }
        if (worstResidual <= tolerance_mm)
            return fit;
        from.erase(from.begin() + static_cast<std::ptrdiff_t>(worst));
        to.erase(to.begin() + static_cast<std::ptrdiff_t>(worst));
    }
    return std::nullopt;
}

Agreement mostAgreed(std::span<const RigidTransform> transforms, const Extent& ball,
                     double tolerance_mm, std::size_t step) {
    Agreement best;
    for (std::size_t k = 0; k < transforms.size(); k += std::max<std::size_t>(step, 1)) {
        std::size_t agree = 0;
        for (const RigidTransform& t : transforms)
            if (disagreement_mm(t, transforms[k], ball) <= tolerance_mm)
                ++agree;
        if (agree > best.agree)
            best = {k, agree};
    }
    return best;
}

Registration registerLayout(std::span<const Vec3> part, std::span<const Vec3> whole,
                            double tolerance_mm, double matchTolerance_mm) {
    Registration best;
    const std::size_t n = part.size();
    const std::size_t m = whole.size();
    if (n < 3 || m < 3)
        return best;
    const double tol2 = matchTolerance_mm * matchTolerance_mm;
    std::vector<Vec3> from, to;
    std::vector<std::uint32_t> onto(n);
    constexpr std::uint32_t kNone = ~0U;
    auto matchOn = [&](const RigidTransform& t) {
        from.clear();
        to.clear();
        for (std::size_t i = 0; i < n; ++i) {
            const Vec3 moved = t.apply(part[i]);
            onto[i] = kNone;
            for (std::uint32_t w = 0; w < m; ++w)
                if ((moved - whole[w]).squaredNorm() <= tol2) {
                    from.push_back(part[i]);
                    to.push_back(whole[w]);
                    onto[i] = w;
                    break;
                }
        }
        return from.size();
    };
    // The whole's pairs by distance, so that each side of a part's triangle finds its
    // counterparts by a binary search rather than by trying every pair.
    struct Pair {
        double d_mm;
        std::uint32_t x, y;
    };
    std::vector<Pair> pairs;
    pairs.reserve(m * (m - 1));
    // Each distance once: every triangle's third corner is looked for among all of them.
    std::vector<double> wholeDistance_mm(m * m, 0.0);
    for (std::uint32_t x = 0; x < m; ++x)
        for (std::uint32_t y = 0; y < m; ++y)
            if (x != y) {
                wholeDistance_mm[x * m + y] = (whole[x] - whole[y]).norm();
                pairs.push_back({wholeDistance_mm[x * m + y], x, y});
            }
    std::sort(pairs.begin(), pairs.end(),
              [](const Pair& l, const Pair& r) { return l.d_mm < r.d_mm; });
    auto near = [&](double d_mm) {
        const auto lo = std::lower_bound(pairs.begin(), pairs.end(), d_mm - tolerance_mm,
                                         [](const Pair& p, double v) { return p.d_mm < v; });
        const auto hi = std::upper_bound(lo, pairs.end(), d_mm + tolerance_mm,
                                         [](double v, const Pair& p) { return v < p.d_mm; });
        return std::span<const Pair>(lo, hi);
    };
    // Every well-spread triangle of the part against every congruent one of the whole, each
    // placement refitted on all the markers it matches: the answer must not depend on the order
    // in which either layout lists its markers. `placed` sees each (transform, count) with the
    // part's markers in `onto`.
    auto forEachPlacement = [&](auto&& placed) {
        std::size_t candidates = 0;
        for (std::size_t i = 0; i < n && candidates < kRegistrationCandidates; ++i)
            for (std::size_t j = i + 1; j < n && candidates < kRegistrationCandidates; ++j) {
                const std::span<const Pair> sidesAB = near((part[i] - part[j]).norm());
                if (sidesAB.empty())
                    continue;
                for (std::size_t k = j + 1; k < n; ++k) {
                    const Vec3 &a = part[i], &b = part[j], &c = part[k];
                    const double twiceArea = (b - a).cross(c - a).norm();
                    const double longest =
                        std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()});
                    if (longest <= 0.0 || twiceArea / longest < kMinTriangleHeight_mm)
                        continue;
                    const double dac = (a - c).norm(), dbc = (b - c).norm();
                    for (const Pair& xy : sidesAB) {
                        const double* fromX = &wholeDistance_mm[xy.x * m];
                        const double* fromY = &wholeDistance_mm[xy.y * m];
                        for (std::uint32_t z = 0; z < m; ++z) {
                            if (z == xy.x || z == xy.y || std::abs(fromX[z] - dac) > tolerance_mm ||
                                std::abs(fromY[z] - dbc) > tolerance_mm)
                                continue;
                            ++candidates;
                            const Vec3 tri[3] = {a, b, c};
                            const Vec3 target[3] = {whole[xy.x], whole[xy.y], whole[z]};
                            const std::optional<RigidFit> seed = fitRigid(tri, target);
                            if (!seed || matchOn(seed->transform) < 3)
                                continue;
                            const std::optional<RigidFit> all = fitRigid(from, to);
                            const RigidTransform t = all ? all->transform : seed->transform;
                            placed(t, matchOn(t));
                        }
                    }
                }
            }
    };
    std::vector<std::uint32_t> bestOnto;
    forEachPlacement([&](const RigidTransform& t, std::size_t count) {
        if (count > best.matched) {
            best.matched = count;
            best.T_whole_from_part = t;
            bestOnto = onto;
        }
    });
    if (best.matched == 0)
        return best;
    // Another placement is one that shares fewer than three of the best's pairs: one that shares
    // three is the same placement, matched a little differently. A second pass, rather than
    // keeping every placement until the best is known.
    forEachPlacement([&](const RigidTransform&, std::size_t count) {
        std::size_t common = 0;
        for (std::size_t i = 0; i < n; ++i)
            common += onto[i] != kNone && onto[i] == bestOnto[i] ? 1U : 0U;
        if (common < 3)
            best.runnerUp = std::max(best.runnerUp, count);
    });
    return best;
}

std::optional<RigidTransform> soleSharedTriangle(std::span<const Vec3> part,
                                                 std::span<const Vec3> whole,
                                                 const TriangleTieLimits& limits) {
    if (part.size() < 3 || whole.size() < 3)
        return std::nullopt;
    std::vector<SortedTriangle> ofPart, triangles;
    appendTriangles(part, 0, ofPart);
    appendTriangles(whole, 0, triangles);
    const TrianglesByLongestSide ofWhole(triangles, limits.uniqueness_mm,
                                         TrianglesByLongestSide::CellMap::None);
    auto longest = [](const SortedTriangle& t) { return t.sides_mm[2]; };
    const SortedTriangle* soleOfPart = nullptr;
    const SortedTriangle* soleOfWhole = nullptr;
    std::size_t compared = 0;
    for (const SortedTriangle& t : ofPart) {
        for (const SortedTriangle& w :
             ofWhole.within(longest(t) - limits.uniqueness_mm, longest(t) + limits.uniqueness_mm)) {
            if (++compared > limits.budget)
                return std::nullopt;
            if (!congruent(t, w, limits.uniqueness_mm))
                continue;
            if (soleOfPart != nullptr)
                return std::nullopt; // a second likeness: the shared triangle is no identity
            soleOfPart = &t;
            soleOfWhole = &w;
        }
    }
    if (soleOfPart == nullptr || !congruent(*soleOfPart, *soleOfWhole, limits.tolerance_mm) ||
        !wellShaped(*soleOfPart, limits.tolerance_mm))
        return std::nullopt;
    std::array<Vec3, 3> from, to;
    for (std::size_t c = 0; c < 3; ++c) {
        from[c] = part[soleOfPart->corners[c]];
        to[c] = whole[soleOfWhole->corners[c]];
    }
    const std::optional<RigidFit> fit = fitRigid(from, to);
    if (!fit)
        return std::nullopt;
    const Vec3 centre_mm = (from[0] + from[1] + from[2]) / 3.0;
    double reach_mm = 0.0;
    for (const Vec3& m : part)
        reach_mm = std::max(reach_mm, (m - centre_mm).norm());
    const double leverError_mm =
        reach_mm * std::max(fit->rms_mm, limits.precision_mm) / triangleHeight(*soleOfPart);
    if (!(leverError_mm <= limits.placement_mm))
        return std::nullopt;
    return fit->transform;
}

bool sameLayout(const MarkerModel& a, const MarkerModel& b) {
    const auto sameMarker = [](const Vec3& x, const Vec3& y) {
        return (x - y).squaredNorm() <= kSameMarker_mm * kSameMarker_mm;
    };
    const auto sameEdge = [](const ModelEdge& x, const ModelEdge& y) {
        return x.from == y.from && x.to == y.to;
    };
    return std::equal(a.markers_model_mm.begin(), a.markers_model_mm.end(),
                      b.markers_model_mm.begin(), b.markers_model_mm.end(), sameMarker) &&
           std::equal(a.edges.begin(), a.edges.end(), b.edges.begin(), b.edges.end(), sameEdge);
}

void appendTriangles(std::span<const Vec3> layout, std::size_t body,
                     std::vector<SortedTriangle>& out) {
    const auto n = static_cast<std::uint32_t>(layout.size());
    for (std::uint32_t i = 0; i < n; ++i)
        for (std::uint32_t j = i + 1; j < n; ++j)
            for (std::uint32_t k = j + 1; k < n; ++k) {
                SortedTriangle t = sortedTriangle(layout[i], layout[j], layout[k], i, j, k);
                t.body = body;
                out.push_back(t);
            }
}

void markAlike(std::span<SortedTriangle> triangles, double tolerance_mm) {
    if (triangles.size() < 2 || !(tolerance_mm > 0.0))
        return;
    const double perBin = 1.0 / tolerance_mm;
    std::size_t bins = 0;
    for (const SortedTriangle& t : triangles)
        bins = std::max(bins, sideBin(t.sides_mm[2], perBin) + 1);
    // Cells of (longest, middle) bins, with a margin of one on each side so that every
    // neighbour of a cell exists; the triangles' indices counting-sorted by cell.
    const std::size_t row = bins + 2;
    auto cellOf = [&](const SortedTriangle& t) {
        return (sideBin(t.sides_mm[2], perBin) + 1) * row + sideBin(t.sides_mm[1], perBin) + 1;
    };
    std::vector<std::uint32_t> cellStart, inCell;
    countingSort(
        triangles.size(), row * row, [&](std::size_t i) { return cellOf(triangles[i]); }, cellStart,
        inCell);
    for (std::size_t i = 0; i < triangles.size(); ++i) {
        SortedTriangle& t = triangles[i];
        const std::size_t cell = cellOf(t);
        for (std::size_t l = cell - row; l <= cell + row && t.unique; l += row)
            for (std::size_t k = cellStart[l - 1]; k < cellStart[l + 2] && t.unique; ++k) {
                const SortedTriangle& other = triangles[inCell[k]];
                if (inCell[k] == i || !congruent(t, other, tolerance_mm))
                    continue;
                const auto body = static_cast<std::uint32_t>(other.body);
                const auto listed = t.alikeBodies.begin() + t.alikeCount;
                const bool known = std::find(t.alikeBodies.begin(), listed, body) != listed;
                if (other.body == t.body ||
                    (!known && t.alikeCount == SortedTriangle::kMaxAlikeBodies))
                    t.unique = false;
                else if (!known)
                    t.alikeBodies[t.alikeCount++] = body;
            }
    }
}

TrianglesByLongestSide::TrianglesByLongestSide(std::span<const SortedTriangle> triangles,
                                               double binWidth_mm, CellMap map)
    : perBin_(1.0 / (binWidth_mm > 0.0 ? binWidth_mm : 1.0)) {
    // Sorted by bin (counting), then within each bin: a layout of 40 markers has ten thousand
    // triangles, and a sort of them all was the larger part of a layout comparison.
    std::size_t bins = 0;
    for (const SortedTriangle& t : triangles)
        bins = std::max(bins, binOf(t.sides_mm[2]) + 1);
    std::vector<std::uint32_t> order;
    countingSort(
        triangles.size(), bins, [&](std::size_t i) { return binOf(triangles[i].sides_mm[2]); },
        binStart_, order);
    triangles_.reserve(triangles.size());
    for (const std::uint32_t i : order)
        triangles_.push_back(triangles[i]);
    for (std::size_t b = 0; b < bins; ++b)
        std::stable_sort(triangles_.begin() + binStart_[b], triangles_.begin() + binStart_[b + 1],
                         shorterLongestSide);
    longest_mm_.reserve(triangles_.size());
    for (const SortedTriangle& t : triangles_)
        longest_mm_.push_back(t.sides_mm[2]);
    if (map == CellMap::None)
        return;
    // A middle side is never longer than the longest, so one bin count serves both.
    cells_ = bins + 1;
    nearCell_.assign(cells_ * cells_, 0);
    for (const SortedTriangle& t : triangles_) {
        const std::size_t l = binOf(t.sides_mm[2]), m = binOf(t.sides_mm[1]);
        for (std::size_t nl = l > 0 ? l - 1 : 0; nl <= l + 1 && nl < cells_; ++nl)
            for (std::size_t nm = m > 0 ? m - 1 : 0; nm <= m + 1 && nm < cells_; ++nm)
                nearCell_[nl * cells_ + nm] = 1;
    }
}

std::span<const SortedTriangle> TrianglesByLongestSide::within(double from_mm, double to_mm) const {
    if (triangles_.empty() || !(from_mm <= to_mm) || to_mm < longest_mm_.front())
        return {};
    const std::size_t last = binStart_.size() - 1;
    const std::size_t fromBin = std::min(binOf(from_mm), last);
    const std::size_t toBin = std::min(binOf(to_mm) + 1, last);
    const auto begin = longest_mm_.begin();
    const auto first =
        std::lower_bound(begin + binStart_[fromBin], begin + binStart_[toBin], from_mm);
    const auto end = std::upper_bound(first, begin + binStart_[toBin], to_mm);
    return std::span(triangles_)
        .subspan(static_cast<std::size_t>(first - begin), static_cast<std::size_t>(end - first));
}

double medianOf(std::vector<double>& values) {
    const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
    std::nth_element(values.begin(), middle, values.end());
    return *middle;
}

bool nearAny(std::span<const Vec3> points, const Vec3& p, double radius2_mm2) {
    return std::any_of(points.begin(), points.end(),
                       [&](const Vec3& q) { return (q - p).squaredNorm() <= radius2_mm2; });
}

SortedTriangle sortedTriangle(const Vec3& a, const Vec3& b, const Vec3& c, std::uint32_t ia,
                              std::uint32_t ib, std::uint32_t ic) {
    return sortedTriangle((b - c).norm(), (a - c).norm(), (a - b).norm(), ia, ib, ic);
}

SortedTriangle sortedTriangle(double facingA_mm, double facingB_mm, double facingC_mm,
                              std::uint32_t ia, std::uint32_t ib, std::uint32_t ic) {
    std::array<std::pair<double, std::uint32_t>, 3> facing = {
        {{facingA_mm, ia}, {facingB_mm, ib}, {facingC_mm, ic}}};
    // Three compare-and-swaps: this runs for every triple of points in every frame.
    if (facing[1] < facing[0])
        std::swap(facing[0], facing[1]);
    if (facing[2] < facing[1])
        std::swap(facing[1], facing[2]);
    if (facing[1] < facing[0])
        std::swap(facing[0], facing[1]);
    SortedTriangle t;
    for (std::size_t i = 0; i < 3; ++i) {
        t.sides_mm[i] = facing[i].first;
        t.corners[i] = facing[i].second;
    }
    return t;
}

double triangleHeight(const SortedTriangle& t) {
    const auto& s = t.sides_mm;
    const double half = 0.5 * (s[0] + s[1] + s[2]);
    const double areaSquared = half * (half - s[0]) * (half - s[1]) * (half - s[2]); // Heron
    return areaSquared > 0.0 ? 2.0 * std::sqrt(areaSquared) / s[2] : 0.0;
}

bool wellShaped(const SortedTriangle& t, double tolerance_mm) {
    const auto& s = t.sides_mm;
    return s[1] - s[0] > 2.0 * tolerance_mm && s[2] - s[1] > 2.0 * tolerance_mm &&
           triangleHeight(t) > 4.0 * tolerance_mm;
}

RigidTransform extrapolate(const RigidTransform& at0, double t0_s, const RigidTransform& at1,
                           double t1_s, double t_s, const Vec3& centre_body) {
    const double s = (t_s - t1_s) / (t1_s - t0_s);
    const Vec3 c0 = at0.apply(centre_body), c1 = at1.apply(centre_body);
    const Eigen::AngleAxisd turn(at1.rotation * at0.rotation.inverse());
    RigidTransform out;
    out.rotation = Quat(Eigen::AngleAxisd(turn.angle() * s, turn.axis())) * at1.rotation;
    out.rotation.normalize();
    out.translation_mm = c1 + s * (c1 - c0) - out.rotation * centre_body;
    return out;
}

namespace {

/// Whether the markers of \a shared lie at least \a minSpread_mm off the line through the two
/// farthest apart of them.
bool offOneLine(const MarkerBits& shared, std::span<const Vec3> layout, double minSpread_mm) {
    std::vector<Vec3> points;
    for (std::size_t k = 0; k < layout.size(); ++k)
        if (holds(shared, k))
            points.push_back(layout[k]);
    return edgetrack::offOneLine(points, minSpread_mm);
}

} // namespace

std::vector<MarkerBits> rigidGroupsOf(std::vector<MarkerBits> views, std::span<const Vec3> layout,
                                      double minSpread_mm) {
    std::sort(views.begin(), views.end());
    views.erase(std::unique(views.begin(), views.end()), views.end());
    std::vector<MarkerBits> groups;
    for (const MarkerBits& view : views) {
        if (!offOneLine(view, layout, minSpread_mm))
            continue;
        groups.push_back(view);
        // Merge the new group with every group that shares three markers off a line with it.
        bool merged = true;
        while (merged) {
            merged = false;
            MarkerBits& last = groups.back();
            for (std::size_t g = 0; g + 1 < groups.size(); ++g)
                if (offOneLine({groups[g][0] & last[0], groups[g][1] & last[1]}, layout,
                               minSpread_mm)) {
                    last[0] |= groups[g][0];
                    last[1] |= groups[g][1];
                    groups.erase(groups.begin() + static_cast<std::ptrdiff_t>(g));
                    merged = true;
                    break;
                }
        }
    }
    return groups;
}

} // namespace edgetrack::completion_detail
