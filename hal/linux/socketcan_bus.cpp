// Linux backend: a CAN / CAN FD interface through a non-blocking SocketCAN raw socket.
#include "hal/linux/socketcan_bus.hpp"

#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <linux/can.h>
#include <linux/can/error.h>
#include <linux/can/raw.h>
#include <net/if.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

namespace edgetrack::linux_hal {

SocketCanBus::SocketCanBus(const SocketCanConfig& config, const hal::Clock& clock)
    : config_(config)
    , clock_(clock)
    , transmitQueue_(config.transmitQueueDepth)
    , receiveQueue_(config.receiveQueueDepth)
    , errors_(config.errorQueueDepth) {
    valid_ = open();
    if (!valid_)
        state_ = hal::CanState::Down;
}

SocketCanBus::~SocketCanBus() {
    close();
}

bool SocketCanBus::open() {
    const auto fail = [&](const char* what) {
        errorText_ = config_.interface + ": " + what + ": " + std::strerror(errno);
        close();
        return false;
    };
    if (config_.interface.empty() || config_.interface.size() >= IFNAMSIZ) {
        errorText_ = "CAN interface name \"" + config_.interface + "\" is not valid";
        return false;
    }
    fd_ = ::socket(PF_CAN, SOCK_RAW | SOCK_NONBLOCK | SOCK_CLOEXEC, CAN_RAW);
    if (fd_ < 0)
        return fail("cannot open a CAN raw socket (is the can-raw module loaded?)");
    const int on = 1;
    if (config_.fd && ::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_FD_FRAMES, &on, sizeof on) != 0)
        return fail("the kernel refuses CAN FD frames");
    const can_err_mask_t errorMask = CAN_ERR_MASK;
    if (::setsockopt(fd_, SOL_CAN_RAW, CAN_RAW_ERR_FILTER, &errorMask, sizeof errorMask) != 0)
        return fail("cannot subscribe to error frames");

    ifreq request{};
    std::memcpy(request.ifr_name, config_.interface.c_str(), config_.interface.size() + 1);
    if (::ioctl(fd_, SIOCGIFINDEX, &request) != 0)
        return fail("no such interface");
    sockaddr_can address{};
    address.can_family = AF_CAN;
    address.can_ifindex = request.ifr_ifindex;
    if (::bind(fd_, reinterpret_cast<const sockaddr*>(&address), sizeof address) != 0)
        return fail("cannot bind");
    if (config_.fd) {
        // A classic controller (MTU 16) takes no FD frame: say so now, not at the first pose.
        if (::ioctl(fd_, SIOCGIFMTU, &request) == 0 && request.ifr_mtu != CANFD_MTU) {
            errno = EPROTONOSUPPORT;
            return fail("interface is not CAN FD (MTU is not 72)");
        }
    }
    errorText_.clear();
    return true;
}

void SocketCanBus::close() {
    if (fd_ >= 0)
        ::close(fd_);
    fd_ = -1;
}

SocketCanBus::WriteOutcome SocketCanBus::write(const hal::CanFrame& frame) {
    canfd_frame raw{};
    raw.can_id = frame.id | (frame.extended ? CAN_EFF_FLAG : 0u);
    raw.len = frame.length;
    if (frame.fd && frame.bitRateSwitch)
        raw.flags = CANFD_BRS;
    std::memcpy(raw.data, frame.data.data(), frame.length);
    const std::size_t size = frame.fd ? CANFD_MTU : CAN_MTU;
    const ssize_t written = ::write(fd_, &raw, size);
    if (written == static_cast<ssize_t>(size))
        return WriteOutcome::Written;
    if (written >= 0)
        return WriteOutcome::Failed;
    switch (errno) {
    case EAGAIN:
    case ENOBUFS:
        return WriteOutcome::Busy;
    case ENETDOWN:
        return WriteOutcome::Down;
    case ENODEV:
    case ENXIO:
        return WriteOutcome::Gone;
    default:
        return WriteOutcome::Failed;
    }
}

void SocketCanBus::dropQueued() {
    counters_.droppedQueueFull += transmitQueue_.size();
    transmitQueue_.clear();
}

void SocketCanBus::goDown(bool gone) {
    // Frames queued for a bus that went away are stale by the time it is back: drop them.
    dropQueued();
    if (gone)
        close();
    setState(hal::CanState::Down, 0);
}

void SocketCanBus::flushQueue() {
    while (!transmitQueue_.empty() && fd_ >= 0) {
        const WriteOutcome outcome = write(transmitQueue_.front());
        switch (outcome) {
        case WriteOutcome::Written:
            transmitQueue_.pop(scratch_);
            ++counters_.sent;
            break;
        case WriteOutcome::Busy:
            return;
        case WriteOutcome::Down:
        case WriteOutcome::Gone:
            goDown(outcome == WriteOutcome::Gone);
            return;
        case WriteOutcome::Failed:
            transmitQueue_.pop(scratch_);
            ++counters_.refused;
            break;
        }
    }
}

