// HAL interface: a flash partition with NOR semantics (erase to 0xFF, writes clear bits).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>

#include "core/result.hpp"

namespace edgetrack::hal {

/**
 * \brief A raw flash partition.
 *
 * Erase sets whole blocks to 0xFF; write can only clear bits (new = old & data), so a region must
 * be erased before it is written. Any operation may fail, e.g. when power is lost part-way; the
 * store built on top must survive that (old or new contents, never neither).
 */
class Flash {
public:
    virtual ~Flash() = default;

    virtual std::size_t size() const = 0;
    virtual std::size_t eraseBlockSize() const = 0;

    virtual Status read(std::size_t offset, std::span<std::uint8_t> out) = 0;
    /// \brief Erase [offset, offset + length); both must be multiples of eraseBlockSize().
    virtual Status erase(std::size_t offset, std::size_t length) = 0;
    virtual Status write(std::size_t offset, std::span<const std::uint8_t> data) = 0;
};

} // namespace edgetrack::hal
