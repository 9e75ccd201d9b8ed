// Tests of pyramid (4-clique) clustering against the paper's Figure 4 and a brute-force reference.
#include <algorithm>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "core/pyramid_clustering.hpp"

namespace edgetrack {
namespace {

struct Graph {
    explicit Graph(std::size_t n)
        : adjacency(n) {}
    void connect(std::size_t a, std::size_t b) {
        adjacency[a].insert(b);
        adjacency[b].insert(a);
    }
    void clique(std::initializer_list<std::size_t> vertices) {
        for (std::size_t a : vertices)
            for (std::size_t b : vertices)
                if (a < b)
                    connect(a, b);
    }
    std::vector<MarkerSet> adjacency;
};

// The paper's definition taken literally: every pyramid, triangles joined when they share one.
std::vector<MarkerSet> referenceClusters(const Graph& g) {
    const std::size_t n = g.adjacency.size();
    auto id = [n](std::size_t a, std::size_t b, std::size_t c) { return (a * n + b) * n + c; };
    std::vector<std::size_t> parent(n * n * n);
    for (std::size_t i = 0; i < parent.size(); ++i)
        parent[i] = i;
    std::vector<bool> inPyramid(parent.size(), false);
    auto root = [&](std::size_t x) {
        while (parent[x] != x)
            x = parent[x] = parent[parent[x]];
        return x;
    };
    auto linked = [&](std::size_t a, std::size_t b) { return g.adjacency[a].contains(b); };
    for (std::size_t a = 0; a < n; ++a)
        for (std::size_t b = a + 1; b < n; ++b)
            for (std::size_t c = b + 1; c < n; ++c)
                for (std::size_t d = c + 1; d < n; ++d) {
                    if (!(linked(a, b) && linked(a, c) && linked(a, d) && linked(b, c) &&
                          linked(b, d) && linked(c, d)))
                        continue;
                    const std::size_t t[4] = {id(a, b, c), id(a, b, d), id(a, c, d), id(b, c, d)};
                    for (std::size_t k = 0; k < 4; ++k) {
                        inPyramid[t[k]] = true;
                        parent[root(t[k])] = root(t[0]);
                    }
                }
    std::vector<std::pair<std::size_t, MarkerSet>> byRoot;
    for (std::size_t a = 0; a < n; ++a)
        for (std::size_t b = a + 1; b < n; ++b)
            for (std::size_t c = b + 1; c < n; ++c) {
                if (!inPyramid[id(a, b, c)])
                    continue;
                const std::size_t r = root(id(a, b, c));
                auto it = std::find_if(byRoot.begin(), byRoot.end(),
                                       [r](const auto& e) { return e.first == r; });
                if (it == byRoot.end()) {
                    byRoot.push_back({r, MarkerSet{}});
                    it = byRoot.end() - 1;
                }
                it->second.insert(a);
                it->second.insert(b);
                it->second.insert(c);
            }
    std::vector<MarkerSet> out;
    for (const auto& e : byRoot)
        out.push_back(e.second);
    return out;
}

bool sameClusters(std::vector<MarkerSet> a, std::span<const MarkerSet> b) {
    if (a.size() != b.size())
        return false;
    return std::all_of(b.begin(), b.end(), [&](const MarkerSet& s) {
        return std::find(a.begin(), a.end(), s) != a.end();
    });
}

TEST(PyramidClustering, CompleteGraphIsOneCluster) {
    Graph g(30);
    std::vector<std::size_t> all(30);
    for (std::size_t i = 0; i < 30; ++i)
        for (std::size_t j = i + 1; j < 30; ++j)
            g.connect(i, j);
    PyramidClustering clustering(64, 10000);
    ASSERT_TRUE(clustering.cluster(g.adjacency, MarkerSet::firstN(30)));
    ASSERT_EQ(clustering.clusters().size(), 1u);
    EXPECT_EQ(clustering.clusters()[0], MarkerSet::firstN(30));
}

TEST(PyramidClustering, PaperFigure4HingedPartsAreTwoObjects) {
    // Two rigid parts sharing the edge A-B (vertices 0 and 1): every triangle shares an edge
    // with another, so triangle clustering would make one object; pyramids make two.
    Graph g(8);
    g.clique({0, 1, 2, 3, 4});
    g.clique({0, 1, 5, 6, 7});
    PyramidClustering clustering(64, 10000);
    ASSERT_TRUE(clustering.cluster(g.adjacency, MarkerSet::firstN(8)));
    ASSERT_EQ(clustering.clusters().size(), 2u);
    MarkerSet first, second;
    for (std::size_t v : {0u, 1u, 2u, 3u, 4u})
        first.insert(v);
    for (std::size_t v : {0u, 1u, 5u, 6u, 7u})
        second.insert(v);
    EXPECT_TRUE(sameClusters({first, second}, clustering.clusters()));
}

TEST(PyramidClustering, TrianglesWithoutPyramidsFormNoCluster) {
    // A strip of triangles: rigid in Mills' sense, but no 4-clique anywhere.
    Graph g(6);
    for (std::size_t i = 0; i + 2 < 6; ++i) {
        g.connect(i, i + 1);
        g.connect(i, i + 2);
    }
    g.connect(4, 5);
    PyramidClustering clustering(64, 10000);
    ASSERT_TRUE(clustering.cluster(g.adjacency, MarkerSet::firstN(6)));
    EXPECT_TRUE(clustering.clusters().empty());
}

TEST(PyramidClustering, AgreesWithPyramidDefinitionOnRandomGraphs) {
    std::mt19937 random(7);
    PyramidClustering clustering(4096, 1000000);
    for (int trial = 0; trial < 300; ++trial) {
        const std::size_t n = 5 + static_cast<std::size_t>(trial % 10);
        const double density = 0.35 + 0.5 * static_cast<double>(trial % 7) / 6.0;
        std::bernoulli_distribution edge(density);
        Graph g(n);
        for (std::size_t i = 0; i < n; ++i)
            for (std::size_t j = i + 1; j < n; ++j)
                if (edge(random))
                    g.connect(i, j);
        ASSERT_TRUE(clustering.cluster(g.adjacency, MarkerSet::firstN(n)));
        EXPECT_TRUE(sameClusters(referenceClusters(g), clustering.clusters()))
            << "trial " << trial << ", " << n << " vertices";
    }
}

TEST(PyramidClustering, OnlyListedVerticesTakePart) {
    Graph g(6);
    g.clique({0, 1, 2, 3, 4, 5});
    MarkerSet some = MarkerSet::firstN(6);
    some.erase(5);
    PyramidClustering clustering(64, 10000);
    ASSERT_TRUE(clustering.cluster(g.adjacency, some));
    ASSERT_EQ(clustering.clusters().size(), 1u);
    EXPECT_EQ(clustering.clusters()[0], some);
}

TEST(PyramidClustering, TooManyCliquesIsReportedNotUndefined) {
    // A complete 4-partite graph with three vertices per part has 3^4 = 81 maximal cliques.
    Graph g(12);
    for (std::size_t i = 0; i < 12; ++i)
        for (std::size_t j = i + 1; j < 12; ++j)
            if (i % 4 != j % 4)
                g.connect(i, j);
    PyramidClustering small(16, 1000000);
    EXPECT_FALSE(small.cluster(g.adjacency, MarkerSet::firstN(12)));
    EXPECT_EQ(small.counters().cliqueOverflow, 1u);
    EXPECT_TRUE(small.clusters().empty());

    PyramidClustering hurried(1000, 5);
    EXPECT_FALSE(hurried.cluster(g.adjacency, MarkerSet::firstN(12)));
    EXPECT_EQ(hurried.counters().budgetExhausted, 1u);

    PyramidClustering enough(1000, 1000000);
    ASSERT_TRUE(enough.cluster(g.adjacency, MarkerSet::firstN(12)));
    EXPECT_EQ(enough.counters().mostCliques, 81u);
    ASSERT_EQ(enough.clusters().size(), 1u);
}

} // namespace
} // namespace edgetrack
