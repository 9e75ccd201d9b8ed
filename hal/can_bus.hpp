// HAL interface: a CAN / CAN FD controller (SocketCAN raw socket semantics).
#pragma once

#include <array>
#include <cstdint>

#include "hal/types.hpp"

namespace edgetrack::hal {

/// \brief A classic (up to 8 bytes) or FD (up to 64 bytes) frame, as struct canfd_frame.
struct CanFrame {
    std::uint32_t id = 0;
    bool extended = false;
    bool fd = false;
    /// CAN FD bit-rate switch for the data phase.
    bool bitRateSwitch = false;
    std::uint8_t length = 0;
    std::array<std::uint8_t, 64> data{};
};

/// \return true for a payload length a frame can carry (0-8, and 12..64 in FD's steps).
constexpr bool isValidCanLength(std::uint8_t length, bool fd) {
    if (length <= 8)
        return true;
    if (!fd)
        return false;
    return length == 12 || length == 16 || length == 20 || length == 24 || length == 32 ||
           length == 48 || length == 64;
}

/// \return true for a frame any controller may send: identifier within 11 or 29 bits, a valid
/// length, and the bit-rate switch only on FD frames.
constexpr bool isValidCanFrame(const CanFrame& frame) {
    const std::uint32_t maxId = frame.extended ? 0x1FFFFFFFu : 0x7FFu;
    return frame.id <= maxId && isValidCanLength(frame.length, frame.fd) &&
           (frame.fd || !frame.bitRateSwitch);
}

/// \brief Controller states of ISO 11898 error confinement, plus interface down.
enum class CanState { ErrorActive, ErrorWarning, ErrorPassive, BusOff, Down };

/// \return the state as SocketCAN's documentation names it, e.g. "error passive", "bus-off".
constexpr const char* canStateName(CanState state) {
    switch (state) {
    case CanState::ErrorActive:
        return "error active";
    case CanState::ErrorWarning:
        return "error warning";
    case CanState::ErrorPassive:
        return "error passive";
    case CanState::BusOff:
        return "bus-off";
    case CanState::Down:
        return "down";
    }
    return "?";
}

enum class CanSendResult {
    Queued,        ///< accepted for transmission
    DroppedOldest, ///< queue was full: the oldest queued frame was dropped to make room
    BusOff,        ///< the controller is bus-off; nothing is sent until it recovers
    Down,          ///< the interface is down
    Invalid,       ///< bad length or identifier
};

/// \brief A controller error or state change, as SocketCAN's error frames report them.
struct CanErrorEvent {
    Nanoseconds time = 0;
    CanState state = CanState::ErrorActive;
    /// CAN_ERR_* class bits of the error frame (0 for a pure state change).
    std::uint32_t errorClass = 0;
};

struct CanCounters {
    std::uint64_t sent = 0;
    std::uint64_t droppedQueueFull = 0;
    std::uint64_t refused = 0;
    std::uint64_t errorEvents = 0;
    std::uint64_t received = 0;
};

/// \brief One CAN interface. Sending never blocks.
class CanBus {
public:
    virtual ~CanBus() = default;

    virtual CanSendResult send(const CanFrame& frame) = 0;
    /// \brief Take a received frame without blocking. \return false when there is none.
    virtual bool receive(CanFrame& frame) = 0;
    /// \brief Take the oldest error event without blocking. \return false when there is none.
    virtual bool nextError(CanErrorEvent& event) = 0;
    virtual CanState state() const = 0;
    virtual CanCounters counters() const = 0;
};

} // namespace edgetrack::hal
