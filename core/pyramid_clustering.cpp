// Pyramid (4-clique) clustering through maximal cliques and clique percolation.
#include "core/pyramid_clustering.hpp"

namespace edgetrack {

namespace {
// A pyramid has four vertices; cliques smaller than that belong to no pyramid.
constexpr std::size_t kPyramid = 4;
// Two pyramids are connected when they share a triangle.
constexpr std::size_t kSharedTriangle = 3;
} // namespace

PyramidClustering::PyramidClustering(std::size_t maxCliques, std::size_t stepBudget)
    : stepBudget_(stepBudget)
    , cliques_(maxCliques)
    , sets_(maxCliques)
    , clusters_(maxCliques) {}

bool PyramidClustering::cluster(std::span<const MarkerSet> adjacency, const MarkerSet& vertices) {
    ++counters_.runs;
    adjacency_ = adjacency;
    cliques_.clear();
    clusters_.clear();
    steps_ = 0;
    abandoned_ = false;
    const std::uint64_t overflowBefore = cliques_.overflowCount();
    searchCliques(MarkerSet{}, vertices, MarkerSet{});
    if (cliques_.overflowCount() != overflowBefore) {
        ++counters_.cliqueOverflow;
        return false;
    }
    if (abandoned_) {
        ++counters_.budgetExhausted;
        return false;
    }
    if (cliques_.size() > counters_.mostCliques)
        counters_.mostCliques = cliques_.size();

    sets_.reset(cliques_.size());
    for (std::size_t i = 0; i < cliques_.size(); ++i)
        for (std::size_t j = i + 1; j < cliques_.size(); ++j)
            if ((cliques_[i] & cliques_[j]).size() >= kSharedTriangle)
                sets_.unite(i, j);
    // Roots are the smallest clique of their component, so clusters come out in clique order.
    for (std::size_t i = 0; i < cliques_.size(); ++i) {
        if (sets_.find(i) != i)
            continue;
        MarkerSet members;
        for (std::size_t j = i; j < cliques_.size(); ++j)
            if (sets_.find(j) == i)
                members |= cliques_[j];
        clusters_.push_back(members);
    }
    return true;
}

void PyramidClustering::searchCliques(const MarkerSet& clique, MarkerSet candidates,
                                      MarkerSet excluded) {
    if (abandoned_)
        return;
    if (++steps_ > stepBudget_) {
        abandoned_ = true;
        return;
    }
    if (candidates.empty()) {
        // A clique that does not fit ends the run: its result would be incomplete anyway.
        if (excluded.empty() && clique.size() >= kPyramid && !cliques_.push_back(clique))
            abandoned_ = true;
        return;
    }
    // No clique through this branch can reach a pyramid's size.
    if (clique.size() + candidates.size() < kPyramid)
        return;
    // Tomita pivot: the vertex whose neighbourhood covers most candidates leaves fewest branches.
    std::size_t pivot = 0, bestCover = 0;
    bool havePivot = false;
    (candidates | excluded).forEach([&](std::size_t u) {
        const std::size_t cover = (candidates & adjacency_[u]).size();
        if (!havePivot || cover > bestCover) {
            pivot = u;
            bestCover = cover;
            havePivot = true;
        }
    });
    MarkerSet branches = candidates.minus(adjacency_[pivot]);
    while (!branches.empty() && !abandoned_) {
        const std::size_t v = branches.popFirst();
        MarkerSet grown = clique;
        grown.insert(v);
        searchCliques(grown, candidates & adjacency_[v], excluded & adjacency_[v]);
        candidates.erase(v);
        excluded.insert(v);
    }
}

} // namespace edgetrack
