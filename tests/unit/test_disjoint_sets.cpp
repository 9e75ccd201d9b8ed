// Tests of the fixed-capacity disjoint sets: smallest element as root, capacity refused, reset.
#include <gtest/gtest.h>

#include "core/disjoint_sets.hpp"

namespace edgetrack {
namespace {

TEST(DisjointSets, TheSmallestElementIsTheRootWhateverTheOrderOfUnions) {
    DisjointSets sets(8);
    sets.reset(8);
    EXPECT_EQ(sets.unite(6, 4), 4U);
    EXPECT_EQ(sets.unite(7, 6), 4U);
    EXPECT_EQ(sets.unite(5, 1), 1U);
    EXPECT_EQ(sets.unite(7, 5), 1U);
    for (const std::size_t e : {1U, 4U, 5U, 6U, 7U})
        EXPECT_EQ(sets.find(e), 1U);
    for (const std::size_t e : {0U, 2U, 3U}) {
        EXPECT_EQ(sets.find(e), e);
        EXPECT_TRUE(sets.isRoot(e));
    }
    EXPECT_FALSE(sets.isRoot(4));
    EXPECT_EQ(sets.unite(4, 7), 1U) << "already one set";
}

TEST(DisjointSets, RefusesElementsBeyondItsCapacityAndStartsOverOnReset) {
    DisjointSets sets(3);
    for (int i = 0; i < 3; ++i)
        EXPECT_TRUE(sets.add());
    EXPECT_FALSE(sets.add());
    EXPECT_EQ(sets.size(), 3U);
    sets.unite(0, 2);
    sets.reset(10);
    EXPECT_EQ(sets.size(), 3U) << "reset holds at most the capacity";
    EXPECT_EQ(sets.find(2), 2U);
    sets.reset(0);
    EXPECT_EQ(sets.size(), 0U);
    EXPECT_TRUE(sets.add());
    EXPECT_EQ(sets.find(0), 0U);
}

} // namespace
} // namespace edgetrack
