// Tests of the fixed-capacity vectors: overflow is refused and counted, storage never moves.
#include <numeric>

#include <gtest/gtest.h>

#include "core/bounded_vector.hpp"
#include "tests/support/alloc_guard.hpp"

using edgetrack::BoundedVector;
using edgetrack::BoundedVectorView;
using edgetrack::FixedVector;

namespace {
// A function that takes the size-erased view works with any capacity and either storage.
int sumAll(const BoundedVectorView<int>& values) {
    return std::accumulate(values.begin(), values.end(), 0);
}
} // namespace

TEST(FixedVector, RefusesAndCountsOverflow) {
    FixedVector<int, 3> v;
    EXPECT_TRUE(v.push_back(1));
    EXPECT_TRUE(v.push_back(2));
    EXPECT_TRUE(v.push_back(3));
    EXPECT_TRUE(v.full());
    EXPECT_FALSE(v.push_back(4));
    EXPECT_FALSE(v.push_back(5));
    EXPECT_EQ(v.size(), 3u);
    EXPECT_EQ(v.overflowCount(), 2u);
    EXPECT_EQ(v[2], 3);
    v.resetOverflowCount();
    EXPECT_EQ(v.overflowCount(), 0u);
}

TEST(FixedVector, AppendReturnsNullWhenFull) {
    FixedVector<int, 1> v;
    int* slot = v.append();
    ASSERT_NE(slot, nullptr);
    *slot = 9;
    EXPECT_EQ(v.append(), nullptr);
    EXPECT_EQ(v.overflowCount(), 1u);
    EXPECT_EQ(v[0], 9);
}

TEST(FixedVector, ResizePastCapacityClampsAndCounts) {
    FixedVector<int, 4> v;
    EXPECT_TRUE(v.resize(2));
    EXPECT_EQ(v.size(), 2u);
    EXPECT_FALSE(v.resize(10));
    EXPECT_EQ(v.size(), 4u);
    EXPECT_EQ(v.overflowCount(), 1u);
}

TEST(FixedVector, CopyHasItsOwnStorage) {
    FixedVector<int, 4> a;
    a.push_back(1);
    a.push_back(2);
    FixedVector<int, 4> b = a;
    b[0] = 10;
    b.push_back(3);
    EXPECT_EQ(a[0], 1);
    EXPECT_EQ(a.size(), 2u);
    EXPECT_EQ(b.size(), 3u);
    EXPECT_NE(a.data(), b.data());
}

TEST(FixedVector, SwapRemoveMovesLastIntoPlace) {
    FixedVector<int, 4> v;
    for (int i : {1, 2, 3, 4})
        v.push_back(i);
    v.swapRemove(1);
    ASSERT_EQ(v.size(), 3u);
    EXPECT_EQ(v[0], 1);
    EXPECT_EQ(v[1], 4);
    EXPECT_EQ(v[2], 3);
}

TEST(BoundedVector, CapacityFromRunTime) {
    const std::size_t configured = 5;
    BoundedVector<int> v(configured);
    EXPECT_EQ(v.capacity(), 5u);
    for (int i = 0; i < 7; ++i)
        v.push_back(i);
    EXPECT_EQ(v.size(), 5u);
    EXPECT_EQ(v.overflowCount(), 2u);
    EXPECT_EQ(sumAll(v), 0 + 1 + 2 + 3 + 4);
}

TEST(BoundedVector, MoveKeepsElementsAndEmptiesSource) {
    BoundedVector<int> a(3);
    a.push_back(7);
    a.push_back(8);
    const int* storage = a.data();
    BoundedVector<int> b(std::move(a));
    EXPECT_EQ(b.size(), 2u);
    EXPECT_EQ(b.data(), storage);
    EXPECT_EQ(b[1], 8);
    EXPECT_EQ(a.capacity(), 0u); // NOLINT(bugprone-use-after-move): the contract under test
    EXPECT_FALSE(a.push_back(1));

    BoundedVector<int> c(1);
    c = std::move(b);
    EXPECT_EQ(c.capacity(), 3u);
    EXPECT_EQ(c[0], 7);
}

TEST(BoundedVector, SameInterfaceAsFixedVector) {
    FixedVector<int, 8> inlineStorage;
    BoundedVector<int> heapOnce(8);
    for (int i = 1; i <= 3; ++i) {
        inlineStorage.push_back(i);
        heapOnce.push_back(i);
    }
    EXPECT_EQ(sumAll(inlineStorage), sumAll(heapOnce));
}

TEST(BoundedVector, NoHeapAfterConstruction) {
    BoundedVector<double> v(1000);
    const auto count = edgetrack::test::countAllocations([&] {
        for (int round = 0; round < 10; ++round) {
            v.clear();
            for (int i = 0; i < 1200; ++i)
                v.push_back(i * 0.5);
        }
    });
    EXPECT_EQ(count, 0u);
    EXPECT_EQ(v.overflowCount(), 2000u);
}
