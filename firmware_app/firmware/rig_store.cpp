// The board's rig on flash: its binary payload on the A/B slot store.
#include "firmware_app/firmware/rig_store.hpp"

#include <cmath>

namespace edgetrack::app {

namespace {

constexpr std::uint32_t kMagic = 0x52525445; // "ETRR" in little-endian bytes
constexpr std::uint16_t kVersion = 1;

} // namespace

std::vector<std::uint8_t> encodeRig(const StereoRig& rig, double reprojectionRms_px) {
    std::vector<std::uint8_t> out;
    ByteWriter w(out);
    for (const CameraModel& camera : rig.cameras()) {
        const CameraIntrinsics& in = camera.intrinsics();
        const CameraExtrinsics& ex = camera.extrinsics();
        w.u16(static_cast<std::uint16_t>(in.width_px));
        w.u16(static_cast<std::uint16_t>(in.height_px));
        for (double v : {in.fx_px, in.fy_px, in.cx_px, in.cy_px})
            w.f64(v);
        for (double v : in.distortion)
            w.f64(v);
        for (int r = 0; r < 3; ++r)
            for (int c = 0; c < 3; ++c)
                w.f64(ex.rotation_cam_from_rig(r, c));
        for (int i = 0; i < 3; ++i)
            w.f64(ex.translation_cam_from_rig_mm(i));
    }
    w.f64(reprojectionRms_px);
    return out;
}

Result<StoredRig> decodeRig(std::span<const std::uint8_t> payload) {
    ByteReader r(payload);
    std::array<CameraModel, 2> cameras;
    for (std::size_t c = 0; c < 2; ++c) {
        CameraIntrinsics in;
        CameraExtrinsics ex;
        std::uint16_t width = 0, height = 0;
        std::array<double, 4 + 5 + 9 + 3> v{};
        bool ok = r.u16(width) && r.u16(height);
        for (double& x : v)
            ok = ok && r.f64(x) && std::isfinite(x);
        if (!ok)
            return Error{"rig payload: camera " + std::to_string(c) + " truncated or not finite"};
        in.width_px = width;
        in.height_px = height;
        in.fx_px = v[0];
        in.fy_px = v[1];
        in.cx_px = v[2];
        in.cy_px = v[3];
        for (std::size_t k = 0; k < 5; ++k)
            in.distortion[k] = v[4 + k];
        for (int row = 0; row < 3; ++row)
            for (int col = 0; col < 3; ++col)
                ex.rotation_cam_from_rig(row, col) = v[9 + static_cast<std::size_t>(row * 3 + col)];
        ex.translation_cam_from_rig_mm = Vec3(v[18], v[19], v[20]);
        cameras[c] = CameraModel(in, ex);
        if (!cameras[c].isValid())
            return Error{"rig payload: camera " + std::to_string(c) + " is not a valid camera"};
    }
    StoredRig stored;
    if (!r.f64(stored.reprojectionRms_px) || !std::isfinite(stored.reprojectionRms_px))
        return Error{"rig payload: no reprojection RMS"};
    if (r.left() != 0)
        return Error{"rig payload: " + std::to_string(r.left()) + " bytes after the rig"};
    stored.rig = StereoRig(cameras[0], cameras[1]);
    if (!stored.rig.isValid())
        return Error{"rig payload: the two cameras do not make a rig"};
    return stored;
}

RigStore::RigStore(hal::Flash& flash)
    : slots_(flash, kMagic, kVersion, "rig") {}

Result<StoredRig> RigStore::load() {
    StoredRig rig;
    Result<StoredPayload> stored =
        slots_.load([&rig](std::span<const std::uint8_t> payload) -> std::optional<std::string> {
            Result<StoredRig> decoded = decodeRig(payload);
            if (!decoded)
                return decoded.error().message;
            rig = std::move(*decoded);
            return std::nullopt;
        });
    if (!stored)
        return stored.error();
    rig.sequence = stored->sequence;
    rig.slot = stored->slot;
    return rig;
}

Status RigStore::save(const StereoRig& rig, double reprojectionRms_px) {
    return slots_.save(encodeRig(rig, reprojectionRms_px));
}

} // namespace edgetrack::app
