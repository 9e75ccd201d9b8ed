// Simulated board devices: clock, LED ring, button, status LED, flash, CAN bus, UDP.
#include "hal/sim/devices.hpp"

#include <algorithm>
#include <chrono>
#include <cstring>
#include <thread>

namespace edgetrack::sim {

namespace {
Nanoseconds hostNow() {
    return std::chrono::duration_cast<std::chrono::nanoseconds>(
               std::chrono::steady_clock::now().time_since_epoch())
        .count();
}
} // namespace

SimClock::SimClock(bool realTime)
    : realTime_(realTime)
    , hostStart_(realTime ? hostNow() : 0) {
    constexpr Nanoseconds kNoon20260101 = 1'767'268'800LL * hal::kNanosecondsPerSecond;
    utcOffset_ = realTime ? std::chrono::duration_cast<std::chrono::nanoseconds>(
                                std::chrono::system_clock::now().time_since_epoch())
                                .count()
                          : kNoon20260101;
}

Nanoseconds SimClock::now() const {
    return realTime_ ? std::max(now_, hostNow() - hostStart_) : now_;
}

void SimClock::advanceTo(Nanoseconds t) {
    if (t <= now_)
        return;
    if (realTime_) {
        const Nanoseconds wait = hostStart_ + t - hostNow();
        if (wait > 0)
            std::this_thread::sleep_for(std::chrono::nanoseconds(wait));
    }
    now_ = t;
}

void SimClock::sleepUntil(Nanoseconds deadline) {
    advanceTo(deadline);
}

// ---------------------------------------------------------------------------------------------

bool SimLedRing::schedulePulse(Nanoseconds onAt, Nanoseconds offAt) {
    if (offAt <= onAt)
        return true; // an empty pulse lights nothing
    return pulses_.push_back({onAt, offAt});
}

double SimLedRing::litFraction(Nanoseconds start, Nanoseconds end) const {
    if (continuous_)
        return 1.0;
    if (end <= start)
        return 0.0;
    Nanoseconds lit = 0;
    for (const Pulse& p : pulses_)
        lit += std::max<Nanoseconds>(0, std::min(end, p.off) - std::max(start, p.on));
    return std::min(1.0, static_cast<double>(lit) / static_cast<double>(end - start));
}

void SimLedRing::forgetBefore(Nanoseconds t) {
    for (std::size_t i = 0; i < pulses_.size();) {
        if (pulses_[i].off < t)
            pulses_.swapRemove(i);
        else
            ++i;
    }
}

// ---------------------------------------------------------------------------------------------

void SimButton::press(Nanoseconds at, Nanoseconds duration, int bounces) {
    constexpr Nanoseconds kBounceGap = 300'000;
    auto edge = [this](Nanoseconds t, bool pressed) { edges_.pushDropOldest({t, pressed}); };
    // A bouncing contact closes, opens and closes again before it settles.
    for (int i = 0; i < bounces; ++i) {
        edge(at + 2 * i * kBounceGap, true);
        edge(at + (2 * i + 1) * kBounceGap, false);
    }
    edge(at + 2 * bounces * kBounceGap, true);
    const Nanoseconds release = at + duration;
    for (int i = 0; i < bounces; ++i) {
        edge(release + 2 * i * kBounceGap, false);
        edge(release + (2 * i + 1) * kBounceGap, true);
    }
    edge(release + 2 * bounces * kBounceGap, false);
}

bool SimButton::nextEdge(hal::ButtonEdge& edge) {
    if (edges_.empty() || edges_.front().time > clock_.now())
        return false;
    return edges_.pop(edge);
}

// ---------------------------------------------------------------------------------------------

void SimStatusLed::set(bool on) {
    if (on == on_)
        return;
    on_ = on;
    ++changes_;
    lastChange_ = clock_.now();
}

// ---------------------------------------------------------------------------------------------

SimFlash::SimFlash(std::size_t size, std::size_t eraseBlockSize)
    : contents_(size, 0xFF)
    , eraseBlockSize_(eraseBlockSize) {}

Status SimFlash::checkRange(const char* what, std::size_t offset, std::size_t length) const {
    if (!powered_)
        return Error{std::string("flash ") + what + ": no power"};
    if (offset > contents_.size() || length > contents_.size() - offset)
        return Error{std::string("flash ") + what + ": range " + std::to_string(offset) + "+" +
                     std::to_string(length) + " is outside the partition"};
    return Ok{};
}

std::size_t SimFlash::landing(std::size_t length) {
    ++operations_;
    if (cutArmed_ && operations_ > cutAt_) {
        cutArmed_ = false;
        powered_ = false;
        return static_cast<std::size_t>(tornShare_ * static_cast<double>(length));
    }
    return length;
}

Status SimFlash::read(std::size_t offset, std::span<std::uint8_t> out) {
    if (Status s = checkRange("read", offset, out.size()); !s)
        return s;
    std::memcpy(out.data(), contents_.data() + offset, out.size());
    return Ok{};
}

Status SimFlash::erase(std::size_t offset, std::size_t length) {
    waitWhileHeld();
    if (Status s = checkRange("erase", offset, length); !s)
        return s;
    if (offset % eraseBlockSize_ != 0 || length % eraseBlockSize_ != 0)
        return Error{"flash erase: " + std::to_string(offset) + "+" + std::to_string(length) +
                     " is not aligned to the " + std::to_string(eraseBlockSize_) +
                     "-byte erase block"};
    const std::size_t landed = landing(length);
    std::fill_n(contents_.begin() + static_cast<std::ptrdiff_t>(offset), landed, 0xFF);
    if (!powered_)
        return Error{"flash erase: power lost"};
    return Ok{};
}

Status SimFlash::write(std::size_t offset, std::span<const std::uint8_t> data) {
    waitWhileHeld();
    if (Status s = checkRange("write", offset, data.size()); !s)
        return s;
    const std::size_t landed = landing(data.size());
    // NOR flash can only clear bits; setting one needs an erase.
    for (std::size_t i = 0; i < landed; ++i)
        contents_[offset + i] &= data[i];
    if (!powered_)
        return Error{"flash write: power lost"};
    return Ok{};
}

void SimFlash::cutPowerAfter(std::uint64_t operations, double tornShare) {
    cutArmed_ = true;
    cutAt_ = operations_ + operations;
    tornShare_ = std::clamp(tornShare, 0.0, 1.0);
}

void SimFlash::restorePower() {
    powered_ = true;
    cutArmed_ = false;
}

void SimFlash::holdOperations() {
    const std::lock_guard lock(holdMutex_);
    held_ = true;
}

void SimFlash::releaseOperations() {
    {
        const std::lock_guard lock(holdMutex_);
        held_ = false;
    }
    released_.notify_all();
}

bool SimFlash::operationWaiting() const {
    const std::lock_guard lock(holdMutex_);
    return waiting_;
}

void SimFlash::waitWhileHeld() {
    std::unique_lock lock(holdMutex_);
    waiting_ = held_;
    released_.wait(lock, [this] { return !held_; });
    waiting_ = false;
}

// ---------------------------------------------------------------------------------------------

SimCanBus::SimCanBus(const hal::Clock& clock, std::size_t transmitQueueDepth,
                     std::size_t peerLogDepth)
    : clock_(clock)
    , transmitQueue_(transmitQueueDepth)
    , peerLog_(peerLogDepth)
    , receiveQueue_(256)
    , errors_(64) {}

hal::CanSendResult SimCanBus::send(const hal::CanFrame& frame) {
    if (!hal::isValidCanFrame(frame)) {
        ++counters_.refused;
        return hal::CanSendResult::Invalid;
    }
    if (state_ == hal::CanState::Down) {
        ++counters_.refused;
        return hal::CanSendResult::Down;
    }
    if (state_ == hal::CanState::BusOff) {
        ++counters_.refused;
        return hal::CanSendResult::BusOff;
    }
    const bool dropped = transmitQueue_.pushDropOldest(frame);
    if (dropped)
        ++counters_.droppedQueueFull;
    deliverQueued();
    return dropped ? hal::CanSendResult::DroppedOldest : hal::CanSendResult::Queued;
}

void SimCanBus::deliverQueued() {
    if (blocked_ || state_ == hal::CanState::BusOff || state_ == hal::CanState::Down)
        return;
    hal::CanFrame frame;
    while (transmitQueue_.pop(frame)) {
        peerLog_.pushDropOldest(frame);
        ++counters_.sent;
    }
}

bool SimCanBus::receive(hal::CanFrame& frame) {
    if (!receiveQueue_.pop(frame))
        return false;
    ++counters_.received;
    return true;
}

bool SimCanBus::nextError(hal::CanErrorEvent& event) {
    return errors_.pop(event);
}

bool SimCanBus::peerReceive(hal::CanFrame& frame) {
    return peerLog_.pop(frame);
}

void SimCanBus::peerSend(const hal::CanFrame& frame) {
    if (state_ != hal::CanState::Down)
        receiveQueue_.pushDropOldest(frame);
}

void SimCanBus::setTransmitBlocked(bool blocked) {
    blocked_ = blocked;
    deliverQueued();
}

void SimCanBus::report(hal::CanState state, std::uint32_t errorClass) {
    state_ = state;
    ++counters_.errorEvents;
    errors_.pushDropOldest({clock_.now(), state, errorClass});
}

void SimCanBus::injectBusOff() {
    constexpr std::uint32_t kCanErrBusOff = 0x40; // CAN_ERR_BUSOFF
    report(hal::CanState::BusOff, kCanErrBusOff);
}

void SimCanBus::restart() {
    constexpr std::uint32_t kCanErrRestarted = 0x100; // CAN_ERR_RESTARTED
    report(hal::CanState::ErrorActive, kCanErrRestarted);
    deliverQueued();
}

void SimCanBus::injectErrorFrame(hal::CanState state, std::uint32_t errorClass) {
    report(state, errorClass);
}

void SimCanBus::setDown(bool down) {
    if (down) {
        state_ = hal::CanState::Down;
        transmitQueue_.clear();
    } else if (state_ == hal::CanState::Down) {
        state_ = hal::CanState::ErrorActive;
    }
}

// ---------------------------------------------------------------------------------------------

SimUdpSender::SimUdpSender(std::size_t keep)
    : sent_(keep) {
    unreachable_.reserve(8);
}

hal::UdpSendResult SimUdpSender::send(const hal::UdpEndpoint& to,
                                      std::span<const std::uint8_t> datagram) {
    if (datagram.size() > kMaxDatagram) {
        ++counters_.failed;
        return hal::UdpSendResult::Failed;
    }
    if (std::find(unreachable_.begin(), unreachable_.end(), to) != unreachable_.end()) {
        ++counters_.failed;
        return hal::UdpSendResult::Unreachable;
    }
    Datagram d;
    d.to = to;
    d.length = datagram.size();
    std::copy(datagram.begin(), datagram.end(), d.bytes.begin());
    sent_.pushDropOldest(d);
    ++counters_.sent;
    return hal::UdpSendResult::Sent;
}

bool SimUdpSender::takeSent(Datagram& datagram) {
    return sent_.pop(datagram);
}

void SimUdpSender::setUnreachable(const hal::UdpEndpoint& endpoint, bool unreachable) {
    std::erase(unreachable_, endpoint);
    if (unreachable)
        unreachable_.push_back(endpoint);
}

} // namespace edgetrack::sim
