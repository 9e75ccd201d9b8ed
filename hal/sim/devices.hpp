// Simulated board devices: clock, LED ring, button, status LED, flash, CAN bus, UDP.
#pragma once

#include <array>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string_view>
#include <vector>

#include "core/bounded_vector.hpp"
#include "core/ring_buffer.hpp"
#include "hal/button.hpp"
#include "hal/can_bus.hpp"
#include "hal/clock.hpp"
#include "hal/flash.hpp"
#include "hal/led_ring.hpp"
#include "hal/status_led.hpp"
#include "hal/udp.hpp"

namespace edgetrack::sim {

using hal::Nanoseconds;

/**
 * \brief The simulated board's clock.
 *
 * Virtual by default: sleepUntil() jumps, so tests run as fast as the host allows and are
 * repeatable. In real-time mode it is the host's clock since construction: sleepUntil() sleeps
 * on the host, so `edgetrack run` paces at camera rate, and a host that falls behind does not
 * hold time back (the cameras drop the frames nobody took, and latencies are real).
 */
class SimClock : public hal::Clock {
public:
    explicit SimClock(bool realTime = false);

    Nanoseconds now() const override;
    void sleepUntil(Nanoseconds deadline) override;
    /// Virtual time 0 is 2026-01-01 12:00:00 UTC, so runs repeat exactly; in real-time mode it is
    /// the host's wall clock at construction.
    Nanoseconds utcOffset() const override { return utcOffset_; }

    /// \brief Move virtual time forward to \a t (never backward).
    void advanceTo(Nanoseconds t);
    bool isRealTime() const { return realTime_; }

private:
    Nanoseconds now_ = 0;
    bool realTime_;
    Nanoseconds hostStart_ = 0;
    Nanoseconds utcOffset_ = 0;
};

/// \brief The LED ring: remembers when it was lit so that the cameras know what they saw.
class SimLedRing : public hal::LedRing {
public:
    void setContinuous(bool on) override { continuous_ = on; }
    bool schedulePulse(Nanoseconds onAt, Nanoseconds offAt) override;
    std::uint64_t droppedPulses() const override { return pulses_.overflowCount(); }

    /// \return the share of [start, end) during which the ring was lit (0 to 1).
    double litFraction(Nanoseconds start, Nanoseconds end) const;
    bool continuous() const { return continuous_; }

    /// \brief Forget pulses that ended before \a t (the camera calls this as time passes).
    void forgetBefore(Nanoseconds t);

    static constexpr std::size_t kPulseQueue = 8;

private:
    struct Pulse {
        Nanoseconds on = 0;
        Nanoseconds off = 0;
    };
    bool continuous_ = false;
    FixedVector<Pulse, kPulseQueue> pulses_;
};

/// \brief The push button; tests press it at chosen times, with optional contact bounce.
class SimButton : public hal::Button {
public:
    explicit SimButton(const hal::Clock& clock)
        : clock_(clock)
        , edges_(kEdgeQueue) {}

    static constexpr std::size_t kEdgeQueue = 64;

    /// \brief A press at \a at lasting \a duration; \a bounces extra edges 0.3 ms apart at each
    /// end.
    void press(Nanoseconds at, Nanoseconds duration, int bounces = 0);

    /// \brief Edges become visible once the clock has passed them, as on real hardware.
    bool nextEdge(hal::ButtonEdge& edge) override;

    std::size_t pendingEdges() const { return edges_.size(); }

private:
    const hal::Clock& clock_;
    RingBuffer<hal::ButtonEdge> edges_;
};

/// \brief The status LED; tests read its state and the times it changed.
class SimStatusLed : public hal::StatusLed {
public:
    explicit SimStatusLed(const hal::Clock& clock)
        : clock_(clock) {}

    void set(bool on) override;

    bool isOn() const { return on_; }
    std::uint64_t changes() const { return changes_; }
    /// \return the time of the last change.
    Nanoseconds lastChange() const { return lastChange_; }

private:
    const hal::Clock& clock_;
    bool on_ = false;
    std::uint64_t changes_ = 0;
    Nanoseconds lastChange_ = 0;
};

/**
 * \brief NOR flash in memory: erase sets 0xFF, write ANDs, and power can be cut mid-operation.
 *
 * cutPowerAfter(k) lets k more erase/write operations complete; the next one is torn (a write
 * lands only its first part, an erase resets only part of its range) and fails, and every
 * operation after it fails until restorePower(), as after an unplugged board. Contents survive.
 */
class SimFlash : public hal::Flash {
public:
    SimFlash(std::size_t size, std::size_t eraseBlockSize);

