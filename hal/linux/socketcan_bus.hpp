// Linux backend: a CAN / CAN FD interface through a non-blocking SocketCAN raw socket.
#pragma once

#include <cstddef>
#include <string>

#include "core/ring_buffer.hpp"
#include "hal/can_bus.hpp"
#include "hal/clock.hpp"

namespace edgetrack::linux_hal {

/// \brief Settings of one SocketCAN interface (the [can] section of the configuration).
struct SocketCanConfig {
    /// Interface name, e.g. "can0" (or "vcan0" in the hardware tests).
    std::string interface = "can0";
    /// Open the socket for CAN FD frames (CAN_RAW_FD_FRAMES); the interface's MTU must allow them.
    bool fd = false;
    /// Frames kept by this backend while the kernel's queue is full; the oldest is dropped.
    std::size_t transmitQueueDepth = 16;
    /// Received data frames and error events kept until read; the oldest are dropped.
    std::size_t receiveQueueDepth = 64;
    std::size_t errorQueueDepth = 32;
};

/**
 * \brief CanBus on a SocketCAN raw socket bound to one interface.
 *
 * Sending never blocks: a frame the kernel cannot take now (EAGAIN, ENOBUFS: the controller's
 * queue is full) waits in a bounded queue that is retried, in order, before every later frame and
 * at every receive(); when it is full the oldest frame is dropped and counted. The controller's
 * error frames (CAN_RAW_ERR_FILTER) drive state(): warning and passive levels, bus-off (sends
 * refused) and the kernel's restart after bus-off (restart-ms or `ip link set can0 type can
 * restart`). An interface that goes down is reported as Down and its queue is cleared; the next
 * sends probe it and resume when it is up again, re-binding when it was removed and re-created.
 * Storage is allocated in the constructor only.
 */
class SocketCanBus : public hal::CanBus {
public:
    /// \param clock stamps error events; must outlive the bus.
    SocketCanBus(const SocketCanConfig& config, const hal::Clock& clock);
    ~SocketCanBus() override;
    SocketCanBus(const SocketCanBus&) = delete;
    SocketCanBus& operator=(const SocketCanBus&) = delete;

    /// \return false when the interface could not be opened at construction; errorText() says why.
    bool isValid() const { return valid_; }
    const std::string& errorText() const { return errorText_; }

    hal::CanSendResult send(const hal::CanFrame& frame) override;
    bool receive(hal::CanFrame& frame) override;
    bool nextError(hal::CanErrorEvent& event) override;
    hal::CanState state() const override { return state_; }
    hal::CanCounters counters() const override { return counters_; }

    /**
     * \brief Whether the interface is up now, without sending: re-opens a removed interface and
     * reads its IFF_UP flag, leaving Down when it is up again (for start-up readiness).
     */
    bool probe();

    /// \return frames waiting in this backend's transmit queue.
    std::size_t queued() const { return transmitQueue_.size(); }

private:
    enum class WriteOutcome { Written, Busy, Down, Gone, Failed };

    bool open();
    void close();
    WriteOutcome write(const hal::CanFrame& frame);
    /// \brief Write queued frames in order until the kernel refuses one.
    void flushQueue();
    /// \brief Read every pending frame: data into the receive queue, errors into the error queue.
    void drainSocket();
    void handleErrorFrame(unsigned int canId, const unsigned char* data);
    void setState(hal::CanState state, std::uint32_t errorClass);
    /// \brief Drop every queued frame, counted as dropped.
    void dropQueued();
    void goDown(bool gone);

    SocketCanConfig config_;
    const hal::Clock& clock_;
    int fd_ = -1;
    bool valid_ = false;
    std::string errorText_;
    hal::CanState state_ = hal::CanState::ErrorActive;
    hal::CanCounters counters_{};
    RingBuffer<hal::CanFrame> transmitQueue_;
    RingBuffer<hal::CanFrame> receiveQueue_;
    RingBuffer<hal::CanErrorEvent> errors_;
    hal::CanFrame scratch_{};
};

} // namespace edgetrack::linux_hal
