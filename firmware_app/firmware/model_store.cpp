// Models on flash: the binary payload codec on the A/B slot store.
#include "firmware_app/firmware/model_store.hpp"

#include <algorithm>
#include <cmath>
#include <set>

namespace edgetrack::app {

namespace {

constexpr std::uint32_t kMagic = 0x534D5445; // "ETMS" in little-endian bytes
constexpr std::uint16_t kVersion = 1;

} // namespace

std::vector<std::uint8_t> encodeModels(std::span<const NamedModel> models) {
    std::vector<std::uint8_t> out;
    ByteWriter w(out);
    w.u32(static_cast<std::uint32_t>(models.size()));
    for (const NamedModel& named : models) {
        const MarkerModel& m = named.model;
        w.u32(m.id);
        w.u16(static_cast<std::uint16_t>(m.sMin));
        w.text(named.name.substr(0, 0xFFFF));
        w.u16(static_cast<std::uint16_t>(m.markers_model_mm.size()));
        for (const Vec3& p : m.markers_model_mm) {
            w.f64(p.x());
            w.f64(p.y());
            w.f64(p.z());
        }
        // Edge lengths follow from the markers; only the co-visible pairs are stored.
        w.u32(static_cast<std::uint32_t>(m.edges.size()));
        for (const ModelEdge& e : m.edges) {
            w.u16(e.from);
            w.u16(e.to);
        }
    }
    return out;
}

Result<std::vector<NamedModel>> decodeModels(std::span<const std::uint8_t> payload,
                                             std::size_t maxMarkers) {
    ByteReader r(payload);
    std::uint32_t count = 0;
    if (!r.u32(count))
        return Error{"model payload: too short for its model count"};
    // Each model takes at least 12 bytes; a count beyond that is corrupt, not a reason to reserve.
    if (count > r.left() / 12)
        return Error{"model payload: " + std::to_string(count) + " models cannot fit"};
    std::vector<NamedModel> models;
    std::set<std::uint32_t> ids;
    for (std::uint32_t k = 0; k < count; ++k) {
        const std::string which = "model payload, model " + std::to_string(k);
        std::uint32_t id = 0;
        std::uint16_t sMin = 0, markers = 0;
        std::string name;
        if (!r.u32(id) || !r.u16(sMin) || !r.text(name) || !r.u16(markers))
            return Error{which + ": truncated"};
        if (markers > maxMarkers)
            return Error{which + ": " + std::to_string(markers) + " markers, at most " +
                         std::to_string(maxMarkers)};
        if (!ids.insert(id).second)
            return Error{which + ": id " + std::to_string(id) + " twice"};
        if (sMin < 3 || sMin > markers)
            return Error{which + ": s_min " + std::to_string(sMin) + " with " +
                         std::to_string(markers) + " markers"};
        NamedModel named{MarkerModel(markers), std::move(name)};
        named.model.id = id;
        named.model.sMin = sMin;
        for (std::uint16_t i = 0; i < markers; ++i) {
            double x = 0.0, y = 0.0, z = 0.0;
            if (!r.f64(x) || !r.f64(y) || !r.f64(z))
                return Error{which + ": truncated in its markers"};
            if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z))
                return Error{which + ": marker " + std::to_string(i) + " is not finite"};
            named.model.markers_model_mm.push_back(Vec3(x, y, z));
        }
        std::uint32_t edges = 0;
        if (!r.u32(edges) || edges > r.left() / 4 ||
            edges > std::size_t{markers} * (markers - 1u) / 2)
            return Error{which + ": bad edge count"};
        const auto& p = named.model.markers_model_mm;
        for (std::uint32_t e = 0; e < edges; ++e) {
            std::uint16_t from = 0, to = 0;
            r.u16(from);
            r.u16(to);
            if (from >= to || to >= markers)
                return Error{which + ": edge " + std::to_string(e) + " joins " +
                             std::to_string(from) + " and " + std::to_string(to)};
            named.model.edges.push_back(ModelEdge{from, to, (p[from] - p[to]).norm()});
        }
        models.push_back(std::move(named));
    }
    if (r.left() != 0)
        return Error{"model payload: " + std::to_string(r.left()) + " bytes after the last model"};
    return models;
}

ModelStore::ModelStore(hal::Flash& flash, std::size_t maxMarkers)
    : slots_(flash, kMagic, kVersion, "model")
    , maxMarkers_(maxMarkers) {}

Result<StoredModels> ModelStore::load() {
    std::vector<NamedModel> models;
    Result<StoredPayload> stored =
        slots_.load([&](std::span<const std::uint8_t> payload) -> std::optional<std::string> {
            Result<std::vector<NamedModel>> decoded = decodeModels(payload, maxMarkers_);
            if (!decoded)
                return decoded.error().message;
            models = std::move(*decoded);
            return std::nullopt;
        });
    if (!stored)
        return stored.error();
    return StoredModels{std::move(models), stored->sequence, stored->slot,
                        std::move(stored->otherSlotProblem)};
}

Status ModelStore::save(std::span<const NamedModel> models) {
    return slots_.save(encodeModels(models));
}

} // namespace edgetrack::app
