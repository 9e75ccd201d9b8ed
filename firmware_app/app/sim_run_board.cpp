// `edgetrack run --board sim`: the simulated board, in real time, sending UDP to the host.
#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <string_view>
#include <vector>

#include "firmware_app/app/run_board.hpp"
#include "hal/linux/posix_udp_sender.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/sim_board.hpp"

namespace edgetrack::app {

namespace {

class SimRunBoard : public RunBoard {
public:
    SimRunBoard(sim::Scene scene, std::uint64_t seed, const sim::SimBoardOptions& options,
                std::string sceneName, const std::array<double, 2>& rigKnock,
                std::vector<SimFault> faults)
        : sim_(std::move(scene), seed, options)
        , believedRig_(sim::knockedRig(sim_.world.rig(), rigKnock[0], rigKnock[1]))
        , board_{sim_.clock, sim_.cameras,  sim_.ledRing, sim_.button, sim_.statusLed,
                 sim_.flash, sim_.rigFlash, sim_.can,     udp_}
        , sceneName_(std::move(sceneName))
        , start_(sim_.clock.now()) {
        for (const SimFault& fault : faults)
            faults_.push_back({fault});
    }

    void applyFaults() override {
        const double now_s = hal::toSeconds(sim_.clock.now() - start_);
        for (Scheduled& f : faults_) {
            if (!f.started && now_s >= f.fault.at_s) {
                f.started = true;
                switch (f.fault.kind) {
                case SimFault::Kind::CameraStall:
                    sim_.cameras.setStalled(true);
                    break;
                case SimFault::Kind::CanBusOff:
                    sim_.can.injectBusOff();
                    break;
                case SimFault::Kind::ButtonBounce:
                    sim_.button.press(sim_.clock.now(), 200 * hal::kNanosecondsPerMillisecond, 5);
                    break;
                }
            }
            if (f.started && !f.ended && now_s >= f.fault.at_s + f.fault.duration_s) {
                f.ended = true;
                if (f.fault.kind == SimFault::Kind::CameraStall)
                    sim_.cameras.setStalled(false);
                else if (f.fault.kind == SimFault::Kind::CanBusOff)
                    sim_.can.restart();
            }
        }
    }

    bool udpValid() const { return udp_.isValid(); }
    int udpErrno() const { return udp_.errnoAtOpen(); }

    hal::Board& board() override { return board_; }
    /// The rig the firmware starts with: the scene's, unless [cameras] sim_rig_knock moved it.
    const StereoRig& rig() const override { return believedRig_; }
    std::string describe() const override { return "simulated board, scene '" + sceneName_ + "'"; }
    bool hasTypedButton() const override { return true; }
    void press(hal::Nanoseconds duration) override {
        sim_.button.press(sim_.clock.now(), duration);
    }
    void press(hal::Nanoseconds duration, hal::Nanoseconds gap) override {
        sim_.button.press(sim_.clock.now(), duration);
        sim_.button.press(sim_.clock.now() + duration + gap, duration);
    }
    std::string devicesName() const override { return "cameras"; }

private:
    struct Scheduled {
        SimFault fault;
        bool started = false;
        bool ended = false;
    };
    sim::SimBoard sim_;
    StereoRig believedRig_;
    // The simulated board's UDP is the host's: a DTrack client on this machine sees the poses.
    linux_hal::PosixUdpSender udp_;
    hal::Board board_;
    std::string sceneName_;
    std::vector<Scheduled> faults_;
    hal::Nanoseconds start_;
};

} // namespace

Result<SimFault> parseSimFault(std::string_view text) {
    const auto fail = [&](const std::string& why) {
        return Error{"--fault " + std::string(text) + ": " + why +
                     " (camera-stall@T+D, can-bus-off@T, button-bounce@T; seconds)"};
    };
    const std::size_t at = text.find('@');
    if (at == std::string_view::npos)
        return fail("no @time");
    SimFault fault;
    const std::string_view kind = text.substr(0, at);
    if (kind == "camera-stall")
        fault.kind = SimFault::Kind::CameraStall;
    else if (kind == "can-bus-off")
        fault.kind = SimFault::Kind::CanBusOff;
    else if (kind == "button-bounce")
        fault.kind = SimFault::Kind::ButtonBounce;
    else
        return fail("unknown fault '" + std::string(kind) + "'");
    std::string_view when = text.substr(at + 1);
    const std::size_t plus = when.find('+');
    const auto number = [](std::string_view s, double& value) {
        const char* end = s.data() + s.size();
        const auto [ptr, ec] = std::from_chars(s.data(), end, value);
        return ec == std::errc{} && ptr == end && std::isfinite(value) && value >= 0.0;
    };
    if (!number(when.substr(0, plus), fault.at_s))
        return fail("the time is not a number of seconds");
    if (plus != std::string_view::npos) {
        if (fault.kind != SimFault::Kind::CameraStall)
            return fail("only camera-stall takes a +duration");
        if (!number(when.substr(plus + 1), fault.duration_s))
            return fail("the duration is not a number of seconds");
    } else if (fault.kind == SimFault::Kind::CameraStall) {
        return fail("camera-stall needs +duration");
    } else if (fault.kind == SimFault::Kind::CanBusOff) {
        fault.duration_s = 1.0; // the controller restarts, as with restart-ms
    }
    return fault;
}

bool isSimScene(const std::string& name) {
    const std::span<const sim::SceneInfo> scenes = sim::sceneCatalogue();
    return std::any_of(scenes.begin(), scenes.end(),
                       [&](const sim::SceneInfo& info) { return name == info.name; });
}

Result<std::unique_ptr<RunBoard>> makeSimRunBoard(const FirmwareConfig& config,
                                                  const std::string& scene, std::uint64_t seed,
                                                  std::vector<SimFault> faults) {
    std::optional<sim::Scene> made = sim::makeScene(scene, seed);
    if (!made)
        return Error{"unknown scene '" + scene + "' (edgetrack sim --list)"};
    sim::SimBoardOptions options;
    options.realTime = true;
    options.cameraBufferPairs = config.cameras.buffers;
    options.flashSize = config.flash.size_bytes;
    options.flashEraseBlock = config.flash.eraseBlock_bytes;
    options.rigFlashSize = config.flash.rigSize_bytes;
    auto board = std::make_unique<SimRunBoard>(std::move(*made), seed, options, scene,
                                               config.cameras.simRigKnock, std::move(faults));
    if (!board->udpValid())
        return Error{std::string("cannot open a UDP socket: ") + std::strerror(board->udpErrno())};
    return std::unique_ptr<RunBoard>(std::move(board));
}

} // namespace edgetrack::app
