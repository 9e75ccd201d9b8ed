// Poses on CAN and CAN FD: the frame layout that deploy/edgetrack.dbc describes.
#pragma once

#include <array>
#include <cstdint>
#include <string>

#include "core/rigid_transform.hpp"
#include "hal/can_bus.hpp"

namespace edgetrack::app {

/**
 * \brief Where the pose frames sit on the bus.
 *
 * Classic CAN: three 8-byte frames per body at classicBaseId + 3 * body + {0, 1, 2}: position,
 * orientation, status; each starts with a 4-bit counter (the frame number modulo 16) so that a
 * receiver pairs the three. CAN FD: one 32-byte frame per body at fdBaseId + body. Standard 11-bit
 * identifiers. Bodies are numbered by model id; a body whose id is maxBodies or more is not sent.
 */
struct CanPoseLayout {
    std::uint32_t classicBaseId = 0x300;
    std::uint32_t fdBaseId = 0x380;
    std::uint32_t maxBodies = 16;

    bool operator==(const CanPoseLayout&) const = default;
};

/// \brief One body's pose in one frame, as it goes on the bus.
struct CanPose {
    std::uint32_t body = 0;
    bool found = false;
    std::uint64_t frame = 0;
    /// Model to rig (mm); ignored when not found.
    RigidTransform T_rig_from_model;
    std::uint32_t markers = 0;
    double rms_mm = 0.0;
    /// From mid-exposure to sending (s).
    double latency_s = 0.0;
};

/**
 * \brief The three classic frames of \a pose: position (0.01 mm, +-5.2 m), orientation (unit
 * quaternion, w >= 0, 15 bits a component), status (found, markers, frame number, latency in us).
 * Values beyond a signal's range are clamped, never wrapped.
 */
std::array<hal::CanFrame, 3> encodeClassicPose(const CanPose& pose, const CanPoseLayout& layout);

/// \brief The CAN FD frame of \a pose: position in um (32 bits), quaternion (16 bits a
/// component), frame number, markers, found, residual (um) and latency (us).
hal::CanFrame encodeFdPose(const CanPose& pose, const CanPoseLayout& layout);

/// \brief The DBC file that describes \a layout (deploy/edgetrack.dbc is this for the default).
std::string poseDbc(const CanPoseLayout& layout);

} // namespace edgetrack::app
