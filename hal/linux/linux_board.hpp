// Linux backend: the real board, every device on its kernel interface, behind one hal::Board.
#pragma once

#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>

#include "hal/hal.hpp"
#include "hal/linux/file_flash.hpp"
#include "hal/linux/gpiod_devices.hpp"
#include "hal/linux/libcamera_camera_pair.hpp"
#include "hal/linux/posix_clock.hpp"
#include "hal/linux/posix_udp_sender.hpp"
#include "hal/linux/socketcan_bus.hpp"

namespace edgetrack::linux_hal {

/// \brief Where each device of the board is (filled from the firmware's configuration).
struct LinuxBoardConfig {
    LibcameraPairConfig cameras;
    std::string gpioChip = "gpiochip0";
    std::string ledLine = "IR_LED";
    std::string buttonLine = "BUTTON";
    std::string statusLine = "STATUS_LED";
    /// The button pulls its line low when pressed (pull-up bias requested).
    bool buttonActiveLow = true;
    std::filesystem::path flashDevice;
    std::size_t flashSize = 1u << 20;
    std::size_t flashEraseBlock = 4096;
    /// The rig's partition (same erase block).
    std::filesystem::path rigFlashDevice;
    std::size_t rigFlashSize = 64u << 10;
    /// Without CAN the board's bus accepts nothing and reports nothing.
    bool canEnabled = false;
    SocketCanConfig can;
};

/**
 * \brief The board on libcamera, libgpiod, SocketCAN and POSIX (ArduPilot's HAL_Linux).
 *
 * Construction opens every device. Only what cannot come back makes the board invalid: libcamera
 * not starting, the flash file or the UDP socket not opening. Cameras, GPIO lines and the CAN
 * interface may be missing or busy at start; they are retried (cameras by the firmware's
 * degraded state, GPIO lines once a second by their devices, CAN at every send or probe) and
 * devicesUp() says when they all are there.
 */
class LinuxBoard {
public:
    explicit LinuxBoard(const LinuxBoardConfig& config);

    bool isValid() const { return error_.empty(); }
    const std::string& errorText() const { return error_; }

    hal::Board& board() { return board_; }
    LibcameraCameraPair& cameras() { return cameras_; }
    const LibcameraCameraPair& cameras() const { return cameras_; }

    /**
     * \brief Whether the GPIO lines and the CAN interface (when enabled) are usable now.
     * \param why set to what is missing, one clause per device, when false.
     */
    bool devicesUp(std::string& why);

    /// \brief One line per device: what it is and how it is doing, for the status view.
    std::string report() const;
    /// \return why a flash partition is read only (FileFlash::warning()), both joined; empty when
    /// neither is.
    std::string flashWarnings() const;

private:
    class DisabledCanBus : public hal::CanBus {
    public:
        hal::CanSendResult send(const hal::CanFrame&) override { return hal::CanSendResult::Down; }
        bool receive(hal::CanFrame&) override { return false; }
        bool nextError(hal::CanErrorEvent&) override { return false; }
        hal::CanState state() const override { return hal::CanState::Down; }
        hal::CanCounters counters() const override { return {}; }
    };

    LinuxBoardConfig config_;
    std::string error_;
    PosixClock clock_;
    LibcameraCameraPair cameras_;
    GpiodLedRing ledRing_;
    GpiodButton button_;
    GpiodStatusLed statusLed_;
    FileFlash flash_;
    FileFlash rigFlash_;
    std::unique_ptr<SocketCanBus> socketCan_;
    DisabledCanBus disabledCan_;
    PosixUdpSender udp_;
    hal::Board board_;
};

} // namespace edgetrack::linux_hal
