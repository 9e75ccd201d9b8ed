// Result<T>: a value or a one-line error message, so that no exception crosses a module boundary.
#pragma once

#include <string>
#include <string_view>
#include <utility>
#include <variant>

namespace edgetrack {

/**
 * \brief \a text fit for one line of a terminal: control bytes (a newline among them) and bytes
 * that are not UTF-8 become \xNN, so that a message quoting a binary file's bytes neither breaks
 * the line nor sends escape sequences to the terminal.
 */
inline std::string printableLine(std::string_view text) {
    std::string out;
    out.reserve(text.size());
    const auto escape = [&out](unsigned char byte) {
        constexpr char kHex[] = "0123456789abcdef";
        out += "\\x";
        out += kHex[byte >> 4];
        out += kHex[byte & 0xF];
    };
    for (std::size_t i = 0; i < text.size();) {
        const auto byte = static_cast<unsigned char>(text[i]);
        if (byte < 0x80) {
            if (byte < 0x20 || byte == 0x7F)
                escape(byte);
            else
                out += static_cast<char>(byte);
            ++i;
            continue;
        }
        // A whole UTF-8 sequence (a path with accents) passes; a stray byte is escaped.
        const std::size_t length = byte >= 0xF0 && byte < 0xF5   ? 4
                                   : byte >= 0xE0                ? 3
                                   : byte >= 0xC2 && byte < 0xE0 ? 2
                                                                 : 0;
        bool whole = length > 0 && i + length <= text.size();
        for (std::size_t k = 1; whole && k < length; ++k)
            whole = (static_cast<unsigned char>(text[i + k]) & 0xC0) == 0x80;
        if (!whole) {
            escape(byte);
            ++i;
            continue;
        }
        out.append(text.substr(i, length));
        i += length;
    }
    return out;
}

/// \brief A failure described by one line of text, e.g. "rec/blobs.csv:12: camera must be 0 or 1".
/// The text is made printableLine() on the way in.
struct Error {
    Error() = default;
    Error(std::string_view text)
        : message(printableLine(text)) {}
    std::string message;
};

/**
 * \brief Either a value of type T or an Error.
 *
 * A small stand-in for C++23 std::expected. Test with isValid() (or operator bool) before value().
 */
template <typename T>
class Result {
public:
    Result(T value)
        : storage_(std::move(value)) {}
    Result(Error error)
        : storage_(std::move(error)) {}

    /// \return true when the result holds a value.
    bool isValid() const { return std::holds_alternative<T>(storage_); }
    explicit operator bool() const { return isValid(); }

    T& value() & { return std::get<T>(storage_); }
    const T& value() const& { return std::get<T>(storage_); }
    T&& value() && { return std::get<T>(std::move(storage_)); }
    T* operator->() { return &value(); }
    const T* operator->() const { return &value(); }
    T& operator*() & { return value(); }
    const T& operator*() const& { return value(); }

    /// \return the error; only meaningful when isValid() is false.
    const Error& error() const { return std::get<Error>(storage_); }

private:
    std::variant<T, Error> storage_;
};

/// \brief Result of an operation that yields nothing but can fail.
struct Ok {};
using Status = Result<Ok>;

} // namespace edgetrack
