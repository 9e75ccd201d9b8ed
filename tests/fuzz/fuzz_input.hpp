// Helpers for fuzz targets: the input split into a selector byte, numbers and text.
#pragma once

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string_view>

namespace edgetrack::fuzz {

/// \brief Reads a fuzzer's input front to back; past its end every read gives zeros.
class FuzzInput {
public:
    FuzzInput(const std::uint8_t* data, std::size_t size)
        : data_(data)
        , size_(size) {}

    std::uint8_t byte() { return at_ < size_ ? data_[at_++] : 0; }

    template <typename T>
    T value() {
        T v{};
        const std::size_t n = sizeof(T) <= size_ - at_ ? sizeof(T) : size_ - at_;
        std::memcpy(&v, data_ + at_, n);
        at_ += n;
        return v;
    }

    /// \brief What is left, as text.
    std::string_view rest() const {
        return {reinterpret_cast<const char*>(data_ + at_), size_ - at_};
    }

private:
    const std::uint8_t* data_;
    std::size_t size_;
    std::size_t at_ = 0;
};

/// \brief Stops the fuzzer with a message: a property of the parser does not hold.
[[noreturn]] void fail(const char* what);

} // namespace edgetrack::fuzz
