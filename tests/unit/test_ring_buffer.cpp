// Tests of the fixed-capacity FIFO: order, drop-oldest, refusal, counters.
#include <gtest/gtest.h>

#include "core/ring_buffer.hpp"
#include "tests/support/alloc_guard.hpp"

using edgetrack::RingBuffer;

TEST(RingBuffer, FirstInFirstOut) {
    RingBuffer<int> q(3);
    EXPECT_TRUE(q.tryPush(1));
    EXPECT_TRUE(q.tryPush(2));
    int v = 0;
    ASSERT_TRUE(q.pop(v));
    EXPECT_EQ(v, 1);
    EXPECT_TRUE(q.tryPush(3));
    EXPECT_TRUE(q.tryPush(4)); // wraps around
    EXPECT_EQ(q.size(), 3u);
    EXPECT_EQ(q.at(2), 4);
    for (int expected : {2, 3, 4}) {
        ASSERT_TRUE(q.pop(v));
        EXPECT_EQ(v, expected);
    }
    EXPECT_FALSE(q.pop(v));
}

TEST(RingBuffer, FullQueueRefusesOrDropsOldest) {
    RingBuffer<int> q(2);
    q.tryPush(1);
    q.tryPush(2);
    EXPECT_FALSE(q.tryPush(3));
    EXPECT_EQ(q.refusedCount(), 1u);
    EXPECT_TRUE(q.pushDropOldest(4));
    EXPECT_EQ(q.droppedCount(), 1u);
    EXPECT_EQ(q.front(), 2);
    EXPECT_EQ(q.at(1), 4);

    RingBuffer<int> none(0);
    EXPECT_FALSE(none.tryPush(1));
    EXPECT_TRUE(none.pushDropOldest(1));
    EXPECT_EQ(none.droppedCount(), 1u);
}

TEST(RingBuffer, NoHeapAfterConstruction) {
    RingBuffer<double> q(64);
    const auto count = edgetrack::test::countAllocations([&] {
        double v = 0.0;
        for (int i = 0; i < 10000; ++i) {
            q.pushDropOldest(i);
            if (i % 3 == 0)
                q.pop(v);
        }
    });
    EXPECT_EQ(count, 0u);
}
