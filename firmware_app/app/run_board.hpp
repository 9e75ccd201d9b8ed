// The board `edgetrack run` drives: one factory per hal backend, behind one interface.
#pragma once

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.hpp"
#include "core/stereo_rig.hpp"
#include "firmware_app/firmware/firmware_config.hpp"
#include "hal/hal.hpp"

namespace edgetrack::app {

/**
 * \brief A board with what `run` needs beyond hal::Board: its rig, its name, and the few things
 * only some backends have (a button the user presses by typing, devices that come up late, a
 * camera stack that needs a new process after a device was removed).
 */
class RunBoard {
public:
    virtual ~RunBoard() = default;

    virtual hal::Board& board() = 0;
    /// \brief The stereo calibration of the board's cameras.
    virtual const StereoRig& rig() const = 0;
    /// \brief One line for the console: which board, which cameras.
    virtual std::string describe() const = 0;

    /// \brief Whether the user presses the button by typing (see press()).
    virtual bool hasTypedButton() const { return false; }
    /// \brief Press the button for \a duration, as typed (a board without hasTypedButton() ignores
    /// it: its button is a real one).
    virtual void press(hal::Nanoseconds duration) { (void)duration; }
    /// \brief Two presses of \a duration, the second starting \a gap after the first's release.
    virtual void press(hal::Nanoseconds duration, hal::Nanoseconds gap) {
        (void)duration;
        (void)gap;
    }
    /// \brief What must be up before the board is ready, for the console ("cameras, GPIO").
    virtual std::string devicesName() const = 0;
    /// \brief Whether every device the firmware uses is up; \a why names the first that is not.
    virtual bool devicesUp(std::string& why) {
        (void)why;
        return true;
    }
    /// \brief A camera vanished in a way only a new process recovers from (libcamera).
    virtual bool needsProcessRestart() const { return false; }
    /// \brief The backend's own counters for the final report (may be empty).
    virtual std::string report() const { return {}; }
    /// \brief Start the faults scheduled for this moment (run --fault; the simulated board's).
    virtual void applyFaults() {}
};

/**
 * \brief A fault of the simulated board's devices, for an integrator to test a receiver's handling
 * of it: `camera-stall@T+D` (the cameras deliver nothing from T s for D s), `can-bus-off@T` (the
 * controller goes bus-off at T s and restarts 1 s later), `button-bounce@T` (a press at T s with
 * five bounces at each end).
 */
struct SimFault {
    enum class Kind { CameraStall, CanBusOff, ButtonBounce };
    Kind kind = Kind::CameraStall;
    double at_s = 0.0;
    double duration_s = 0.0;
};

/// \brief \a text as a SimFault; a one-line error naming what is wrong.
Result<SimFault> parseSimFault(std::string_view text);

/// \return whether the simulated board knows scene \a name (`edgetrack sim --list`).
bool isSimScene(const std::string& name);

/// \brief The simulated board rendering \a scene (seed \a seed), in real time, with the host's UDP.
Result<std::unique_ptr<RunBoard>> makeSimRunBoard(const FirmwareConfig& config,
                                                  const std::string& scene, std::uint64_t seed,
                                                  std::vector<SimFault> faults = {});

/// \brief The real board: libcamera, libgpiod, SocketCAN, the flash file, [cameras] rig.
Result<std::unique_ptr<RunBoard>> makeLinuxRunBoard(const FirmwareConfig& config);

} // namespace edgetrack::app
