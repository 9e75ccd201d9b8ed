// Result<T>: a value or a one-line error message, so that no exception crosses a module boundary.
#pragma once

#include <string>
#include <utility>
#include <variant>

namespace edgetrack {

/// \brief A failure described by one line of text, e.g. "rec/blobs.csv:12: camera must be 0 or 1".
struct Error {
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
