// Rigid marker models (paper sections 4-5): marker layout in the model frame, co-visibility edges,
// and S_min, the number of markers that identify the model unambiguously.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <vector>

#include "core/bounded_vector.hpp"
#include "core/geometry.hpp"
#include "core/marker_set.hpp"
#include "core/rigid_transform.hpp"

namespace edgetrack {

/// \brief Two markers of a model seen at the same time, and their distance (mm).
struct ModelEdge {
    std::uint16_t from = 0;
    std::uint16_t to = 0;
    double distance_mm = 0.0;
};

/**
 * \brief A rigid object's markers in its own frame (mm) and which of them can be seen together.
 *
 * Storage is sized once by the constructor (markers, and every pair of them as a possible edge);
 * filling it never allocates.
 */
class MarkerModel {
public:
    MarkerModel() = default;
    /// \brief An empty model that can hold \a maxMarkers markers and all edges between them.
    explicit MarkerModel(std::size_t maxMarkers);

    /// \brief Copy \a other's content; false when it does not fit this model's capacity.
    bool assign(const MarkerModel& other);
    void clear();

    std::uint32_t id = 0;
    /// Marker positions in the model frame (mm).
    BoundedVector<Vec3> markers_model_mm;
    /// Co-visible marker pairs, from < to, with the distance of the model positions.
    BoundedVector<ModelEdge> edges;
    /// Smallest number of co-visible markers that identifies this model (>= 4).
    std::uint32_t sMin = 4;
    /// Another model with (almost) the same layout, told apart only by tracking continuity; -1
    /// none.
    std::int32_t sameShapeAs = -1;

    /// \return whether an edge joins markers \a a and \a b.
    bool hasEdge(std::size_t a, std::size_t b) const;
};

/// \brief Settings of the S_min analysis.
struct SminConfig {
    /// Two distances this close are indistinguishable to the tracker (mm).
    double tolerance_mm = 2.0;
    /// A mapping between two models covering this share of the smaller one makes them copies.
    double sameShapeShare = 0.8;
    /// S_min is never below this: with three markers, one spurious point can complete a false fit.
    std::uint32_t floor = 4;

    bool operator==(const SminConfig&) const = default;
};

class SminPairMemory;

/**
 * \brief Working storage of computeSmin: every co-visible pair of one model, sorted by length,
 * and its markers sorted by x.
 * Sized once for models of up to \a maxMarkers markers; a computeSmin given one allocates nothing
 * for such models (a larger model makes it grow).
 */
class SminWorkspace {
public:
    explicit SminWorkspace(std::size_t maxMarkers = MarkerSet::kCapacity);

    /// One ordered pair of a model's markers and its length (mm).
    struct Pair {
        float length_mm;
        std::uint8_t x;
        std::uint8_t y;
    };
    using PairList = std::vector<Pair>;

private:
    friend void computeSmin(std::span<MarkerModel> models, const SminConfig& config,
                            SminWorkspace& workspace, SminPairMemory* memory);
    PairList pairs_;
    /// The same pairs by first marker, then length, and where each marker's pairs start.
    PairList pairsByCorner_;
    std::vector<std::uint32_t> cornerStart_;
    /// The other model's markers sorted by x (mm): a moved marker's neighbours lie in a window.
    std::vector<Vec3> markersByX_;
};

/**
 * \brief What computeSmin found for pairs of models before, for a caller that runs it again on
 * models most of which have not changed (calibration completion, once a round).
 *
 * The largest congruence of model \a a onto model \a b (indices into the models of the call,
 * \a a <= \a b) depends on those two models alone.
 */
class SminPairMemory {
public:
    virtual ~SminPairMemory() = default;
    /// The largest congruence of \a a onto \a b, if known.
    virtual std::optional<std::size_t> recall(std::size_t a, std::size_t b) const = 0;
    /// Told each largest congruence computeSmin had to find.
    virtual void remember(std::size_t a, std::size_t b, std::size_t largest) = 0;
};

/**
 * \brief Set every model's S_min (and sameShapeAs) from its congruences with itself and the others.
 *
 * For every pair of co-visible triangles, of one model and of itself or another model, whose sides
 * agree within the tolerance (other than a triangle with itself), the rigid transform between them
 * is applied to the whole model and the markers that land on a marker of the other are counted: L
 * markers that fit two ways cannot identify the model, L + 1 can. S_min is the largest such L plus
 * one, at least \a config.floor and at most the model's size. Models that map onto each other
 * almost entirely are copies of one layout (two identical cubes): they are marked as the same
 * shape and left out of each other's S_min, since no number of markers tells them apart.
 *
 * Runs at the end of a calibration, and once a round in its completion; its cost grows with the
 * triangles of each model times the congruent pairs of the other, which are found by a binary
 * search in \a workspace. A pair \a memory recalls is not searched again; each one searched is
 * told to it.
 */
void computeSmin(std::span<MarkerModel> models, const SminConfig& config, SminWorkspace& workspace,
                 SminPairMemory* memory = nullptr);

/// \brief computeSmin with a workspace of its own (allocated for the call).
void computeSmin(std::span<MarkerModel> models, const SminConfig& config);

/**
 * \brief Whether \a a and \a b are copies of one layout: a rigid transform puts at least
 * config.sameShapeShare of the smaller one's markers onto markers of the other (within
 * config.tolerance_mm). Tried from a's widest co-visible triangles, so it is cheap enough for
 * start-up; computeSmin finds the same relation as part of its fuller analysis.
 */
bool sameShape(const MarkerModel& a, const MarkerModel& b, const SminConfig& config);

/**
 * \brief sameShape's transform: T_b_from_a, which puts that share of the smaller layout's markers
 * onto the other's; nothing when the two are not copies of one layout. For a layout with
 * symmetries (a cube) it is one of the equally good ones.
 */
std::optional<RigidTransform> sameShapeTransform(const MarkerModel& a, const MarkerModel& b,
                                                 const SminConfig& config);

/**
 * \brief Whether \a part is a piece of \a whole's layout: a rigid transform puts at least
 * config.sameShapeShare of part's markers onto markers of whole (within config.tolerance_mm).
 */
bool isPartOf(const MarkerModel& part, const MarkerModel& whole, const SminConfig& config);

/**
 * \brief The canonical frame of a marker layout: origin at the centroid, axes along the principal
 * axes by decreasing spread, signs fixed by the third moments (so a layout gets the same frame
 * whatever frame it was measured in, unless its spread is isotropic).
 * \return T_layout_from_canonical: maps canonical coordinates to the layout's coordinates.
 */
RigidTransform canonicalFrame(std::span<const Vec3> layout_mm);

} // namespace edgetrack
