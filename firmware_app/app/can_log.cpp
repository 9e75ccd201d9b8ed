// CAN frames as `candump -L` lines, and the bus decorator that logs what the firmware sends.
#include "firmware_app/app/can_log.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>

namespace edgetrack::app {

std::size_t formatCandumpLine(const hal::CanFrame& frame, std::int64_t utc_ns,
                              std::string_view interface, std::span<char> out) {
    const std::int64_t utc_us = utc_ns / 1000;
    const int head = std::snprintf(out.data(), out.size(), "(%lld.%06lld) %.*s %0*X#",
                                   static_cast<long long>(utc_us / 1'000'000),
                                   static_cast<long long>(utc_us % 1'000'000),
                                   static_cast<int>(interface.size()), interface.data(),
                                   frame.extended ? 8 : 3, static_cast<unsigned>(frame.id));
    if (head < 0 || static_cast<std::size_t>(head) >= out.size())
        return 0;
    std::size_t used = static_cast<std::size_t>(head);
    // Flags nibble, payload in hex and the newline: at most 1 + 128 + 1 characters.
    if (out.size() - used < 2u + 1u + 2u * frame.length + 1u)
        return 0;
    constexpr std::array<char, 16> kHex = {'0', '1', '2', '3', '4', '5', '6', '7',
                                           '8', '9', 'A', 'B', 'C', 'D', 'E', 'F'};
    if (frame.fd) {
        out[used++] = '#';
        out[used++] = kHex[frame.bitRateSwitch ? 1u : 0u];
    }
    const std::size_t length = std::min<std::size_t>(frame.length, frame.data.size());
    for (std::size_t i = 0; i < length; ++i) {
        out[used++] = kHex[frame.data[i] >> 4];
        out[used++] = kHex[frame.data[i] & 0x0F];
    }
    out[used++] = '\n';
    return used;
}

CanLogBus::CanLogBus(hal::CanBus& bus, const hal::Clock& clock, std::string interface,
                     const std::filesystem::path& file)
    : bus_(bus)
    , clock_(clock)
    , interface_(std::move(interface)) {
    file_ = std::fopen(file.c_str(), "w");
    if (file_ == nullptr) {
        error_ = file.string() + ": cannot open for writing: " + std::strerror(errno);
        return;
    }
    // Full buffering in storage of our own: the frame loop's writes never allocate.
    fileBuffer_.resize(1 << 16);
    std::setvbuf(file_, fileBuffer_.data(), _IOFBF, fileBuffer_.size());
}

CanLogBus::~CanLogBus() {
    if (file_ != nullptr)
        std::fclose(file_);
}

hal::CanSendResult CanLogBus::send(const hal::CanFrame& frame) {
    const hal::CanSendResult result = bus_.send(frame);
    if (file_ == nullptr ||
        (result != hal::CanSendResult::Queued && result != hal::CanSendResult::DroppedOldest))
        return result;
    std::array<char, 192> line{};
    const std::size_t length =
        formatCandumpLine(frame, clock_.now() + clock_.utcOffset(), interface_, line);
    if (length == 0) {
        ++lost_;
        return result;
    }
    // Flushed here, before stdio would on its own, so that each flush's fate is known.
    if (buffered_ + length > fileBuffer_.size())
        flush();
    if (std::fwrite(line.data(), 1, length, file_) != length) {
        ++writeFailures_;
        ++lost_;
        return result;
    }
    buffered_ += length;
    ++pending_;
    return result;
}

void CanLogBus::flush() {
    if (file_ == nullptr)
        return;
    if (std::fflush(file_) == 0) {
        logged_ += pending_;
    } else {
        ++writeFailures_;
        lost_ += pending_;
        std::clearerr(file_);
    }
    pending_ = 0;
    buffered_ = 0;
}

} // namespace edgetrack::app
