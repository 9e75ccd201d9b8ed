// Linux backend: a flash partition kept in a file (or an MTD block device's image), made durable.
#pragma once

#include <filesystem>
#include <string>

#include "hal/flash.hpp"

namespace edgetrack::linux_hal {

/**
 * \brief hal::Flash on a file, with the NOR semantics of the interface.
 *
 * Erase writes 0xFF; write ANDs the data into what is there (as NOR programming clears bits); each
 * erase and write is followed by fdatasync, so the order the model store relies on (payload before
 * header) holds across a power cut. A missing file is created erased at the given size. An
 * existing one of another size (a truncated copy, a file of another partition) is not refused:
 * what it holds is read (past its end reads as erased), nothing is ever written to it, and
 * warning() says so; the board comes up on the slots it can read instead of stopping, and a
 * restart loop under systemd, never tracking, is avoided.
 */
class FileFlash : public hal::Flash {
public:
    FileFlash(const std::filesystem::path& path, std::size_t size, std::size_t eraseBlockSize);
    ~FileFlash() override;
    FileFlash(const FileFlash&) = delete;
    FileFlash& operator=(const FileFlash&) = delete;

    /// \return false when the file could not be opened or created (see error()).
    bool isValid() const { return fd_ >= 0; }
    const std::string& error() const { return error_; }
    /// \return why the partition is read only (a file of another size), or empty.
    const std::string& warning() const { return warning_; }

    std::size_t size() const override { return size_; }
    std::size_t eraseBlockSize() const override { return eraseBlockSize_; }
    Status read(std::size_t offset, std::span<std::uint8_t> out) override;
    Status erase(std::size_t offset, std::size_t length) override;
    Status write(std::size_t offset, std::span<const std::uint8_t> data) override;

private:
    Status checkRange(const char* what, std::size_t offset, std::size_t length) const;
    Status writeBytes(std::size_t offset, std::span<const std::uint8_t> data);

    std::string path_;
    std::size_t size_;
    std::size_t eraseBlockSize_;
    int fd_ = -1;
    /// Bytes the file holds: size_, or fewer for a degraded (read-only) partition.
    std::size_t fileSize_ = 0;
    std::string error_;
    std::string warning_;
};

} // namespace edgetrack::linux_hal
