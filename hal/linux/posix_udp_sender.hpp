// Linux backend: UDP datagrams through a non-blocking POSIX socket (unicast and multicast).
#pragma once

#include "hal/udp.hpp"

namespace edgetrack::linux_hal {

/**
 * \brief Sends datagrams with sendto() on one non-blocking IPv4 socket.
 *
 * Never blocks and never fails fatally: a full socket buffer is WouldBlock, an ICMP error from an
 * earlier datagram or a missing route is Unreachable, anything else Failed; all are counted.
 * Multicast goes out with TTL 1 (the tracking network) and loops back to local receivers.
 */
class PosixUdpSender : public hal::UdpSender {
public:
    PosixUdpSender();
    ~PosixUdpSender() override;
    PosixUdpSender(const PosixUdpSender&) = delete;
    PosixUdpSender& operator=(const PosixUdpSender&) = delete;

    /// \return false when no socket could be opened (the error is in errnoAtOpen()).
    bool isValid() const { return fd_ >= 0; }
    int errnoAtOpen() const { return openErrno_; }

    hal::UdpSendResult send(const hal::UdpEndpoint& to,
                            std::span<const std::uint8_t> datagram) override;
    hal::UdpCounters counters() const override { return counters_; }

private:
    int fd_ = -1;
    int openErrno_ = 0;
    hal::UdpCounters counters_{};
};

} // namespace edgetrack::linux_hal
