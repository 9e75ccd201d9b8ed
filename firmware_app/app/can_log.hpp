// A CAN bus that also writes every frame it sends to a file, in can-utils' `candump -L` format.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "hal/can_bus.hpp"
#include "hal/clock.hpp"

namespace edgetrack::app {

/**
 * \brief Write \a frame as one `candump -L` line into \a out: `(SECONDS.MICROSECONDS) IFACE
 * ID#DATA` with the wall time \a utc_ns (ns since 1970), 3 hex digits of identifier for a standard
 * frame and 8 for an extended one, and `ID##F DATA` for CAN FD, F being the flags nibble (1: bit
 * rate switch). `canplayer`, `log2asc` and DBC decoders read it.
 * \return the line's length with its '\n', or 0 when it does not fit \a out. Allocates nothing.
 */
std::size_t formatCandumpLine(const hal::CanFrame& frame, std::int64_t utc_ns,
                              std::string_view interface, std::span<char> out);

/**
 * \brief A CanBus that passes everything to another one and logs each frame that bus accepted
 * (queued, or queued after dropping the oldest), stamped with the board's wall time.
 *
 * The log is written through a buffer allocated at construction; a write that fails is counted
 * and the frame still goes to the bus.
 */
class CanLogBus : public hal::CanBus {
public:
    CanLogBus(hal::CanBus& bus, const hal::Clock& clock, std::string interface,
              const std::filesystem::path& file);
    ~CanLogBus() override;
    CanLogBus(const CanLogBus&) = delete;
    CanLogBus& operator=(const CanLogBus&) = delete;

    /// \return false when the file could not be opened; error() says why.
    bool isValid() const { return file_ != nullptr; }
    const std::string& error() const { return error_; }

    hal::CanSendResult send(const hal::CanFrame& frame) override;
    bool receive(hal::CanFrame& frame) override { return bus_.receive(frame); }
    bool nextError(hal::CanErrorEvent& event) override { return bus_.nextError(event); }
    hal::CanState state() const override { return bus_.state(); }
    hal::CanCounters counters() const override { return bus_.counters(); }

    /// \return frames known to be in the file: written out by a flush that succeeded.
    std::uint64_t framesLogged() const { return logged_; }
    /// \return frames lost: their flush failed (a full disk), or a line could not be formatted.
    std::uint64_t framesLost() const { return lost_; }
    std::uint64_t writeFailures() const { return writeFailures_; }
    /// \brief Push what is buffered to the file.
    void flush();

private:
    hal::CanBus& bus_;
    const hal::Clock& clock_;
    std::string interface_;
    std::string error_;
    std::FILE* file_ = nullptr;
    std::vector<char> fileBuffer_;
    std::uint64_t logged_ = 0;
    std::uint64_t lost_ = 0;
    std::uint64_t writeFailures_ = 0;
    /// Lines and bytes in the buffer since the last flush: a buffered write always succeeds, so a
    /// frame counts as logged only once a flush has put it in the file.
    std::uint64_t pending_ = 0;
    std::size_t buffered_ = 0;
};

} // namespace edgetrack::app
