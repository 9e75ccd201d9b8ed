// `edgetrack run`: the firmware on the simulated board or the real one (libcamera, gpiod, CAN).
#pragma once

#include <cstdint>
#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

namespace edgetrack::app {

struct RunCommandOptions {
    std::filesystem::path config;
    std::string board = "sim";
    std::string scene;
    /// Stop after this many processed frames (0: until SIGINT or SIGTERM).
    std::int64_t frames = 0;
    /// "HOST:PORT": replaces the configured DTrack destinations.
    std::string udp;
    /// Enables CAN output on this interface.
    std::string can;
    /// Enables CAN output and logs every frame sent to this file (`candump -L` format).
    std::filesystem::path canLog;
    /// Model directory (INTERFACES §4) to track, saved to flash.
    std::filesystem::path models;
    std::uint64_t seed = 1;
    /// Read button presses from standard input (Enter: short press, "long": long press).
    bool buttonFromStdin = true;
    /// Faults of the simulated board's devices (SimFault's forms), for testing receivers.
    std::vector<std::string> faults;
};

/**
 * \brief Run the firmware until \a options.frames frames, SIGINT or SIGTERM.
 *
 * Prints a status line once a second (`[health] status_interval_s`) to \a err and the full status
 * view at the end and on SIGUSR1; tells systemd READY=1 once cameras, flash and outputs are up,
 * and feeds its watchdog. \return the process exit code.
 */
int runFirmwareCommand(const RunCommandOptions& options, std::ostream& out, std::ostream& err);

} // namespace edgetrack::app
