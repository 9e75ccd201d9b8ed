// `edgetrack run`: picks the board backend, wires it to the firmware and runs the loop.
#include "firmware_app/app/run_command.hpp"

#include <atomic>
#include <csignal>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <optional>
#include <poll.h>
#include <string_view>
#include <systemd/sd-daemon.h>
#include <unistd.h>

#include "firmware_app/app/can_log.hpp"
#include "firmware_app/app/run_board.hpp"
#include "firmware_app/firmware/firmware.hpp"
#include "firmware_app/formats/model_file.hpp"

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

    enum class Press { None, Short, Double, Long, Status };

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
        if (line.starts_with("d"))
            return Press::Double;
        if (line.starts_with("s"))
            return Press::Status;
        return Press::Short;
    }

private:
    bool enabled_;
};

/// Exit code asking systemd (Restart=on-failure) for a new process: EX_TEMPFAIL.
constexpr int kExitRestart = 75;

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
    if (!options.canLog.empty())
        config.can.enabled = true;
    // The only place that picks a backend.
    const std::string scene = options.scene.empty() ? "two_cubes" : options.scene;
    if (options.board != "linux" && !isSimScene(scene)) {
        // A bad argument, like an unknown option.
        err << "edgetrack run: unknown scene '" << scene << "' (edgetrack sim --list)\n";
        return 2;
    }
    std::vector<SimFault> faults;
    for (const std::string& text : options.faults) {
        Result<SimFault> fault = parseSimFault(text);
        if (!fault) {
            err << "edgetrack run: " << fault.error().message << "\n";
            return 2;
        }
        faults.push_back(*fault);
    }
    if (!faults.empty() && options.board == "linux") {
        err << "edgetrack run: --fault is for the simulated board\n";
        return 2;
    }
    Result<std::unique_ptr<RunBoard>> made =
        options.board == "linux" ? makeLinuxRunBoard(config)
                                 : makeSimRunBoard(config, scene, options.seed, std::move(faults));
    if (!made) {
        err << "edgetrack run: " << made.error().message << "\n";
        return 1;
    }
    RunBoard& runBoard = **made;
    hal::Board& backendBoard = runBoard.board();
    // The CAN log sits between the firmware and the board's bus, so any board can log.
    std::unique_ptr<CanLogBus> canLog;
    std::optional<hal::Board> loggingBoard;
    if (!options.canLog.empty()) {
        canLog = std::make_unique<CanLogBus>(backendBoard.can, backendBoard.clock,
                                             config.can.interface, options.canLog);
        if (!canLog->isValid()) {
            err << "edgetrack run: --can-log " << canLog->error() << "\n";
            return 1;
        }
        loggingBoard.emplace(hal::Board{backendBoard.clock, backendBoard.cameras,
                                        backendBoard.ledRing, backendBoard.button,
                                        backendBoard.statusLed, backendBoard.flash,
                                        backendBoard.rigFlash, *canLog, backendBoard.udp});
    }
    hal::Board& board = loggingBoard ? *loggingBoard : backendBoard;

    Firmware firmware(config, board, runBoard.rig());
    if (!firmware.isValid()) {
        err << "edgetrack run: " << firmware.error() << "\n";
        return 1;
    }
    firmware.start();
    out << "edgetrack run: " << runBoard.describe() << "; " << firmware.flashReport() << "\n";
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
    // A board whose button is typed (the simulated one) takes presses from standard input.
    const bool typedButton = options.buttonFromStdin && runBoard.hasTypedButton();
    const bool interactive = typedButton && ::isatty(STDIN_FILENO) != 0;
    if (interactive)
        out << "edgetrack run: press Enter to start or end a calibration (the button), type "
               "'d' for a double press (rig calibration by wand), 'long' to delete all models, "
               "'s' for the status view, Ctrl-C to stop\n";
    out << std::flush;

    stopRequested = false;
    std::signal(SIGINT, onStopSignal);
    std::signal(SIGTERM, onStopSignal);
    // A closed terminal (SIGHUP) stops the board as Ctrl-C does: with its final report.
    std::signal(SIGHUP, onStopSignal);
    std::signal(SIGUSR1, onReportSignal);

    StdinButton stdinButton(typedButton);
    std::uint64_t watchdogInterval_us = 0;
    const bool watchdog = sd_watchdog_enabled(0, &watchdogInterval_us) > 0;
    const hal::Nanoseconds statusPeriod =
        static_cast<hal::Nanoseconds>(config.health.statusInterval_s * 1e9);
    hal::Nanoseconds nextStatus = board.clock.now() + statusPeriod;
    hal::Nanoseconds nextWatchdog = board.clock.now();
    bool notifiedReady = false;
    std::string waitingFor;
    hal::Nanoseconds nextReadyCheck = board.clock.now();
    const bool terminal = ::isatty(STDERR_FILENO) != 0;
    while (!stopRequested) {
        switch (stdinButton.poll()) {
        case StdinButton::Press::Short:
            runBoard.press(200 * hal::kNanosecondsPerMillisecond);
            break;
        case StdinButton::Press::Double:
            runBoard.press(100 * hal::kNanosecondsPerMillisecond,
                           static_cast<hal::Nanoseconds>(config.gpio.doublePress_s * 0.5e9));
            break;
        case StdinButton::Press::Long:
            runBoard.press(static_cast<hal::Nanoseconds>((config.gpio.longPress_s + 0.3) * 1e9));
            break;
        case StdinButton::Press::Status:
            reportRequested = true;
            break;
        case StdinButton::Press::None:
            break;
        }
        runBoard.applyFaults();
        firmware.step();
        const hal::Nanoseconds now = board.clock.now();
        if (runBoard.needsProcessRestart()) {
            err << "\nedgetrack run: a camera's device was removed while streaming; libcamera "
                   "cannot take it back in this process: exiting so that systemd starts "
                   "edgetrack again\n";
            break;
        }
        if (!notifiedReady && firmware.ready() && now >= nextReadyCheck) {
            // Cameras, flash and outputs up; on the real board the GPIO lines and CAN too.
            nextReadyCheck = now + 200 * hal::kNanosecondsPerMillisecond;
            std::string why;
            if (!runBoard.devicesUp(why)) {
                if (why != waitingFor)
                    err << "\nedgetrack run: waiting for " << why << "\n" << std::flush;
                waitingFor = why;
            } else {
                sd_notify(0, "READY=1");
                notifiedReady = true;
                out << "edgetrack run: ready (" << runBoard.devicesName()
                    << (config.can.enabled ? ", CAN" : "") << " up)\n"
                    << std::flush;
            }
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
    std::signal(SIGHUP, SIG_DFL);
    std::signal(SIGUSR1, SIG_DFL);
    if (terminal && statusPeriod > 0)
        err << "\n";
    out << firmware.statusReport();
    if (canLog) {
        canLog->flush();
        out << "edgetrack run: " << canLog->framesLogged() << " CAN frames logged to "
            << options.canLog.string() << " (candump -L)";
        if (canLog->framesLost() > 0)
            out << ", " << canLog->framesLost() << " lost (" << canLog->writeFailures()
                << " writes failed)";
        out << "\n";
    }
    out << runBoard.report();
    if (runBoard.needsProcessRestart()) {
        out << std::flush;
        err << std::flush;
        // libcamera still holds the removed camera: leave without running its destructors.
        std::_Exit(kExitRestart);
    }
    return 0;
}

} // namespace edgetrack::app
