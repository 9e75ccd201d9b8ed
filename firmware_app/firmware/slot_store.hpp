// A payload on flash in two slots with sequence numbers and CRCs, so no power cut loses it.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "hal/flash.hpp"

namespace edgetrack::app {

/// \brief What one slot of a store holds.
enum class SlotState : std::uint8_t {
    Empty,   ///< erased: never written, or wiped
    Corrupt, ///< written, but a header or payload check fails (a save cut short, or decay)
    Valid,   ///< a whole payload
};

/// \brief One slot as load() found it.
struct SlotReport {
    SlotState state = SlotState::Empty;
    /// Save counter of a valid slot; the newer slot has the larger (serial-number order).
    std::uint32_t sequence = 0;
    /// For a corrupt slot, what failed.
    std::string why;
};

/// \brief The payload load() returns, and where it came from.
struct StoredPayload {
    std::vector<std::uint8_t> bytes;
    std::uint32_t sequence = 0;
    int slot = 0;
    /// The other slot when it is corrupt (a torn or damaged save, perhaps a newer one than this):
    /// "slot B corrupt (payload CRC mismatch)"; empty when it is valid or empty.
    std::string otherSlotProblem;
};

/**
 * \brief A payload in a flash partition, kept in two slots (A/B).
 *
 * A save erases the slot that does not hold the newest valid payload, writes the payload, and
 * writes the slot's header last: the header carries a magic number naming what the store holds,
 * the format version, the sequence number, the payload's length and CRC-32, and its own CRC-32.
 * Power lost at any erase or write leaves the other slot untouched and this one without a valid
 * header, so a load finds the old payload or the new one, never neither.
 *
 * Each slot is half the partition, rounded down to whole erase blocks; a slot starts with a
 * 32-byte header. Load and save allocate (they run at start-up and after a calibration, never
 * in the frame loop).
 */
class SlotStore {
public:
    /// \param what names the contents in errors ("model", "rig"); \a magic tells its slots apart
    /// from other stores'.
    SlotStore(hal::Flash& flash, std::uint32_t magic, std::uint16_t version, std::string what);

    /// \return false when the partition cannot hold two slots of one erase block each.
    bool isValid() const { return slotSize_ > kHeaderSize; }

    /// \return the payload bytes one slot can hold.
    std::size_t capacityBytes() const { return isValid() ? slotSize_ - kHeaderSize : 0; }

    /**
     * \brief The newest valid payload that \a check accepts (nothing: accepted; otherwise why
     * not: the slot then counts as corrupt); an error naming each slot's state when there is none.
     */
    Result<StoredPayload>
    load(const std::function<std::optional<std::string>(std::span<const std::uint8_t>)>& check);

    /// \brief Save \a payload as the newest; the previous one stays loadable until this returns
    /// Ok. Fails (leaving the old payload) when it does not fit a slot or the flash fails.
    Status save(std::span<const std::uint8_t> payload);

    /// \brief Both slots' states, as load() sees them before checking the payloads.
    std::array<SlotReport, 2> inspect();

    static constexpr std::size_t kHeaderSize = 32;

private:
    struct SlotContent {
        SlotReport report;
        std::vector<std::uint8_t> payload;
    };
    SlotContent readSlot(int slot);
    std::size_t slotOffset(int slot) const { return static_cast<std::size_t>(slot) * slotSize_; }

    hal::Flash& flash_;
    std::uint32_t magic_;
    std::uint16_t version_;
    std::string what_;
    std::size_t slotSize_ = 0;
};

/// \brief Little-endian writer of the stores' payloads.
class ByteWriter {
public:
    explicit ByteWriter(std::vector<std::uint8_t>& out)
        : out_(out) {}
    void u16(std::uint16_t v) { bytes(v, 2); }
    void u32(std::uint32_t v) { bytes(v, 4); }
    void f64(double v);
    void text(const std::string& s);

private:
    void bytes(std::uint64_t v, int count);
    std::vector<std::uint8_t>& out_;
};

/// \brief Little-endian reader that refuses, rather than overruns, a short payload.
class ByteReader {
public:
    explicit ByteReader(std::span<const std::uint8_t> in)
        : in_(in) {}
    bool u16(std::uint16_t& v) { return number(v, 2); }
    bool u32(std::uint32_t& v) { return number(v, 4); }
    bool f64(double& v);
    bool text(std::string& s);
    std::size_t left() const { return in_.size() - at_; }

private:
    template <typename T>
    bool number(T& v, int count) {
        if (left() < static_cast<std::size_t>(count))
            return false;
        std::uint64_t value = 0;
        for (int i = 0; i < count; ++i)
            value |= std::uint64_t{in_[at_ + static_cast<std::size_t>(i)]} << (8 * i);
        at_ += static_cast<std::size_t>(count);
        v = static_cast<T>(value);
        return true;
    }
    std::span<const std::uint8_t> in_;
    std::size_t at_ = 0;
};

} // namespace edgetrack::app
