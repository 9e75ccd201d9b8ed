// HAL interface: non-blocking UDP datagrams to unicast or multicast destinations.
#pragma once

#include <array>
#include <cstdint>
#include <span>

namespace edgetrack::hal {

/// \brief An IPv4 destination; multicast groups (224.0.0.0/4) are addresses like any other.
struct UdpEndpoint {
    std::array<std::uint8_t, 4> address{127, 0, 0, 1};
    std::uint16_t port = 0;

    bool operator==(const UdpEndpoint&) const = default;
    bool isMulticast() const { return (address[0] & 0xF0) == 0xE0; }
};

enum class UdpSendResult { Sent, WouldBlock, Unreachable, Failed };

struct UdpCounters {
    std::uint64_t sent = 0;
    std::uint64_t failed = 0;
};

/// \brief Sends datagrams; never blocks, never fatal. Errors are counted.
class UdpSender {
public:
    virtual ~UdpSender() = default;
    virtual UdpSendResult send(const UdpEndpoint& to, std::span<const std::uint8_t> datagram) = 0;
    virtual UdpCounters counters() const = 0;
};

} // namespace edgetrack::hal
