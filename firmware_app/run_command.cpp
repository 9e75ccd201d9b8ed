// `edgetrack run`: picks the board backend, wires it to the firmware and runs the loop.
#include "firmware_app/run_command.hpp"

#include <atomic>
#include <csignal>
#include <cstring>
#include <memory>
#include <poll.h>
#include <string_view>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "firmware_app/firmware.hpp"
#include "firmware_app/model_file.hpp"
#include "hal/linux/posix_udp_sender.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/sim_board.hpp"

namespace edgetrack::app {

namespace {

std::atomic<bool> stopRequested{false};
std::atomic<bool> reportRequested{false};

extern "C" void onStopSignal(int) {
    stopRequested = true;
}
extern "C" void onReportSignal(int) {
    reportRequested = true;
}

/// Button presses typed on standard input, for the simulated board's push button.
class StdinButton {
public:
    explicit StdinButton(bool enabled)
        : enabled_(enabled) {}

    enum class Press { None, Short, Long, Status };

    Press poll() {
        if (!enabled_)
            return Press::None;
        pollfd fd{STDIN_FILENO, POLLIN, 0};
        if (::poll(&fd, 1, 0) <= 0 || (fd.revents & (POLLIN | POLLHUP)) == 0)
            return Press::None;
        char buffer[64];
        const ssize_t n = ::read(STDIN_FILENO, buffer, sizeof buffer);
        if (n <= 0) {
            enabled_ = false; // end of input: no more presses
            return Press::None;
        }
        const std::string_view line(buffer, static_cast<std::size_t>(n));
        if (line.starts_with("l"))
            return Press::Long;
        if (line.starts_with("s"))
            return Press::Status;
        return Press::Short;
    }

private:
    bool enabled_;
};

} // namespace

int runFirmwareCommand(const RunCommandOptions& options, std::ostream& out, std::ostream& err) {
    FirmwareConfig config;
    if (!options.config.empty()) {
        Result<FirmwareConfig> loaded = loadFirmwareConfig(options.config);
        if (!loaded) {
            err << "edgetrack run: " << loaded.error().message << "\n";
            return 1;
        }
        config = std::move(*loaded);
    }
    if (!options.udp.empty()) {
        Result<hal::UdpEndpoint> endpoint = parseEndpoint(options.udp);
        if (!endpoint) {
            err << "edgetrack run: --udp " << endpoint.error().message << "\n";
            return 2;
        }
        config.udp.enabled = true;
        config.udp.destinations = {*endpoint};
    }
    if (!options.can.empty()) {
        config.can.enabled = true;
        config.can.interface = options.can;
    }
    if (options.board != "sim") {
        err << "edgetrack run: --board " << options.board
            << ": the Linux backends (libcamera, libgpiod, SocketCAN) are not built yet (issue 8)"
            << "\n";
        return 2;
    }
    const std::string sceneName = options.scene.empty() ? "two_cubes" : options.scene;
    std::optional<sim::Scene> scene = sim::makeScene(sceneName, options.seed);
    if (!scene) {
        err << "edgetrack run: unknown scene '" << sceneName << "' (edgetrack sim --list)\n";
        return 2;
    }

    sim::SimBoardOptions boardOptions;
    boardOptions.realTime = true;
    boardOptions.cameraBufferPairs = config.cameras.buffers;
    boardOptions.flashSize = config.flash.size_bytes;
    boardOptions.flashEraseBlock = config.flash.eraseBlock_bytes;
    auto sim = std::make_unique<sim::SimBoard>(std::move(*scene), options.seed, boardOptions);
    // The simulated board's UDP is the host's: a DTrack client on this machine sees the poses.
    linux_hal::PosixUdpSender udp;
    if (!udp.isValid()) {
        err << "edgetrack run: cannot open a UDP socket: " << std::strerror(udp.errnoAtOpen())
            << "\n";
        return 1;
    }
    hal::Board board{sim->clock,     sim->cameras, sim->ledRing, sim->button,
                     sim->statusLed, sim->flash,   sim->can,     udp};

    Firmware firmware(config, board, sim->world.rig());
    if (!firmware.isValid()) {
        err << "edgetrack run: " << firmware.error() << "\n";
        return 1;
    }
    firmware.start();
    out << "edgetrack run: simulated board, scene '" << sceneName << "'; " << firmware.flashReport()
        << "\n";
    if (!options.models.empty()) {
        Result<std::vector<NamedModel>> models =
            readModelDirectory(options.models, MarkerSet::kCapacity);
        if (!models) {
            err << "edgetrack run: " << models.error().message << "\n";
            return 1;
        }
        if (Status s = firmware.replaceModels(std::move(*models)); !s) {
            err << "edgetrack run: " << s.error().message << "\n";
            return 1;
        }
        out << "edgetrack run: tracking " << firmware.models().size() << " models from "
            << options.models.string() << "\n";
    }
    if (config.udp.enabled)
        for (const hal::UdpEndpoint& to : config.udp.destinations)
            out << "edgetrack run: DTrack UDP to " << int{to.address[0]} << "."
                << int{to.address[1]} << "." << int{to.address[2]} << "." << int{to.address[3]}
                << ":" << to.port << "\n";
    const bool interactive = options.buttonFromStdin && ::isatty(STDIN_FILENO) != 0;
    if (interactive)
        out << "edgetrack run: press Enter to start or end a calibration (the button), type "
               "'long' to delete all models, 's' for the status view, Ctrl-C to stop\n";
    out << std::flush;

    stopRequested = false;
    std::signal(SIGINT, onStopSignal);
    std::signal(SIGTERM, onStopSignal);
    std::signal(SIGUSR1, onReportSignal);

    StdinButton stdinButton(options.buttonFromStdin);
    std::uint64_t watchdogInterval_us = 0;
    const bool watchdog = sd_watchdog_enabled(0, &watchdogInterval_us) > 0;
    const hal::Nanoseconds statusPeriod =
        static_cast<hal::Nanoseconds>(config.health.statusInterval_s * 1e9);
    hal::Nanoseconds nextStatus = board.clock.now() + statusPeriod;
    hal::Nanoseconds nextWatchdog = board.clock.now();
    bool notifiedReady = false;
    const bool terminal = ::isatty(STDERR_FILENO) != 0;
    while (!stopRequested) {
        switch (stdinButton.poll()) {
        case StdinButton::Press::Short:
            sim->button.press(board.clock.now(), 200 * hal::kNanosecondsPerMillisecond);
            break;
        case StdinButton::Press::Long:
            sim->button.press(board.clock.now(),
                              static_cast<hal::Nanoseconds>((config.gpio.longPress_s + 0.3) * 1e9));
            break;
        case StdinButton::Press::Status:
            reportRequested = true;
            break;
        case StdinButton::Press::None:
            break;
        }
        firmware.step();
        const hal::Nanoseconds now = board.clock.now();
        if (!notifiedReady && firmware.ready()) {
            sd_notify(0, "READY=1");
            notifiedReady = true;
        }
        if (watchdog && now >= nextWatchdog) {
            sd_notify(0, "WATCHDOG=1");
            nextWatchdog = now + static_cast<hal::Nanoseconds>(watchdogInterval_us) * 500;
        }
        if (statusPeriod > 0 && now >= nextStatus) {
            const std::string line = firmware.statusLine();
            err << (terminal ? "\r" : "") << line << (terminal ? "   " : "\n") << std::flush;
            sd_notify(0, ("STATUS=" + line).c_str());
            nextStatus = now + statusPeriod;
        }
        if (reportRequested.exchange(false))
            err << "\n" << firmware.statusReport() << std::flush;
        if (options.frames > 0 &&
            firmware.counters().framesProcessed >= static_cast<std::uint64_t>(options.frames))
            break;
    }
    sd_notify(0, "STOPPING=1");
    firmware.stop();
    std::signal(SIGINT, SIG_DFL);
    std::signal(SIGTERM, SIG_DFL);
    std::signal(SIGUSR1, SIG_DFL);
    if (terminal && statusPeriod > 0)
        err << "\n";
    out << firmware.statusReport();
    return 0;
}

} // namespace edgetrack::app
