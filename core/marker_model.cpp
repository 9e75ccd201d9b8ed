// Rigid marker models: storage, canonical frames, and S_min from self- and cross-congruences.
#include "core/marker_model.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/Eigenvalues>

#include "core/marker_set.hpp"
#include "core/rigid_fit.hpp"

namespace edgetrack {

MarkerModel::MarkerModel(std::size_t maxMarkers)
    : markers_model_mm(maxMarkers)
    , edges(maxMarkers * (maxMarkers > 0 ? maxMarkers - 1 : 0) / 2) {}

bool MarkerModel::assign(const MarkerModel& other) {
    if (other.markers_model_mm.size() > markers_model_mm.capacity() ||
        other.edges.size() > edges.capacity())
        return false;
    id = other.id;
    sMin = other.sMin;
    sameShapeAs = other.sameShapeAs;
    markers_model_mm.clear();
    for (const Vec3& m : other.markers_model_mm)
        markers_model_mm.push_back(m);
    edges.clear();
    for (const ModelEdge& e : other.edges)
        edges.push_back(e);
    return true;
}

void MarkerModel::clear() {
    id = 0;
    sMin = 4;
    sameShapeAs = -1;
    markers_model_mm.clear();
    edges.clear();
}

bool MarkerModel::hasEdge(std::size_t a, std::size_t b) const {
    if (a > b)
        std::swap(a, b);
    return std::any_of(edges.begin(), edges.end(),
                       [&](const ModelEdge& e) { return e.from == a && e.to == b; });
}

namespace {

using Adjacency = FixedVector<MarkerSet, MarkerSet::kCapacity>;

void buildAdjacency(const MarkerModel& model, Adjacency& adjacency) {
    adjacency.clear();
    adjacency.resize(std::min(model.markers_model_mm.size(), MarkerSet::kCapacity));
    for (const ModelEdge& e : model.edges) {
        if (e.from >= adjacency.size() || e.to >= adjacency.size())
            continue;
        adjacency[e.from].insert(e.to);
        adjacency[e.to].insert(e.from);
    }
}

// A triangle this flat fixes the rotation about its long side poorly; it proves nothing.
bool wellShaped(const Vec3& a, const Vec3& b, const Vec3& c, double minHeight_mm) {
    const double twiceArea = (b - a).cross(c - a).norm();
    const double longest = std::max({(b - a).norm(), (c - a).norm(), (c - b).norm()});
    return longest > 0.0 && twiceArea / longest >= minHeight_mm;
}

// Markers of `from` that land within tolerance of some marker of `to` under `transform`.
std::size_t countCongruent(const MarkerModel& from, const MarkerModel& to,
                           const RigidTransform& transform, double tolerance2) {
    std::size_t count = 0;
    for (const Vec3& m : from.markers_model_mm) {
        const Vec3 moved = transform.apply(m);
        for (const Vec3& n : to.markers_model_mm)
            if ((moved - n).squaredNorm() <= tolerance2) {
                ++count;
                break;
            }
    }
    return count;
}

/// Markers of `from` that land within tolerance of some marker of `to` (\a toByX, sorted by x)
/// under `transform`, counted until the count can no longer exceed \a best: only a larger count
/// matters to a search for the largest. The window in x holds every marker within tolerance.
std::size_t countCongruentBeyond(const MarkerModel& from, std::span<const Vec3> toByX,
                                 const RigidTransform& transform, double tolerance,
                                 std::size_t best) {
    const double tolerance2 = tolerance * tolerance;
    // Wider than the tolerance by far more than rounding: the distance test decides.
    const double window = tolerance * (1.0 + 1e-9);
    const std::size_t size = from.markers_model_mm.size();
    // As a matrix: half the arithmetic of a quaternion's rotation, for every marker.
    const Mat3 rotation = transform.rotationMatrix();
    std::size_t count = 0;
    for (std::size_t i = 0; i < size; ++i) {
        if (count + (size - i) <= best)
            return count;
        const Vec3 moved = rotation * from.markers_model_mm[i] + transform.translation_mm;
        auto it = std::lower_bound(toByX.begin(), toByX.end(), moved.x() - window,
                                   [](const Vec3& n, double x) { return n.x() < x; });
        for (; it != toByX.end() && it->x() <= moved.x() + window; ++it)
            if ((moved - *it).squaredNorm() <= tolerance2) {
                ++count;
                break;
            }
    }
    return count;
}

/// Calls visit(x, y) for every co-visible ordered pair of \a adjB, whatever its length, and
/// corners(x, y, ...) visit(z) for every marker co-visible with both: the plain walk, for a few
/// triangles.
struct EveryPair {
    const Adjacency& adjB;
    template <typename Visit>
    void operator()(double, double, Visit&& visit) const {
        for (std::size_t x = 0; x < adjB.size(); ++x)
            adjB[x].forEach([&](std::size_t y) { visit(x, y); });
    }
    template <typename Visit>
    void corners(std::size_t x, std::size_t y, double, double, Visit&& visit) const {
        (adjB[x] & adjB[y]).forEach(visit);
    }
};

/// A window of float lengths that holds every length within \a tolerance of \a d_mm by the
/// double test (and a few just outside, which the caller's exact test refuses).
struct LengthWindow {
    float low;
    float high;
    LengthWindow(double d_mm, double tolerance)
        : low(static_cast<float>(d_mm - tolerance) - 1e-3F)
        , high(static_cast<float>(d_mm + tolerance) + 1e-3F) {}
    /// Calls visit(pair) for the pairs of \a sorted (by length) within the window.
    template <typename Visit>
    void forEachIn(std::span<const SminWorkspace::Pair> sorted, Visit&& visit) const {
        auto it = std::lower_bound(
            sorted.begin(), sorted.end(), low,
            [](const SminWorkspace::Pair& p, float value) { return p.length_mm < value; });
        for (; it != sorted.end() && it->length_mm <= high; ++it)
            visit(*it);
    }
};

/// Calls visit(x, y) for the co-visible ordered pairs whose length lies near \a d_mm, found by a
/// binary search in the pairs sorted by length, and corners(x, y, ...) visit(z) for the markers
/// co-visible with both whose distance from x lies near the given length, found the same way in
/// x's pairs: for every triangle of a model against every pair of another, the walk over all
/// pairs and then over all their common neighbours is what made S_min dear.
struct PairsByLength {
    const Adjacency& adjB;
    std::span<const SminWorkspace::Pair> byLength;
    /// The same pairs ordered by x, then by length; x's start at byCorner[cornerStart[x]].
    std::span<const SminWorkspace::Pair> byCorner;
    std::span<const std::uint32_t> cornerStart;
    template <typename Visit>
    void operator()(double d_mm, double tolerance, Visit&& visit) const {
        LengthWindow(d_mm, tolerance).forEachIn(byLength, [&](const SminWorkspace::Pair& p) {
            visit(p.x, p.y);
        });
    }
    template <typename Visit>
    void corners(std::size_t x, std::size_t y, double dxz_mm, double tolerance,
                 Visit&& visit) const {
        const auto ofX = byCorner.subspan(cornerStart[x], cornerStart[x + 1] - cornerStart[x]);
        LengthWindow(dxz_mm, tolerance).forEachIn(ofX, [&](const SminWorkspace::Pair& p) {
            if (p.y != y && adjB[y].contains(p.y))
                visit(p.y);
        });
    }
};

/// Fills \a pairs with b's co-visible ordered pairs sorted by length, \a byCorner with them
/// sorted by first marker and then length, and \a cornerStart with where each marker's begin.
void sortPairs(const MarkerModel& b, const Adjacency& adjB, SminWorkspace::PairList& pairs,
               SminWorkspace::PairList& byCorner, std::vector<std::uint32_t>& cornerStart) {
    pairs.clear();
    const auto& pb = b.markers_model_mm;
    for (std::size_t x = 0; x < adjB.size(); ++x)
        adjB[x].forEach([&](std::size_t y) {
            pairs.push_back({static_cast<float>((pb[x] - pb[y]).norm()),
                             static_cast<std::uint8_t>(x), static_cast<std::uint8_t>(y)});
        });
    std::sort(pairs.begin(), pairs.end(),
              [](const SminWorkspace::Pair& l, const SminWorkspace::Pair& r) {
                  return l.length_mm != r.length_mm ? l.length_mm < r.length_mm
                         : l.x != r.x               ? l.x < r.x
                                                    : l.y < r.y;
              });
    byCorner.assign(pairs.begin(), pairs.end());
    // std::sort, not a stable sort by x alone: that takes a buffer from the heap.
    std::sort(byCorner.begin(), byCorner.end(),
              [](const SminWorkspace::Pair& l, const SminWorkspace::Pair& r) {
                  return l.x != r.x                   ? l.x < r.x
                         : l.length_mm != r.length_mm ? l.length_mm < r.length_mm
                                                      : l.y < r.y;
              });
    cornerStart.assign(adjB.size() + 1, 0);
    for (const SminWorkspace::Pair& p : byCorner)
        ++cornerStart[p.x + 1u];
    for (std::size_t x = 0; x < adjB.size(); ++x)
        cornerStart[x + 1] += cornerStart[x];
}

/**
 * Call visit(x, y, z) for every co-visible triangle of `b` whose sides match (within `tolerance`)
 * the sides |ij|, |ik|, |jk| of a triangle, in that order; stop when visit returns true. The
 * pairs (x, y) and corners z come from \a pairsNear (EveryPair or PairsByLength); which triangles
 * are visited does not depend on it, only their order.
 * \return whether a visit stopped the search.
 */
template <typename PairsNear, typename Visit>
bool forEachCongruentTriangle(const Vec3& i, const Vec3& j, const Vec3& k, std::span<const Vec3> pb,
                              double tolerance, const PairsNear& pairsNear, Visit&& visit) {
    const double dij = (i - j).norm();
    const double dik = (i - k).norm();
    const double djk = (j - k).norm();
    bool stopped = false;
    pairsNear(dij, tolerance, [&](std::size_t x, std::size_t y) {
        if (stopped || std::abs((pb[x] - pb[y]).norm() - dij) > tolerance)
            return;
        pairsNear.corners(x, y, dik, tolerance, [&](std::size_t z) {
            if (stopped || std::abs((pb[x] - pb[z]).norm() - dik) > tolerance ||
                std::abs((pb[y] - pb[z]).norm() - djk) > tolerance)
                return;
            stopped = visit(x, y, z);
        });
    });
    return stopped;
}

// The most markers of `a` that fit `b` under one transform other than the identity of a model
// with itself, found from congruent co-visible triangles, or any number of at least \a enough
// once one transform reaches it (the caller decides nothing by more). The result is a maximum,
// so the order in which the pairs of b come does not matter.
std::size_t largestCongruence(const MarkerModel& a, const Adjacency& adjA, const MarkerModel& b,
                              const PairsByLength& pairsNear, std::span<const Vec3> markersByXB,
                              bool self, std::size_t enough, const SminConfig& config) {
    const double tol = config.tolerance_mm;
    const auto& pa = a.markers_model_mm;
    const auto& pb = b.markers_model_mm;
    std::size_t best = 0;
    for (std::size_t i = 0; i < adjA.size() && best < enough; ++i) {
        adjA[i].forEach([&](std::size_t j) {
            if (j <= i || best >= enough)
                return;
            (adjA[i] & adjA[j]).forEach([&](std::size_t k) {
                if (k <= j || best >= enough || !wellShaped(pa[i], pa[j], pa[k], 2.0 * tol))
                    return;
                forEachCongruentTriangle(
                    pa[i], pa[j], pa[k], pb.span(), tol, pairsNear,
                    [&](std::size_t x, std::size_t y, std::size_t z) {
                        if (self && x == i && y == j && z == k)
                            return false;
                        const std::optional<RigidTransform> fit =
                            fitTriangle({pa[i], pa[j], pa[k]}, {pb[x], pb[y], pb[z]});
                        if (fit)
                            best = std::max(best,
                                            countCongruentBeyond(a, markersByXB, *fit, tol, best));
                        return best >= enough;
                    });
            });
        });
    }
    return best;
}

} // namespace

namespace {

/// A rigid transform (T_b_from_a) that puts at least \a needed of a's markers onto b's, tried
/// from a's widest co-visible triangles: copies and parts share almost every triangle, so a few
/// wide ones find the transform; a full congruence search (computeSmin) is far dearer.
std::optional<RigidTransform> mapOnto(const MarkerModel& a, const MarkerModel& b, double needed,
                                      double tol) {
    Adjacency adjA, adjB;
    buildAdjacency(a, adjA);
    buildAdjacency(b, adjB);
    const auto& pa = a.markers_model_mm;
    const auto& pb = b.markers_model_mm;
    constexpr std::size_t kTriangles = 8;
    struct Triangle {
        std::size_t i, j, k;
        double twiceArea;
    };
    FixedVector<Triangle, kTriangles> widest;
    for (std::size_t i = 0; i < adjA.size(); ++i)
        adjA[i].forEach([&](std::size_t j) {
            if (j <= i)
                return;
            (adjA[i] & adjA[j]).forEach([&](std::size_t k) {
                if (k <= j)
                    return;
                const Triangle t{i, j, k, (pa[j] - pa[i]).cross(pa[k] - pa[i]).norm()};
                if (!widest.full()) {
                    widest.push_back(t);
                    return;
                }
                auto smallest = std::min_element(
                    widest.begin(), widest.end(),
                    [](const Triangle& x, const Triangle& y) { return x.twiceArea < y.twiceArea; });
                if (smallest->twiceArea < t.twiceArea)
                    *smallest = t;
            });
        });
    std::optional<RigidTransform> found;
    for (const Triangle& t : widest) {
        forEachCongruentTriangle(pa[t.i], pa[t.j], pa[t.k], pb.span(), tol, EveryPair{adjB},
                                 [&](std::size_t x, std::size_t y, std::size_t z) {
                                     const Vec3 from[3] = {pa[t.i], pa[t.j], pa[t.k]};
                                     const Vec3 to[3] = {pb[x], pb[y], pb[z]};
                                     const std::optional<RigidFit> fit = fitRigid(from, to);
                                     if (!fit || static_cast<double>(countCongruent(
                                                     a, b, fit->transform, tol * tol)) < needed)
                                         return false;
                                     found = fit->transform;
                                     return true;
                                 });
        if (found)
            return found;
    }
    return std::nullopt;
}

} // namespace

std::optional<RigidTransform> sameShapeTransform(const MarkerModel& a, const MarkerModel& b,
                                                 const SminConfig& config) {
    const std::size_t smaller = std::min(a.markers_model_mm.size(), b.markers_model_mm.size());
    const std::size_t larger = std::max(a.markers_model_mm.size(), b.markers_model_mm.size());
    if (smaller < 3 ||
        static_cast<double>(smaller) < config.sameShapeShare * static_cast<double>(larger))
        return std::nullopt;
    return mapOnto(a, b, config.sameShapeShare * static_cast<double>(smaller), config.tolerance_mm);
}

bool sameShape(const MarkerModel& a, const MarkerModel& b, const SminConfig& config) {
    return sameShapeTransform(a, b, config).has_value();
}

bool isPartOf(const MarkerModel& part, const MarkerModel& whole, const SminConfig& config) {
    const std::size_t size = part.markers_model_mm.size();
    if (size < 3 || size > whole.markers_model_mm.size())
        return false;
    return mapOnto(part, whole, config.sameShapeShare * static_cast<double>(size),
                   config.tolerance_mm)
        .has_value();
}

SminWorkspace::SminWorkspace(std::size_t maxMarkers) {
    const std::size_t markers = std::min(maxMarkers, MarkerSet::kCapacity);
    pairs_.reserve(markers * (markers > 0 ? markers - 1 : 0));
    pairsByCorner_.reserve(pairs_.capacity());
    cornerStart_.reserve(markers + 1);
    markersByX_.reserve(markers);
}

void computeSmin(std::span<MarkerModel> models, const SminConfig& config) {
    SminWorkspace workspace;
    computeSmin(models, config, workspace);
}

void computeSmin(std::span<MarkerModel> models, const SminConfig& config, SminWorkspace& workspace,
                 SminPairMemory* memory) {
    // Largest ambiguous set per model, kept in sMin until the end.
    for (MarkerModel& m : models) {
        m.sMin = 0;
        m.sameShapeAs = -1;
    }
    Adjacency adjA, adjB;
    SminWorkspace::PairList& pairsB = workspace.pairs_;
    std::vector<Vec3>& byX = workspace.markersByX_;
    // Every pair a <= b, each b's pairs sorted once. The order of the pairs decides nothing but
    // which copy sameShapeAs names when a model has several: for a model, the last pair with a
    // copy in it is the same in this order as in the order of a first.
    for (std::size_t b = 0; b < models.size(); ++b) {
        bool bReady = false;
        for (std::size_t a = 0; a <= b; ++a) {
            const bool self = a == b;
            std::optional<std::size_t> known = memory ? memory->recall(a, b) : std::nullopt;
            // Two models are copies when this many markers of the smaller map onto the other.
            const double copyMarkers =
                config.sameShapeShare *
                static_cast<double>(
                    std::min(models[a].markers_model_mm.size(), models[b].markers_model_mm.size()));
            if (!known) {
                if (!bReady) {
                    buildAdjacency(models[b], adjB);
                    sortPairs(models[b], adjB, pairsB, workspace.pairsByCorner_,
                              workspace.cornerStart_);
                    byX.assign(models[b].markers_model_mm.begin(),
                               models[b].markers_model_mm.end());
                    std::sort(byX.begin(), byX.end(),
                              [](const Vec3& l, const Vec3& r) { return l.x() < r.x(); });
                    bReady = true;
                }
                buildAdjacency(models[a], adjA);
                const PairsByLength pairsNear{adjB, pairsB, workspace.pairsByCorner_,
                                              workspace.cornerStart_};
                // A copy is a copy however much more of it maps; no count exceeds a's markers.
                const std::size_t enough = self ? models[a].markers_model_mm.size()
                                                : static_cast<std::size_t>(std::ceil(copyMarkers));
                known = largestCongruence(models[a], adjA, models[b], pairsNear, byX, self, enough,
                                          config);
                if (memory)
                    memory->remember(a, b, *known);
            }
            const std::size_t l = *known;
            if (!self && static_cast<double>(l) >= copyMarkers) {
                models[a].sameShapeAs = static_cast<std::int32_t>(b);
                models[b].sameShapeAs = static_cast<std::int32_t>(a);
                continue;
            }
            const auto l32 = static_cast<std::uint32_t>(l);
            models[a].sMin = std::max(models[a].sMin, l32);
            models[b].sMin = std::max(models[b].sMin, l32);
        }
    }
    for (MarkerModel& m : models) {
        const auto size = static_cast<std::uint32_t>(m.markers_model_mm.size());
        m.sMin = std::max(config.floor, std::min(m.sMin + 1, size));
    }
}

RigidTransform canonicalFrame(std::span<const Vec3> layout_mm) {
    if (layout_mm.empty())
        return RigidTransform::identity();
    Vec3 centroid = Vec3::Zero();
    for (const Vec3& p : layout_mm)
        centroid += p;
    centroid /= static_cast<double>(layout_mm.size());
    Mat3 covariance = Mat3::Zero();
    for (const Vec3& p : layout_mm)
        covariance += (p - centroid) * (p - centroid).transpose();
    const Eigen::SelfAdjointEigenSolver<Mat3> solver(covariance);
    // Eigenvalues come in increasing order; the first axis is the one of largest spread.
    Vec3 x = solver.eigenvectors().col(2);
    Vec3 y = solver.eigenvectors().col(1);
    auto thirdMoment = [&](const Vec3& axis) {
        double sum = 0.0;
        for (const Vec3& p : layout_mm) {
            const double s = (p - centroid).dot(axis);
            sum += s * s * s;
        }
        return sum;
    };
    if (thirdMoment(x) < 0.0)
        x = -x;
    if (thirdMoment(y) < 0.0)
        y = -y;
    Mat3 axes;
    axes.col(0) = x;
    axes.col(1) = y;
    axes.col(2) = x.cross(y);
    return RigidTransform::fromMatrix(axes, centroid);
}

} // namespace edgetrack