    std::size_t size() const override { return contents_.size(); }
    std::size_t eraseBlockSize() const override { return eraseBlockSize_; }
    Status read(std::size_t offset, std::span<std::uint8_t> out) override;
    Status erase(std::size_t offset, std::size_t length) override;
    Status write(std::size_t offset, std::span<const std::uint8_t> data) override;

    /// \param tornShare share of the torn operation that lands (0 to 1).
    void cutPowerAfter(std::uint64_t operations, double tornShare = 0.5);
    void restorePower();
    bool powered() const { return powered_; }
    /// \brief A busy flash (a slow SD card): erases and writes wait, in whatever thread makes
    /// them, until releaseOperations().
    void holdOperations();
    void releaseOperations();
    /// \return whether an operation is waiting for releaseOperations().
    bool operationWaiting() const;
    /// \return erase and write operations performed since construction.
    std::uint64_t operations() const { return operations_; }

    const std::vector<std::uint8_t>& contents() const { return contents_; }
    std::vector<std::uint8_t>& contents() { return contents_; }

private:
    Status checkRange(const char* what, std::size_t offset, std::size_t length) const;
    /// \return how much of an operation of \a length lands: all, or a torn part with power lost.
    std::size_t landing(std::size_t length);
    void waitWhileHeld();

    std::vector<std::uint8_t> contents_;
    std::size_t eraseBlockSize_;
    std::uint64_t operations_ = 0;
    std::uint64_t cutAt_ = 0;
    bool cutArmed_ = false;
    double tornShare_ = 0.5;
    bool powered_ = true;
    mutable std::mutex holdMutex_;
    std::condition_variable released_;
    bool held_ = false;
    bool waiting_ = false;
};

/**
 * \brief A CAN bus with a peer at the other end, and faults to inject.
 *
 * Sent frames wait in a transmit queue of fixed depth; while the bus is free they go straight to
 * the peer, who reads them with peerReceive(). Frames the peer sends arrive in receive().
 */
class SimCanBus : public hal::CanBus {
public:
    SimCanBus(const hal::Clock& clock, std::size_t transmitQueueDepth = 16,
              std::size_t peerLogDepth = 4096);

    hal::CanSendResult send(const hal::CanFrame& frame) override;
    bool receive(hal::CanFrame& frame) override;
    bool nextError(hal::CanErrorEvent& event) override;
    hal::CanState state() const override { return state_; }
    hal::CanCounters counters() const override { return counters_; }

    // The peer's side.
    bool peerReceive(hal::CanFrame& frame);
    void peerSend(const hal::CanFrame& frame);

    // Faults.
    /// \brief Frames stay queued (no acknowledgement) until unblocked; the queue then overflows.
    void setTransmitBlocked(bool blocked);
    void injectBusOff();
    /// \brief The controller restarts after bus-off (as with restart-ms on Linux).
    void restart();
    void injectErrorFrame(hal::CanState state, std::uint32_t errorClass);
    void setDown(bool down);

private:
    void deliverQueued();
    void report(hal::CanState state, std::uint32_t errorClass);

    const hal::Clock& clock_;
    RingBuffer<hal::CanFrame> transmitQueue_;
    RingBuffer<hal::CanFrame> peerLog_;
    RingBuffer<hal::CanFrame> receiveQueue_;
    RingBuffer<hal::CanErrorEvent> errors_;
    hal::CanState state_ = hal::CanState::ErrorActive;
    bool blocked_ = false;
    hal::CanCounters counters_{};
};

/// \brief UDP in memory: keeps the last datagrams for tests (the oldest are dropped when full);
/// destinations can be made unreachable. A datagram longer than kMaxDatagram fails: the firmware
/// never needs more (DTrack frames of 16 bodies or 128 markers are under 8 KB; IP fragments what
/// is over one Ethernet frame).
class SimUdpSender : public hal::UdpSender {
public:
    explicit SimUdpSender(std::size_t keep = 256);

    hal::UdpSendResult send(const hal::UdpEndpoint& to,
                            std::span<const std::uint8_t> datagram) override;
    hal::UdpCounters counters() const override { return counters_; }

    static constexpr std::size_t kMaxDatagram = 8192;

    struct Datagram {
        hal::UdpEndpoint to;
        std::size_t length = 0;
        std::array<std::uint8_t, kMaxDatagram> bytes{};

        std::string_view text() const {
            return {reinterpret_cast<const char*>(bytes.data()), length};
        }
    };
    /// \brief Take the oldest kept datagram. \return false when there is none.
    bool takeSent(Datagram& datagram);
    void setUnreachable(const hal::UdpEndpoint& endpoint, bool unreachable);

private:
    RingBuffer<Datagram> sent_;
    std::vector<hal::UdpEndpoint> unreachable_;
    hal::UdpCounters counters_{};
};

} // namespace edgetrack::sim
