// Tests of the simulated camera pair: timing, buffer re-use, drops, LED strobe, faults.
#include <chrono>
#include <set>
#include <thread>

#include <gtest/gtest.h>

#include "core/pixel_stats.hpp"
#include "hal/sim/sim_board.hpp"
#include "tests/support/alloc_guard.hpp"

using namespace edgetrack;
using namespace edgetrack::sim;

TEST(SimCameraPair, DeliversPairedFramesAtTheFrameRate) {
    SimBoard board(*makeScene("slow_cube", 1), 1);
    board.ledRing.setContinuous(true);
    ASSERT_TRUE(board.cameras.start());
    hal::StereoFrame frame;
    Nanoseconds previousMid = 0;
    for (int i = 0; i < 5; ++i) {
        ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond),
                  hal::AcquireStatus::Frame);
        // Numbered by exposure as `edgetrack sim` numbers frames: frame k is the scene at
        // k / rate, and the first exposure after start at time 0 is frame 1.
        EXPECT_EQ(frame.number, static_cast<std::uint64_t>(i + 1));
        EXPECT_EQ(frame.midExposure(), static_cast<Nanoseconds>(frame.number) * 10'000'000 +
                                           SimCameraPair::kSyncSkew / 2);
        EXPECT_EQ(frame.camera[0].width_px, 1280);
        EXPECT_EQ(frame.camera[1].exposureStart - frame.camera[0].exposureStart,
                  SimCameraPair::kSyncSkew);
        EXPECT_EQ(frame.camera[0].exposureEnd - frame.camera[0].exposureStart, 1'000'000);
        EXPECT_GE(board.clock.now(), frame.camera[1].exposureEnd);
        if (i > 0) {
            EXPECT_EQ(frame.camera[0].midExposure() - previousMid, 10'000'000);
        }
        previousMid = frame.camera[0].midExposure();
        board.cameras.release(frame);
    }
}

TEST(SimCameraPair, InRealTimeAHostThatFellBehindGetsOldFramesAndTheRestAreDropped) {
    // Under host overload the board fell behind wall time and dropped nothing, and a frame that
    // arrived 100 ms late said 3 ms. A real sensor fills the buffers it has and drops the rest.
    SimBoardOptions options;
    options.realTime = true;
    options.cameraBufferPairs = 4;
    SimBoard board(*makeScene("slow_cube", 1), 1, options);
    board.ledRing.setContinuous(true);
    ASSERT_TRUE(board.cameras.start());
    hal::StereoFrame frame;
    ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    board.cameras.release(frame);
    const std::uint64_t first = frame.number;
    std::this_thread::sleep_for(std::chrono::milliseconds(200)); // about 20 exposures
    ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    EXPECT_EQ(frame.number, first + 1) << "the oldest frame a buffer held";
    EXPECT_GE(board.clock.now() - frame.midExposure(), 150 * hal::kNanosecondsPerMillisecond)
        << "its age is real";
    board.cameras.release(frame);
    std::uint64_t last = frame.number;
    for (int i = 0; i < 3; ++i) {
        ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond),
                  hal::AcquireStatus::Frame);
        board.cameras.release(frame);
        last = frame.number;
    }
    EXPECT_EQ(last, first + 4) << "four buffers' worth delivered";
    ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    EXPECT_GE(frame.number, first + 18) << "then the frames read out with no buffer are gone";
    EXPECT_GE(board.cameras.counters().droppedNoBuffer, 14u);
}

