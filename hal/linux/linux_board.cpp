// Linux backend: the real board, every device on its kernel interface, behind one hal::Board.
#include "hal/linux/linux_board.hpp"

#include <cstring>
#include <sstream>

namespace edgetrack::linux_hal {

LinuxBoard::LinuxBoard(const LinuxBoardConfig& config)
    : config_(config)
    , cameras_(config.cameras)
    , ledRing_(GpioLineAddress{config.gpioChip, config.ledLine}, clock_)
    , button_(GpioLineAddress{config.gpioChip, config.buttonLine}, clock_, config.buttonActiveLow)
    , statusLed_(GpioLineAddress{config.gpioChip, config.statusLine}, clock_)
    , flash_(config.flashDevice, config.flashSize, config.flashEraseBlock)
    , rigFlash_(config.rigFlashDevice, config.rigFlashSize, config.flashEraseBlock)
    , socketCan_(config.canEnabled ? std::make_unique<SocketCanBus>(config.can, clock_) : nullptr)
    , board_{clock_,     cameras_,
             ledRing_,   button_,
             statusLed_, flash_,
             rigFlash_,  socketCan_ ? static_cast<hal::CanBus&>(*socketCan_) : disabledCan_,
             udp_} {
    if (!cameras_.isValid())
        error_ = cameras_.errorText();
    else if (!flash_.isValid())
        error_ = "model flash " + config.flashDevice.string() + ": " + flash_.error();
    else if (!rigFlash_.isValid())
        error_ = "rig flash " + config.rigFlashDevice.string() + ": " + rigFlash_.error();
    else if (!udp_.isValid())
        error_ = std::string("cannot open a UDP socket: ") + std::strerror(udp_.errnoAtOpen());
}

std::string LinuxBoard::flashWarnings() const {
    std::string text;
    for (const FileFlash* flash : {&flash_, &rigFlash_})
        if (!flash->warning().empty())
            text += (text.empty() ? "" : "; ") + flash->warning();
    return text;
}

bool LinuxBoard::devicesUp(std::string& why) {
    why.clear();
    const auto missing = [&](const std::string& what) { why += (why.empty() ? "" : "; ") + what; };
    if (!ledRing_.available())
        missing("LED line: " + ledRing_.errorText());
    if (!button_.available())
        missing("button line: " + button_.errorText());
    if (!statusLed_.available())
        missing("status LED line: " + statusLed_.errorText());
    if (socketCan_ && !socketCan_->probe())
        missing("CAN " + config_.can.interface + " is down" +
                (socketCan_->errorText().empty() ? "" : " (" + socketCan_->errorText() + ")"));
    return why.empty();
}

std::string LinuxBoard::report() const {
    std::ostringstream out;
    out << "cameras: " << cameras_.describe() << "\n";
    const LibcameraPairCounters camera = cameras_.libcameraCounters();
    out << "  frames converted from RGB " << camera.converted << ", failed requests "
        << camera.failedRequests << "\n";
    out << "LED ring " << config_.gpioChip << ":" << config_.ledLine << ": "
        << (ledRing_.available() ? "held" : ledRing_.errorText()) << ", strobe thread "
        << ledRing_.schedulingNote() << "\n";
    out << "button " << config_.gpioChip << ":" << config_.buttonLine << ": "
        << (button_.available() ? "held" : button_.errorText()) << "\n";
    out << "status LED " << config_.gpioChip << ":" << config_.statusLine << ": "
        << (statusLed_.available() ? "held" : statusLed_.errorText()) << "\n";
    if (const std::string warnings = flashWarnings(); !warnings.empty())
        out << "flash: " << warnings << "\n";
    if (socketCan_)
        out << "CAN " << config_.can.interface << (config_.can.fd ? " (FD)" : "") << ": "
            << hal::canStateName(socketCan_->state()) << ", " << socketCan_->queued()
            << " queued\n";
    else
        out << "CAN: off\n";
    return out.str();
}

} // namespace edgetrack::linux_hal