bool SocketCanBus::probe() {
    if (fd_ < 0 && !open())
        return false;
    ifreq request{};
    std::strncpy(request.ifr_name, config_.interface.c_str(), IFNAMSIZ - 1);
    if (::ioctl(fd_, SIOCGIFFLAGS, &request) < 0) {
        goDown(errno == ENODEV);
        return false;
    }
    if ((request.ifr_flags & IFF_UP) == 0) {
        if (state_ != hal::CanState::Down)
            goDown(false);
        return false;
    }
    if (state_ == hal::CanState::Down)
        setState(hal::CanState::ErrorActive, 0);
    return true;
}

hal::CanSendResult SocketCanBus::send(const hal::CanFrame& frame) {
    if (!hal::isValidCanFrame(frame) || (frame.fd && !config_.fd)) {
        ++counters_.refused;
        return hal::CanSendResult::Invalid;
    }
    drainSocket();
    if (state_ == hal::CanState::BusOff) {
        ++counters_.refused;
        return hal::CanSendResult::BusOff;
    }
    if (fd_ < 0 && !open()) {
        // Removed interface: it may come back under the same name (a USB adapter re-plugged).
        ++counters_.refused;
        return hal::CanSendResult::Down;
    }
    flushQueue();
    if (transmitQueue_.empty() && fd_ >= 0) {
        const WriteOutcome outcome = write(frame);
        switch (outcome) {
        case WriteOutcome::Written:
            ++counters_.sent;
            if (state_ == hal::CanState::Down)
                setState(hal::CanState::ErrorActive, 0);
            return hal::CanSendResult::Queued;
        case WriteOutcome::Busy:
            break;
        case WriteOutcome::Down:
        case WriteOutcome::Gone:
            goDown(outcome == WriteOutcome::Gone);
            ++counters_.refused;
            return hal::CanSendResult::Down;
        case WriteOutcome::Failed:
            ++counters_.refused;
            return hal::CanSendResult::Invalid;
        }
    }
    if (state_ == hal::CanState::Down) {
        ++counters_.refused;
        return hal::CanSendResult::Down;
    }
    const bool dropped = transmitQueue_.pushDropOldest(frame);
    if (dropped)
        ++counters_.droppedQueueFull;
    return dropped ? hal::CanSendResult::DroppedOldest : hal::CanSendResult::Queued;
}

void SocketCanBus::drainSocket() {
    if (fd_ < 0)
        return;
    canfd_frame raw{};
    for (;;) {
        const ssize_t got = ::read(fd_, &raw, sizeof raw);
        if (got < 0) {
            if (errno == ENETDOWN && state_ != hal::CanState::Down)
                goDown(false);
            else if (errno == ENODEV)
                goDown(true);
            return;
        }
        if (got != CAN_MTU && got != CANFD_MTU)
            continue;
        if ((raw.can_id & CAN_ERR_FLAG) != 0) {
            handleErrorFrame(raw.can_id, raw.data);
            continue;
        }
        hal::CanFrame frame;
        frame.extended = (raw.can_id & CAN_EFF_FLAG) != 0;
        frame.id = raw.can_id & (frame.extended ? CAN_EFF_MASK : CAN_SFF_MASK);
        frame.fd = got == CANFD_MTU;
        frame.bitRateSwitch = frame.fd && (raw.flags & CANFD_BRS) != 0;
        frame.length = raw.len <= 64 ? raw.len : 64;
        std::memcpy(frame.data.data(), raw.data, frame.length);
        receiveQueue_.pushDropOldest(frame);
        ++counters_.received;
    }
}

void SocketCanBus::handleErrorFrame(unsigned int canId, const unsigned char* data) {
    hal::CanState next = state_ == hal::CanState::Down ? hal::CanState::ErrorActive : state_;
    if ((canId & CAN_ERR_CRTL) != 0) {
        const unsigned char controller = data[1];
        if ((controller & (CAN_ERR_CRTL_RX_PASSIVE | CAN_ERR_CRTL_TX_PASSIVE)) != 0)
            next = hal::CanState::ErrorPassive;
        else if ((controller & (CAN_ERR_CRTL_RX_WARNING | CAN_ERR_CRTL_TX_WARNING)) != 0)
            next = hal::CanState::ErrorWarning;
        else if ((controller & CAN_ERR_CRTL_ACTIVE) != 0)
            next = hal::CanState::ErrorActive;
    }
    if ((canId & CAN_ERR_RESTARTED) != 0)
        next = hal::CanState::ErrorActive;
    if ((canId & CAN_ERR_BUSOFF) != 0) {
        next = hal::CanState::BusOff;
        // Nothing leaves a bus-off controller; what waits would be stale after the restart.
        dropQueued();
    }
    setState(next, canId & CAN_ERR_MASK);
}

void SocketCanBus::setState(hal::CanState state, std::uint32_t errorClass) {
    if (state == state_ && errorClass == 0)
        return;
    state_ = state;
    hal::CanErrorEvent event;
    event.time = clock_.now();
    event.state = state;
    event.errorClass = errorClass;
    errors_.pushDropOldest(event);
    ++counters_.errorEvents;
}

bool SocketCanBus::receive(hal::CanFrame& frame) {
    drainSocket();
    flushQueue();
    return receiveQueue_.pop(frame);
}

bool SocketCanBus::nextError(hal::CanErrorEvent& event) {
    drainSocket();
    return errors_.pop(event);
}

} // namespace edgetrack::linux_hal