TEST(SimCameraPair, ReusesItsBuffersAndDropsWhenAllAreHeld) {
    SimBoardOptions options;
    options.cameraBufferPairs = 2;
    SimBoard board(*makeScene("slow_cube", 1), 1, options);
    ASSERT_TRUE(board.cameras.start());
    std::set<const std::uint8_t*> buffers;
    hal::StereoFrame a, b, c;
    for (int i = 0; i < 10; ++i) {
        ASSERT_EQ(board.cameras.acquire(a, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
        buffers.insert(a.camera[0].pixels);
        board.cameras.release(a);
    }
    EXPECT_LE(buffers.size(), 2u);

    ASSERT_EQ(board.cameras.acquire(a, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    ASSERT_EQ(board.cameras.acquire(b, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    EXPECT_NE(a.camera[0].pixels, b.camera[0].pixels);
    // Both buffers held: exposures complete with nowhere to go and are dropped.
    EXPECT_EQ(board.cameras.acquire(c, 25'000'000), hal::AcquireStatus::Timeout);
    EXPECT_GE(board.cameras.counters().droppedNoBuffer, 2u);
    board.cameras.release(a);
    EXPECT_EQ(board.cameras.acquire(c, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    EXPECT_EQ(c.camera[0].pixels, a.camera[0].pixels);
}

TEST(SimCameraPair, StrobedLedLightsOnlyTheStrobedExposure) {
    SimBoard board(*makeScene("two_cubes", 1), 1);
    ASSERT_TRUE(board.cameras.start());
    hal::StereoFrame frame;
    // Not strobed: dark.
    ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    const std::size_t size = 1280u * 800u;
    EXPECT_EQ(measurePixels({frame.camera[0].pixels, size}, 100).brightCount, 0u);
    board.cameras.release(frame);
    // Strobed for the next exposure (both cameras' windows): markers show.
    const Nanoseconds start = board.cameras.nextExposureStart();
    board.ledRing.schedulePulse(start - 50'000, start + board.cameras.exposureDuration() +
                                                    SimCameraPair::kSyncSkew + 50'000);
    ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
    EXPECT_GT(measurePixels({frame.camera[0].pixels, size}, 100).brightCount, 200u);
    EXPECT_GT(measurePixels({frame.camera[1].pixels, size}, 100).brightCount, 200u);
}

TEST(SimCameraPair, FaultsAndUnpairedFrames) {
    SimBoard board(*makeScene("slow_cube", 1), 1);
    hal::StereoFrame frame;
    EXPECT_EQ(board.cameras.acquire(frame, 1000), hal::AcquireStatus::Stopped);
    ASSERT_TRUE(board.cameras.start());
    board.cameras.dropPartnerEvery(2);
    for (int i = 0; i < 4; ++i) {
        ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond),
                  hal::AcquireStatus::Frame);
        board.cameras.release(frame);
    }
    EXPECT_EQ(board.cameras.counters().droppedUnpaired, 4u);
    board.cameras.dropPartnerEvery(0);

    board.cameras.setStalled(true);
    const Nanoseconds before = board.clock.now();
    EXPECT_EQ(board.cameras.acquire(frame, 50'000'000), hal::AcquireStatus::Timeout);
    EXPECT_EQ(board.clock.now(), before + 50'000'000);
    board.cameras.setStalled(false);

    board.cameras.injectFailure();
    EXPECT_EQ(board.cameras.acquire(frame, 1000), hal::AcquireStatus::Failed);
    ASSERT_TRUE(board.cameras.start()); // the firmware's retry
    EXPECT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond), hal::AcquireStatus::Frame);
}

TEST(SimCameraPair, SteadyStateCaptureDoesNotAllocate) {
    SimBoard board(*makeScene("stress", 1), 1);
    board.ledRing.setContinuous(true);
    ASSERT_TRUE(board.cameras.start());
    hal::StereoFrame frame;
    for (int i = 0; i < 5; ++i) { // warm-up: vectors of the observation reach their size
        ASSERT_EQ(board.cameras.acquire(frame, hal::kNanosecondsPerSecond),
                  hal::AcquireStatus::Frame);
        board.cameras.release(frame);
    }
    const auto allocations = test::countAllocations([&] {
        for (int i = 0; i < 100; ++i) {
            if (board.cameras.acquire(frame, hal::kNanosecondsPerSecond) ==
                hal::AcquireStatus::Frame)
                board.cameras.release(frame);
        }
    });
    EXPECT_EQ(allocations, 0u);
}
