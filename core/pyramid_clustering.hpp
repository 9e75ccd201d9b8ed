// Pyramid (4-clique) clustering of a calibration graph into rigid clusters (paper section 4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/bounded_vector.hpp"
#include "core/disjoint_sets.hpp"
#include "core/marker_set.hpp"

namespace edgetrack {

/// \brief Work and overflow of the clustering, for the status view.
struct ClusteringCounters {
    std::uint64_t runs = 0;
    /// Runs abandoned because the graph had more maximal cliques than the configured capacity.
    std::uint64_t cliqueOverflow = 0;
    /// Runs abandoned because the clique search took more steps than its budget.
    std::uint64_t budgetExhausted = 0;
    /// Most maximal cliques (of four or more vertices) in one run.
    std::uint64_t mostCliques = 0;
};

/**
 * \brief Splits a graph into the connected components of its pyramids (4-cliques), two pyramids
 * being connected when they share a triangle.
 *
 * The paper builds these components from triangles and pyramids directly, which costs O(N^4) on a
 * fully connected graph, the usual state of a calibration graph. The same components are the
 * 4-clique communities of clique percolation (Palla et al., Nature 2005): they are exactly the
 * unions of maximal cliques (of at least four vertices) that are chained by sharing at least three
 * vertices. A rigid object's graph has few maximal cliques (one when it is complete), so this
 * finds them with Bron-Kerbosch (Tomita pivoting) on 128-bit rows and joins them with union-find.
 *
 * A vertex may belong to several clusters (two rigid parts hinged on an edge share its two ends);
 * a vertex in no pyramid belongs to none. The clique search is bounded by a clique capacity and a
 * step budget; a run that exceeds either returns false and is counted, and the caller keeps its
 * previous clustering (a graph that hard is in the middle of losing edges and is tried again).
 */
class PyramidClustering {
public:
    /**
     * \param maxCliques maximal cliques one run may hold.
     * \param stepBudget clique-search steps (recursive calls) one run may take.
     */
    PyramidClustering(std::size_t maxCliques, std::size_t stepBudget);

    /**
     * \brief Cluster the graph on \a vertices whose neighbourhoods are \a adjacency.
     * \param adjacency adjacency[i]: the neighbours of vertex i (symmetric, no self loops);
     * vertices must be below adjacency.size() and MarkerSet::kCapacity. \return false when the
     * clique capacity or the step budget ran out (clusters() is then empty).
     */
    bool cluster(std::span<const MarkerSet> adjacency, const MarkerSet& vertices);

    /// \brief The clusters of the last successful run, in the order of their first clique.
    std::span<const MarkerSet> clusters() const { return clusters_.span(); }
    const ClusteringCounters& counters() const { return counters_; }

private:
    void searchCliques(const MarkerSet& clique, MarkerSet candidates, MarkerSet excluded);

    std::size_t stepBudget_;
    std::size_t steps_ = 0;
    bool abandoned_ = false;
    std::span<const MarkerSet> adjacency_;
    BoundedVector<MarkerSet> cliques_;
    DisjointSets sets_;
    BoundedVector<MarkerSet> clusters_;
    ClusteringCounters counters_{};
};

} // namespace edgetrack
