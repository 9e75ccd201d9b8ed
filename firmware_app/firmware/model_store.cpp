// Models on flash: the A/B slot protocol and the binary payload codec.
#include "firmware_app/firmware/model_store.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <set>
#include <zlib.h>

namespace edgetrack::app {

namespace {

constexpr std::uint32_t kMagic = 0x534D5445; // "ETMS" in little-endian bytes
constexpr std::uint16_t kVersion = 1;
// Payload writes go in pages of this size, as NOR flash programs them.
constexpr std::size_t kPage = 256;

std::uint32_t crc32Of(std::span<const std::uint8_t> bytes) {
    return static_cast<std::uint32_t>(
        ::crc32(::crc32(0L, Z_NULL, 0), bytes.data(), static_cast<uInt>(bytes.size())));
}

class Writer {
public:
    explicit Writer(std::vector<std::uint8_t>& out)
        : out_(out) {}
    void u16(std::uint16_t v) { bytes(v, 2); }
    void u32(std::uint32_t v) { bytes(v, 4); }
    void f64(double v) { bytes(std::bit_cast<std::uint64_t>(v), 8); }
    void text(const std::string& s) {
        u16(static_cast<std::uint16_t>(s.size()));
        out_.insert(out_.end(), s.begin(), s.end());
    }

private:
    void bytes(std::uint64_t v, int count) {
        for (int i = 0; i < count; ++i)
            out_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
    }
    std::vector<std::uint8_t>& out_;
};

/// Little-endian reader that refuses, rather than overruns, a short payload.
class Reader {
public:
    explicit Reader(std::span<const std::uint8_t> in)
        : in_(in) {}
    bool u16(std::uint16_t& v) { return number(v, 2); }
    bool u32(std::uint32_t& v) { return number(v, 4); }
    bool f64(double& v) {
        std::uint64_t bits = 0;
        if (!number(bits, 8))
            return false;
        v = std::bit_cast<double>(bits);
        return true;
    }
    bool text(std::string& s) {
        std::uint16_t length = 0;
        if (!u16(length) || length > left())
            return false;
        s.assign(reinterpret_cast<const char*>(in_.data() + at_), length);
        at_ += length;
        return true;
    }
    std::size_t left() const { return in_.size() - at_; }

private:
    template <typename T>
    bool number(T& v, int count) {
        if (left() < static_cast<std::size_t>(count))
            return false;
        std::uint64_t value = 0;
        for (int i = 0; i < count; ++i)
            value |= std::uint64_t{in_[at_ + static_cast<std::size_t>(i)]} << (8 * i);
        at_ += static_cast<std::size_t>(count);
        v = static_cast<T>(value);
        return true;
    }
    std::span<const std::uint8_t> in_;
    std::size_t at_ = 0;
};

struct Header {
    std::uint32_t sequence = 0;
    std::uint32_t payloadLength = 0;
    std::uint32_t payloadCrc = 0;
};

std::array<std::uint8_t, ModelStore::kHeaderSize> encodeHeader(const Header& h) {
    std::vector<std::uint8_t> bytes;
    Writer w(bytes);
    w.u32(kMagic);
    w.u16(kVersion);
    w.u16(static_cast<std::uint16_t>(ModelStore::kHeaderSize));
    w.u32(h.sequence);
    w.u32(h.payloadLength);
    w.u32(h.payloadCrc);
    w.u32(0);
    w.u32(0);
    w.u32(crc32Of(bytes));
    std::array<std::uint8_t, ModelStore::kHeaderSize> out{};
    std::copy(bytes.begin(), bytes.end(), out.begin());
    return out;
}

/// Serial-number order: a is newer than b if it is ahead by less than half the range.
bool newer(std::uint32_t a, std::uint32_t b) {
    return a != b && static_cast<std::uint32_t>(a - b) < 0x80000000u;
}

} // namespace

std::vector<std::uint8_t> encodeModels(std::span<const NamedModel> models) {
    std::vector<std::uint8_t> out;
    Writer w(out);
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
    Reader r(payload);
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
    : flash_(flash)
    , maxMarkers_(maxMarkers) {
    const std::size_t block = flash.eraseBlockSize();
    if (block > 0)
        slotSize_ = flash.size() / 2 / block * block;
}

ModelStore::SlotContent ModelStore::readSlot(int slot) {
    SlotContent content;
    SlotReport& report = content.report;
    auto corrupt = [&](std::string why) {
        report.state = SlotState::Corrupt;
        report.why = std::move(why);
        return content;
    };
    std::array<std::uint8_t, kHeaderSize> raw{};
    if (Status s = flash_.read(slotOffset(slot), raw); !s)
        return corrupt("cannot read: " + s.error().message);
    if (std::all_of(raw.begin(), raw.end(), [](std::uint8_t b) { return b == 0xFF; })) {
        report.state = SlotState::Empty;
        return content;
    }
    Reader r(raw);
    std::uint32_t magic = 0, sequence = 0, length = 0, payloadCrc = 0, reserved = 0, headerCrc = 0;
    std::uint16_t version = 0, headerSize = 0;
    r.u32(magic);
    r.u16(version);
    r.u16(headerSize);
    r.u32(sequence);
    r.u32(length);
    r.u32(payloadCrc);
    r.u32(reserved);
    r.u32(reserved);
    r.u32(headerCrc);
    if (headerCrc != crc32Of(std::span(raw).first(kHeaderSize - 4)))
        return corrupt("header CRC mismatch (a save cut short?)");
    if (magic != kMagic || headerSize != kHeaderSize)
        return corrupt("not a model slot");
    if (version != kVersion)
        return corrupt("format version " + std::to_string(version) + ", this firmware reads " +
                       std::to_string(kVersion));
    if (length > capacityBytes())
        return corrupt("payload length " + std::to_string(length) + " exceeds the slot");
    content.payload.resize(length);
    if (Status s = flash_.read(slotOffset(slot) + kHeaderSize, content.payload); !s)
        return corrupt("cannot read the payload: " + s.error().message);
    if (crc32Of(content.payload) != payloadCrc)
        return corrupt("payload CRC mismatch");
    report.state = SlotState::Valid;
    report.sequence = sequence;
    return content;
}

std::array<SlotReport, 2> ModelStore::inspect() {
    return {readSlot(0).report, readSlot(1).report};
}

Result<StoredModels> ModelStore::load() {
    if (!isValid())
        return Error{"flash partition of " + std::to_string(flash_.size()) +
                     " bytes cannot hold two model slots"};
    std::array<SlotContent, 2> slots{readSlot(0), readSlot(1)};
    std::string why;
    // Newest first; a valid slot whose payload does not decode is treated as corrupt.
    std::array<int, 2> order{0, 1};
    if (slots[1].report.state == SlotState::Valid &&
        (slots[0].report.state != SlotState::Valid ||
         newer(slots[1].report.sequence, slots[0].report.sequence)))
        order = {1, 0};
    for (int slot : order) {
        SlotContent& c = slots[static_cast<std::size_t>(slot)];
        if (c.report.state == SlotState::Valid) {
            Result<std::vector<NamedModel>> models = decodeModels(c.payload, maxMarkers_);
            if (models)
                return StoredModels{std::move(*models), c.report.sequence, slot};
            c.report.state = SlotState::Corrupt;
            c.report.why = models.error().message;
        }
    }
    for (int slot : {0, 1}) {
        const SlotReport& report = slots[static_cast<std::size_t>(slot)].report;
        why += (slot == 0 ? "slot A " : ", slot B ");
        why += report.state == SlotState::Empty ? "empty" : "corrupt (" + report.why + ")";
    }
    return Error{"no models on flash: " + why};
}

Status ModelStore::save(std::span<const NamedModel> models) {
    if (!isValid())
        return Error{"flash partition cannot hold two model slots"};
    const std::vector<std::uint8_t> payload = encodeModels(models);
    if (payload.size() > capacityBytes())
        return Error{"models take " + std::to_string(payload.size()) + " bytes; a slot holds " +
                     std::to_string(capacityBytes())};
    const std::array<SlotReport, 2> slots = inspect();
    // Write over the slot that does not hold the newest valid set.
    int target = 0;
    std::uint32_t sequence = 1;
    const bool valid0 = slots[0].state == SlotState::Valid;
    const bool valid1 = slots[1].state == SlotState::Valid;
    if (valid0 && (!valid1 || newer(slots[0].sequence, slots[1].sequence))) {
        target = 1;
        sequence = slots[0].sequence + 1;
    } else if (valid1) {
        target = 0;
        sequence = slots[1].sequence + 1;
    }
    const std::size_t base = slotOffset(target);
    if (Status s = flash_.erase(base, slotSize_); !s)
        return s;
    for (std::size_t at = 0; at < payload.size(); at += kPage) {
        const std::size_t length = std::min(kPage, payload.size() - at);
        if (Status s =
                flash_.write(base + kHeaderSize + at, std::span(payload).subspan(at, length));
            !s)
            return s;
    }
    // The header goes last: until it is whole, this slot does not count.
    const auto header = encodeHeader(
        Header{sequence, static_cast<std::uint32_t>(payload.size()), crc32Of(payload)});
    return flash_.write(base, header);
}

} // namespace edgetrack::app
