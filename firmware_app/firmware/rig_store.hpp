// The board's own stereo rig on flash, in two slots like the models, so no power cut loses it.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/result.hpp"
#include "core/stereo_rig.hpp"
#include "firmware_app/firmware/slot_store.hpp"
#include "hal/flash.hpp"

namespace edgetrack::app {

/// \brief A rig the board measured, and how well it fit its wand session.
struct StoredRig {
    StereoRig rig;
    /// Mean of both cameras' reprojection RMS in the calibration that produced it (px).
    double reprojectionRms_px = 0.0;
    std::uint32_t sequence = 0;
    int slot = 0;
};

/**
 * \brief The rig in its own flash partition, kept in two slots (A/B) by a SlotStore: a power cut
 * at any erase or write of a save leaves the old rig or the new one, never neither.
 */
class RigStore {
public:
    explicit RigStore(hal::Flash& flash);

    bool isValid() const { return slots_.isValid(); }
    /// \brief The newest valid rig; an error naming each slot's state when there is none.
    Result<StoredRig> load();
    /// \brief Save \a rig as the newest, with the reprojection RMS (px) it was measured with.
    Status save(const StereoRig& rig, double reprojectionRms_px);
    std::array<SlotReport, 2> inspect() { return slots_.inspect(); }

private:
    SlotStore slots_;
};

/// \brief The payload: both cameras' size, intrinsics, distortion, pose, then the RMS.
std::vector<std::uint8_t> encodeRig(const StereoRig& rig, double reprojectionRms_px);
/// \brief Decode a payload; refuses a short or long one, non-finite numbers and invalid cameras.
Result<StoredRig> decodeRig(std::span<const std::uint8_t> payload);

} // namespace edgetrack::app
