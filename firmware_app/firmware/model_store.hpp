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
#include "firmware_app/firmware/slot_store.hpp"
#include "firmware_app/formats/named_model.hpp"
#include "hal/flash.hpp"

namespace edgetrack::app {

/// \brief The model set load() returns, and where it came from.
struct StoredModels {
    std::vector<NamedModel> models;
    std::uint32_t sequence = 0;
    int slot = 0;
    /// StoredPayload::otherSlotProblem.
    std::string otherSlotProblem;
};

/**
 * \brief The model set in a flash partition, kept in two slots (A/B) by a SlotStore: a power cut
 * at any erase or write leaves the old set or the new one, never neither.
 */
class ModelStore {
public:
    /// \param maxMarkers markers per model that load() accepts (the tracker's capacity).
    ModelStore(hal::Flash& flash, std::size_t maxMarkers);

    /// \return false when the partition cannot hold two slots of one erase block each.
    bool isValid() const { return slots_.isValid(); }

    /// \return the payload bytes one slot can hold.
    std::size_t capacityBytes() const { return slots_.capacityBytes(); }

    /// \brief The newest valid model set; an error naming each slot's state when there is none.
    Result<StoredModels> load();

    /// \brief Save \a models as the newest set; the previous set stays loadable until this
    /// returns Ok. Fails (leaving the old set) when the set does not fit a slot or flash fails.
    Status save(std::span<const NamedModel> models);

    /// \brief Both slots' states, as load() sees them.
    std::array<SlotReport, 2> inspect() { return slots_.inspect(); }

    static constexpr std::size_t kHeaderSize = SlotStore::kHeaderSize;

private:
    SlotStore slots_;
    std::size_t maxMarkers_;
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
