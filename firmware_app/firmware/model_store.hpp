// Models on the board's flash: two slots with sequence numbers and CRCs, so no power cut loses
// them.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "core/result.hpp"
#include "firmware_app/formats/named_model.hpp"
#include "hal/flash.hpp"

namespace edgetrack::app {

/// \brief What one slot of the store holds.
enum class SlotState : std::uint8_t {
    Empty,   ///< erased: never written, or wiped
    Corrupt, ///< written, but a header or payload check fails (a save cut short, or decay)
    Valid,   ///< a whole model set
};

/// \brief One slot as load() found it.
struct SlotReport {
    SlotState state = SlotState::Empty;
    /// Save counter of a valid slot; the newer slot has the larger (serial-number order).
    std::uint32_t sequence = 0;
    /// For a corrupt slot, what failed.
    std::string why;
};

/// \brief The model set load() returns, and where it came from.
struct StoredModels {
    std::vector<NamedModel> models;
    std::uint32_t sequence = 0;
    int slot = 0;
};

/**
 * \brief The model set in a flash partition, kept in two slots (A/B).
 *
 * A save erases the slot that does not hold the newest valid set, writes the payload, and writes
 * the slot's header last: the header carries the sequence number, the payload's length and CRC-32,
 * and its own CRC-32. Power lost at any erase or write leaves the other slot untouched and this
 * one without a valid header, so a load finds the old set or the new one, never neither.
 *
 * Slot layout: a 32-byte header, then the payload (encodeModels()); each slot is half the
 * partition, rounded down to whole erase blocks. Load and save allocate (they run at start-up and
 * after a calibration, never in the frame loop).
 */
class ModelStore {
public:
    /// \param maxMarkers markers per model that load() accepts (the tracker's capacity).
    ModelStore(hal::Flash& flash, std::size_t maxMarkers);

    /// \return false when the partition cannot hold two slots of one erase block each.
    bool isValid() const { return slotSize_ > kHeaderSize; }

    /// \return the payload bytes one slot can hold.
    std::size_t capacityBytes() const { return isValid() ? slotSize_ - kHeaderSize : 0; }

    /// \brief The newest valid model set; an error naming each slot's state when there is none.
    Result<StoredModels> load();

    /// \brief Save \a models as the newest set; the previous set stays loadable until this
    /// returns Ok. Fails (leaving the old set) when the set does not fit a slot or flash fails.
    Status save(std::span<const NamedModel> models);

    /// \brief Both slots' states, as load() sees them.
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
    std::size_t maxMarkers_;
    std::size_t slotSize_ = 0;
};

/// \brief The store's payload: the models, little-endian, marker coordinates as IEEE doubles.
std::vector<std::uint8_t> encodeModels(std::span<const NamedModel> models);

/**
 * \brief Decode a payload, checking every count against the bytes left, marker indices, finite
 * coordinates, S_min, unique ids and \a maxMarkers; never reads past \a payload.
 */
Result<std::vector<NamedModel>> decodeModels(std::span<const std::uint8_t> payload,
                                             std::size_t maxMarkers);

} // namespace edgetrack::app
