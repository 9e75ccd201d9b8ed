// Linux backend: non-blocking UDP sends with sendto().
#include "hal/linux/posix_udp_sender.hpp"

#include <arpa/inet.h>
#include <cerrno>
#include <cstring>
#include <netinet/in.h>
#include <sys/socket.h>
#include <unistd.h>

namespace edgetrack::linux_hal {

PosixUdpSender::PosixUdpSender() {
    fd_ = ::socket(AF_INET, SOCK_DGRAM | SOCK_NONBLOCK | SOCK_CLOEXEC, 0);
    if (fd_ < 0) {
        openErrno_ = errno;
        return;
    }
    const unsigned char ttl = 1;
    const unsigned char loop = 1;
    ::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_TTL, &ttl, sizeof ttl);
    ::setsockopt(fd_, IPPROTO_IP, IP_MULTICAST_LOOP, &loop, sizeof loop);
}

PosixUdpSender::~PosixUdpSender() {
    if (fd_ >= 0)
        ::close(fd_);
}

hal::UdpSendResult PosixUdpSender::send(const hal::UdpEndpoint& to,
                                        std::span<const std::uint8_t> datagram) {
    if (fd_ < 0) {
        ++counters_.failed;
        return hal::UdpSendResult::Failed;
    }
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(to.port);
    std::memcpy(&address.sin_addr.s_addr, to.address.data(), 4);
    const ssize_t sent = ::sendto(fd_, datagram.data(), datagram.size(), MSG_DONTWAIT,
                                  reinterpret_cast<const sockaddr*>(&address), sizeof address);
    if (sent == static_cast<ssize_t>(datagram.size())) {
        ++counters_.sent;
        return hal::UdpSendResult::Sent;
    }
    ++counters_.failed;
    switch (errno) {
    case EAGAIN:
    case ENOBUFS:
        return hal::UdpSendResult::WouldBlock;
    case ECONNREFUSED:
    case ENETUNREACH:
    case EHOSTUNREACH:
    case ENETDOWN:
        return hal::UdpSendResult::Unreachable;
    default:
        return hal::UdpSendResult::Failed;
    }
}

} // namespace edgetrack::linux_hal
