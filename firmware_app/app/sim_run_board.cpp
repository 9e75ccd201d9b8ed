// `edgetrack run --board sim`: the simulated board, in real time, sending UDP to the host.
#include <algorithm>
#include <cstring>

#include "firmware_app/app/run_board.hpp"
#include "hal/linux/posix_udp_sender.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/sim_board.hpp"

namespace edgetrack::app {

namespace {

class SimRunBoard : public RunBoard {
public:
    SimRunBoard(sim::Scene scene, std::uint64_t seed, const sim::SimBoardOptions& options,
                std::string sceneName, const std::array<double, 2>& rigKnock)
        : sim_(std::move(scene), seed, options)
        , believedRig_(sim::knockedRig(sim_.world.rig(), rigKnock[0], rigKnock[1]))
        , board_{sim_.clock, sim_.cameras,  sim_.ledRing, sim_.button, sim_.statusLed,
                 sim_.flash, sim_.rigFlash, sim_.can,     udp_}
        , sceneName_(std::move(sceneName)) {}

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
    sim::SimBoard sim_;
    StereoRig believedRig_;
    // The simulated board's UDP is the host's: a DTrack client on this machine sees the poses.
    linux_hal::PosixUdpSender udp_;
    hal::Board board_;
    std::string sceneName_;
};

} // namespace

bool isSimScene(const std::string& name) {
    const std::span<const sim::SceneInfo> scenes = sim::sceneCatalogue();
    return std::any_of(scenes.begin(), scenes.end(),
                       [&](const sim::SceneInfo& info) { return name == info.name; });
}

Result<std::unique_ptr<RunBoard>> makeSimRunBoard(const FirmwareConfig& config,
                                                  const std::string& scene, std::uint64_t seed) {
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
                                               config.cameras.simRigKnock);
    if (!board->udpValid())
        return Error{std::string("cannot open a UDP socket: ") + std::strerror(board->udpErrno())};
    return std::unique_ptr<RunBoard>(std::move(board));
}

} // namespace edgetrack::app
