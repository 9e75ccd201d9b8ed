// The board: one reference to each hardware interface (ArduPilot's AP_HAL::HAL).
#pragma once

#include "hal/button.hpp"
#include "hal/camera_pair.hpp"
#include "hal/can_bus.hpp"
#include "hal/clock.hpp"
#include "hal/flash.hpp"
#include "hal/led_ring.hpp"
#include "hal/status_led.hpp"
#include "hal/udp.hpp"

namespace edgetrack::hal {

/**
 * \brief Everything the firmware may touch of the hardware.
 *
 * A backend (hal/sim, hal/linux) owns the drivers and hands out this view; firmware_app is the only
 * code that picks the backend.
 */
struct Board {
    Clock& clock;
    CameraPair& cameras;
    LedRing& ledRing;
    Button& button;
    StatusLed& statusLed;
    /// The models' partition.
    Flash& flash;
    /// The rig's partition: the board's own stereo calibration (a rig calibration by wand).
    Flash& rigFlash;
    CanBus& can;
    UdpSender& udp;
};

} // namespace edgetrack::hal
