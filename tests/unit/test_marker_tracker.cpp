// Tests of frame-to-frame correspondence: IDs persist under motion, new markers get new IDs.
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "core/marker_tracker.hpp"
#include "tests/support/alloc_guard.hpp"

using namespace edgetrack;

namespace {
std::vector<Vec3> grid(int count, double spacing_mm) {
    std::vector<Vec3> points;
    for (int i = 0; i < count; ++i)
        points.emplace_back((i % 5) * spacing_mm, (i / 5) * spacing_mm, 600.0);
    return points;
}
} // namespace

TEST(MarkerTracker, IdsPersistUnderFastMotionAndShuffledOrder) {
    MarkerTracker tracker{FrameToFrameConfig{}};
    const std::vector<Vec3> base = grid(20, 15.0);
    std::mt19937 random(1);
    std::vector<std::uint32_t> idOfBase(base.size(), 0);
    for (int frame = 0; frame < 300; ++frame) {
        const double t = frame * 0.01;
        // From rest to 1 m/s sideways in 0.3 s, with a wobble: then 10 mm per frame, close to the
        // 15 mm marker spacing, which only the velocity prediction resolves.
        const double ramp_s = 0.3;
        const double x = t < ramp_s ? 1000.0 * t * t / (2.0 * ramp_s) : 1000.0 * (t - 0.5 * ramp_s);
        const Vec3 shift(x, 30.0 * std::sin(3.0 * t), 0.0);
        std::vector<int> order(base.size());
        std::iota(order.begin(), order.end(), 0);
        std::shuffle(order.begin(), order.end(), random);
        std::vector<Vec3> points;
        for (int i : order)
            points.push_back(base[static_cast<std::size_t>(i)] + shift);
        const auto tracked = tracker.update(t, points);
        ASSERT_EQ(tracked.size(), base.size());
        for (std::size_t k = 0; k < order.size(); ++k) {
            const auto truth = static_cast<std::size_t>(order[k]);
            EXPECT_EQ(tracked[k].position_rig_mm, points[k]);
            if (frame == 0) {
                idOfBase[truth] = tracked[k].id;
                EXPECT_EQ(tracked[k].age, 0u);
            } else {
                EXPECT_EQ(tracked[k].id, idOfBase[truth]) << "frame " << frame;
                EXPECT_EQ(tracked[k].age, static_cast<std::uint32_t>(frame));
            }
        }
    }
    EXPECT_EQ(tracker.counters().born, 20u);
}

TEST(MarkerTracker, NewAndReturningMarkersGetNewIds) {
    MarkerTracker tracker{FrameToFrameConfig{}};
    const auto first = tracker.update(0.0, std::vector<Vec3>{{0, 0, 500}, {50, 0, 500}});
    const std::uint32_t a = first[0].id, b = first[1].id;
    EXPECT_NE(a, b);
    // b is hidden for a frame, a stays; then b comes back: it is a new marker to this stage.
    const auto second = tracker.update(0.01, std::vector<Vec3>{{0, 0, 500}});
    EXPECT_EQ(second[0].id, a);
    const auto third = tracker.update(0.02, std::vector<Vec3>{{50, 0, 500}, {0, 0, 500}});
    EXPECT_EQ(third[1].id, a);
    EXPECT_NE(third[0].id, b);
    EXPECT_EQ(third[0].age, 0u);
    EXPECT_EQ(third[1].age, 2u);
}

TEST(MarkerTracker, LongGapStartsAfresh) {
    MarkerTracker tracker{FrameToFrameConfig{}};
    const std::uint32_t id = tracker.update(0.0, std::vector<Vec3>{{0, 0, 500}})[0].id;
    EXPECT_NE(tracker.update(1.0, std::vector<Vec3>{{0, 0, 500}})[0].id, id);
}

TEST(MarkerTracker, CrossingMarkersKeepTheirIdsThanksToPrediction) {
    MarkerTracker tracker{FrameToFrameConfig{}};
    std::uint32_t left = 0, right = 0;
    for (int frame = 0; frame < 40; ++frame) {
        const double t = frame * 0.01;
        // Two markers 2 mm apart in depth pass each other at 0.8 m/s each.
        const Vec3 a(-160.0 + 800.0 * t, 0.0, 600.0), b(160.0 - 800.0 * t, 0.0, 602.0);
        const auto tracked = tracker.update(t, std::vector<Vec3>{a, b});
        if (frame == 0) {
            left = tracked[0].id;
            right = tracked[1].id;
        }
        EXPECT_EQ(tracked[0].id, left) << frame;
        EXPECT_EQ(tracked[1].id, right) << frame;
    }
}

TEST(MarkerTracker, OverflowIsCountedAndTrackingDoesNotAllocate) {
    FrameToFrameConfig config;
    config.maxMarkers = 16;
    MarkerTracker tracker(config);
    const std::vector<Vec3> points = grid(20, 20.0);
    tracker.update(0.0, points);
    EXPECT_EQ(tracker.counters().markerOverflow, 4u);
    const auto count = test::countAllocations([&] {
        for (int i = 1; i < 1000; ++i)
            tracker.update(i * 0.01, points);
    });
    EXPECT_EQ(count, 0u);
    EXPECT_EQ(tracker.current().size(), 16u);
}
