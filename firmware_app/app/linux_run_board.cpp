// `edgetrack run --board linux`: the real board on libcamera, libgpiod, SocketCAN and POSIX.
#include "firmware_app/app/run_board.hpp"
#include "firmware_app/formats/recording.hpp"
#include "hal/linux/linux_board.hpp"

namespace edgetrack::app {

namespace {

/// The stereo calibration of the real cameras, which must be for the configured image size.
Result<StereoRig> loadBoardRig(const FirmwareConfig& config) {
    if (config.cameras.rigFile.empty())
        return Error{"--board linux needs the stereo calibration: set [cameras] rig (INTERFACES "
                     "§2)"};
    Result<StereoRig> rig = recording::readRig(config.cameras.rigFile);
    if (!rig)
        return rig;
    for (int c = 0; c < 2; ++c) {
        const CameraIntrinsics& intrinsics = rig->camera(c).intrinsics();
        if (intrinsics.width_px != config.cameras.width_px ||
            intrinsics.height_px != config.cameras.height_px)
            return Error{config.cameras.rigFile.string() + ": camera " + std::to_string(c) +
                         " is calibrated at " + std::to_string(intrinsics.width_px) + "x" +
                         std::to_string(intrinsics.height_px) + ", [cameras] asks for " +
                         std::to_string(config.cameras.width_px) + "x" +
                         std::to_string(config.cameras.height_px)};
    }
    return rig;
}

linux_hal::LinuxBoardConfig linuxBoardConfig(const FirmwareConfig& config) {
    linux_hal::LinuxBoardConfig board;
    board.cameras.ids = {config.cameras.ids[0], config.cameras.ids[1]};
    board.cameras.width_px = config.cameras.width_px;
    board.cameras.height_px = config.cameras.height_px;
    board.cameras.frameRate_hz = config.cameras.frameRate_hz;
    board.cameras.exposure_us = config.cameras.exposure_us;
    board.cameras.pairTolerance_us = config.cameras.pairTolerance_us;
    board.cameras.buffers = config.cameras.buffers;
    board.gpioChip = config.gpio.chip;
    board.ledLine = config.gpio.ledLine;
    board.buttonLine = config.gpio.buttonLine;
    board.statusLine = config.gpio.statusLine;
    board.buttonActiveLow = config.gpio.buttonActiveLow;
    board.flashDevice = config.flash.device;
    board.flashSize = config.flash.size_bytes;
    board.flashEraseBlock = config.flash.eraseBlock_bytes;
    board.rigFlashDevice = config.flash.rigDevice;
    board.rigFlashSize = config.flash.rigSize_bytes;
    board.canEnabled = config.can.enabled;
    board.can.interface = config.can.interface;
    board.can.fd = config.can.fd;
    return board;
}

class LinuxRunBoard : public RunBoard {
public:
    LinuxRunBoard(const FirmwareConfig& config, StereoRig rig)
        : linux_(linuxBoardConfig(config))
        , rig_(std::move(rig)) {}

    bool isValid() const { return linux_.isValid(); }
    const std::string& errorText() const { return linux_.errorText(); }

    hal::Board& board() override { return linux_.board(); }
    const StereoRig& rig() const override { return rig_; }
    std::string describe() const override {
        std::string text = "Linux board; " + linux_.cameras().describe();
        if (!linux_.flashWarnings().empty())
            text += "; DEGRADED: " + linux_.flashWarnings();
        return text;
    }
    std::string devicesName() const override { return "cameras, GPIO"; }
    bool devicesUp(std::string& why) override { return linux_.devicesUp(why); }
    bool needsProcessRestart() const override { return linux_.cameras().needsProcessRestart(); }
    std::string report() const override { return linux_.report(); }

private:
    linux_hal::LinuxBoard linux_;
    StereoRig rig_;
};

} // namespace

Result<std::unique_ptr<RunBoard>> makeLinuxRunBoard(const FirmwareConfig& config) {
    Result<StereoRig> rig = loadBoardRig(config);
    if (!rig)
        return rig.error();
    auto board = std::make_unique<LinuxRunBoard>(config, *rig);
    if (!board->isValid())
        return Error{board->errorText()};
    return std::unique_ptr<RunBoard>(std::move(board));
}

} // namespace edgetrack::app
