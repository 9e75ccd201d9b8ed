// Simulated camera pair: renders the world into buffers allocated once, lit by the sim LED ring.
#include "hal/sim/sim_camera_pair.hpp"

#include <cmath>

namespace edgetrack::sim {

SimCameraPair::SimCameraPair(const World& world, SimClock& clock, SimLedRing& led, int bufferPairs)
    : world_(world)
    , clock_(clock)
    , led_(led)
    , renderer_(world.scene().rig.width_px, world.scene().rig.height_px,
                world.scene().background_dn, world.scene().noiseSigma_dn, world.seed())
    , period_(static_cast<Nanoseconds>(std::llround(1e9 / world.scene().frameRate_hz)))
    , exposure_(static_cast<Nanoseconds>(std::llround(world.scene().exposure_s * 1e9)))
    , width_(world.scene().rig.width_px)
    , height_(world.scene().rig.height_px) {
    const std::size_t pairs = static_cast<std::size_t>(bufferPairs > 0 ? bufferPairs : 1);
    buffers_.resize(2 * pairs);
    held_.assign(pairs, false);
}

Status SimCameraPair::start() {
    // Buffers are allocated here, once, as libcamera's FrameBufferAllocator does.
    for (auto& buffer : buffers_)
        buffer.resize(static_cast<std::size_t>(width_) * static_cast<std::size_t>(height_));
    std::fill(held_.begin(), held_.end(), false);
    failed_ = false;
    started_ = true;
    // Stream from the next frame boundary after now.
    nextIndex_ = static_cast<std::uint64_t>(std::max<Nanoseconds>(0, clock_.now()) / period_ + 1);
    return Ok{};
}

void SimCameraPair::stop() {
    started_ = false;
}

Nanoseconds SimCameraPair::exposureStart(std::uint64_t index) const {
    // Frame index k has its mid-exposure at k * period, so truth time_s = k / rate.
    return static_cast<Nanoseconds>(index) * period_ - exposure_ / 2;
}

void SimCameraPair::addSpuriousBurst(std::uint64_t index) {
    // A generator seeded by the frame, so the burst of a frame is the same whenever it is drawn.
    std::uint64_t state = (index + 1) * 0x9E3779B97F4A7C15ULL ^ world_.seed();
    auto uniform = [&state]() {
        state = state * 6364136223846793005ULL + 1442695040888963407ULL;
        return static_cast<double>(state >> 11) * (1.0 / 9007199254740992.0);
    };
    for (std::vector<Glint>& glints : observation_.glints)
        for (int i = 0; i < spuriousBurst_; ++i) {
            Glint g;
            g.centre_px = Vec2(8.0 + uniform() * (width_ - 16), 8.0 + uniform() * (height_ - 16));
            g.radiusMajor_px = g.radiusMinor_px = 1.5 + uniform();
            g.peak_dn = 300.0;
            glints.push_back(g);
        }
}

Nanoseconds SimCameraPair::nextExposureStart() const {
    return exposureStart(nextIndex_);
}

hal::AcquireStatus SimCameraPair::acquire(hal::StereoFrame& frame, Nanoseconds timeout) {
    if (!started_)
        return hal::AcquireStatus::Stopped;
    if (failed_) {
        ++counters_.failures;
        return hal::AcquireStatus::Failed;
    }
    const Nanoseconds deadline = clock_.now() + timeout;
    while (true) {
        const std::uint64_t index = nextIndex_;
        const Nanoseconds start = exposureStart(index);
        const Nanoseconds ready = start + exposure_ + kSyncSkew + kReadout;
        if (stalled_ || ready > deadline) {
            clock_.advanceTo(deadline);
            return hal::AcquireStatus::Timeout;
        }
        // A host that fell behind (real time) finds exposures read out while it was busy: the
        // sensor filled as many as it had free buffers for, oldest first, and dropped the rest.
        // (In virtual time a test moves the clock, and capture stands for a thread that took
        // each frame as it came.)
        if (const Nanoseconds now = clock_.now();
            clock_.isRealTime() && now > ready && index >= skipTo_) {
            std::uint64_t free = 0;
            for (const bool held : held_)
                free += held ? 0U : 1U;
            std::uint64_t readOut = 1;
            while (exposureStart(index + readOut) + exposure_ + kSyncSkew + kReadout <= now)
                ++readOut;
            if (readOut > free && free > 0) {
                counters_.droppedNoBuffer += readOut - free;
                skipFrom_ = index + free;
                skipTo_ = index + readOut;
            }
        }
        clock_.advanceTo(ready);
        ++nextIndex_;
        if (index >= skipFrom_ && index < skipTo_)
            continue; // already counted as dropped

        if (dropPartnerEvery_ > 0 && (index + 1) % dropPartnerEvery_ == 0) {
            ++counters_.droppedUnpaired;
            continue;
        }
        int slot = -1;
        for (std::size_t i = 0; i < held_.size(); ++i)
            if (!held_[i]) {
                slot = static_cast<int>(i);
                break;
            }
        if (slot < 0) {
            ++counters_.droppedNoBuffer;
            continue;
        }

        world_.observe(index, observation_);
        addSpuriousBurst(index);
        const auto s = static_cast<std::size_t>(slot);
        held_[s] = true;
        // The exposure's index, as in `edgetrack sim`'s recordings: frame k of both shows the
        // scene at k / rate, and a dropped exposure leaves a gap.
        frame.number = index;
        frame.slot = slot;
        for (int camera = 0; camera < 2; ++camera) {
            const auto c = static_cast<std::size_t>(camera);
            std::vector<std::uint8_t>& buffer = buffers_[2 * s + c];
            const Nanoseconds begin = start + camera * kSyncSkew;
            renderer_.render(buffer, width_, camera, observation_,
                             led_.litFraction(begin, begin + exposure_), index);
            hal::CameraFrame& out = frame.camera[c];
            out.pixels = buffer.data();
            out.width_px = width_;
            out.height_px = height_;
            out.stride_bytes = width_;
            out.exposureStart = begin;
            out.exposureEnd = begin + exposure_;
            out.sequence = index;
        }
        led_.forgetBefore(start);
        ++counters_.delivered;
        return hal::AcquireStatus::Frame;
    }
}

void SimCameraPair::release(const hal::StereoFrame& frame) {
    if (frame.slot >= 0 && static_cast<std::size_t>(frame.slot) < held_.size())
        held_[static_cast<std::size_t>(frame.slot)] = false;
}

} // namespace edgetrack::sim
