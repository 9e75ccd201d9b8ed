// Linux backend: flash partition in a file with NOR erase/program semantics and fdatasync.
#include "hal/linux/file_flash.hpp"

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#include <vector>

namespace edgetrack::linux_hal {

namespace {
std::string systemError(const std::string& what) {
    return what + ": " + std::strerror(errno);
}
} // namespace

FileFlash::FileFlash(const std::filesystem::path& path, std::size_t size,
                     std::size_t eraseBlockSize)
    : path_(path.string())
    , size_(size)
    , eraseBlockSize_(eraseBlockSize) {
    if (eraseBlockSize == 0 || size % eraseBlockSize != 0) {
        error_ = path_ + ": size must be a whole number of erase blocks";
        return;
    }
    const int fd = ::open(path_.c_str(), O_RDWR | O_CREAT | O_CLOEXEC, 0600);
    if (fd < 0) {
        error_ = systemError(path_);
        return;
    }
    struct stat info {};
    if (::fstat(fd, &info) != 0) {
        error_ = systemError(path_);
        ::close(fd);
        return;
    }
    fd_ = fd;
    fileSize_ = size_;
    if (info.st_size == 0) {
        // A new partition starts erased.
        const std::vector<std::uint8_t> erased(size_, 0xFF);
        if (Status s = writeBytes(0, erased); !s) {
            error_ = s.error().message;
            ::close(fd_);
            fd_ = -1;
        }
    } else if (static_cast<std::size_t>(info.st_size) != size_) {
        fileSize_ = std::min(size_, static_cast<std::size_t>(info.st_size));
        warning_ = path_ + ": holds " + std::to_string(info.st_size) + " bytes, the partition is " +
                   std::to_string(size_) +
                   ": read as far as it goes and never written (saves fail) until it is fixed";
    }
}

FileFlash::~FileFlash() {
    if (fd_ >= 0)
        ::close(fd_);
}

Status FileFlash::checkRange(const char* what, std::size_t offset, std::size_t length) const {
    if (fd_ < 0)
        return Error{path_ + ": not open"};
    if (offset > size_ || length > size_ - offset)
        return Error{path_ + ": " + what + " past the end of the partition"};
    return Ok{};
}

Status FileFlash::writeBytes(std::size_t offset, std::span<const std::uint8_t> data) {
    std::size_t done = 0;
    while (done < data.size()) {
        const ssize_t n = ::pwrite(fd_, data.data() + done, data.size() - done,
                                   static_cast<off_t>(offset + done));
        if (n < 0) {
            if (errno == EINTR)
                continue;
            return Error{systemError(path_ + ": write")};
        }
        done += static_cast<std::size_t>(n);
    }
    if (::fdatasync(fd_) != 0)
        return Error{systemError(path_ + ": fdatasync")};
    return Ok{};
}

Status FileFlash::read(std::size_t offset, std::span<std::uint8_t> out) {
    if (Status s = checkRange("read", offset, out.size()); !s)
        return s;
    // Past the end of a short file reads as erased.
    const std::size_t inFile = offset >= fileSize_ ? 0 : std::min(out.size(), fileSize_ - offset);
    std::fill(out.begin() + static_cast<std::ptrdiff_t>(inFile), out.end(), std::uint8_t{0xFF});
    std::size_t done = 0;
    while (done < inFile) {
        const ssize_t n =
            ::pread(fd_, out.data() + done, inFile - done, static_cast<off_t>(offset + done));
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0)
            return Error{systemError(path_ + ": read")};
        done += static_cast<std::size_t>(n);
    }
    return Ok{};
}

Status FileFlash::erase(std::size_t offset, std::size_t length) {
    if (Status s = checkRange("erase", offset, length); !s)
        return s;
    if (!warning_.empty())
        return Error{warning_};
    if (offset % eraseBlockSize_ != 0 || length % eraseBlockSize_ != 0)
        return Error{path_ + ": erase must cover whole blocks"};
    const std::vector<std::uint8_t> erased(length, 0xFF);
    return writeBytes(offset, erased);
}

Status FileFlash::write(std::size_t offset, std::span<const std::uint8_t> data) {
    if (Status s = checkRange("write", offset, data.size()); !s)
        return s;
    if (!warning_.empty())
        return Error{warning_};
    // NOR programming only clears bits: what lands is old & new.
    std::vector<std::uint8_t> merged(data.size());
    if (Status s = read(offset, merged); !s)
        return s;
    for (std::size_t i = 0; i < data.size(); ++i)
        merged[i] &= data[i];
    return writeBytes(offset, merged);
}

} // namespace edgetrack::linux_hal
