// Fuzz target: the CAN pose encoder fed any pose, finite or not, in range or not.
#include <cmath>
#include <cstdint>

#include "firmware_app/firmware/can_pose.hpp"
#include "tests/fuzz/fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    fuzz::FuzzInput in(data, size);
    app::CanPose pose;
    pose.body = in.value<std::uint32_t>() % 64;
    pose.found = in.byte() % 2 == 1;
    pose.frame = in.value<std::uint64_t>();
    pose.T_rig_from_model.translation_mm = {in.value<double>(), in.value<double>(),
                                            in.value<double>()};
    pose.T_rig_from_model.rotation =
        Quat(in.value<double>(), in.value<double>(), in.value<double>(), in.value<double>());
    pose.markers = in.value<std::uint32_t>();
    pose.rms_mm = in.value<double>();
    pose.latency_s = in.value<double>();
    const app::CanPoseLayout layout;
    const auto classic = app::encodeClassicPose(pose, layout);
    for (const hal::CanFrame& frame : classic)
        if (frame.length > 8)
            fuzz::fail("a classic frame longer than 8 bytes");
    const hal::CanFrame fd = app::encodeFdPose(pose, layout);
    if (fd.length > 64)
        fuzz::fail("an FD frame longer than 64 bytes");
    return 0;
}
