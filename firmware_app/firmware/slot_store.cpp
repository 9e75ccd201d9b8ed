// The A/B slot protocol of the stores on flash, and their little-endian payload codec.
#include "firmware_app/firmware/slot_store.hpp"

#include <algorithm>
#include <bit>
#include <zlib.h>

namespace edgetrack::app {

namespace {

// Payload writes go in pages of this size, as NOR flash programs them.
constexpr std::size_t kPage = 256;

std::uint32_t crc32Of(std::span<const std::uint8_t> bytes) {
    return static_cast<std::uint32_t>(
        ::crc32(::crc32(0L, Z_NULL, 0), bytes.data(), static_cast<uInt>(bytes.size())));
}

/// Serial-number order: a is newer than b if it is ahead by less than half the range.
bool newer(std::uint32_t a, std::uint32_t b) {
    return a != b && static_cast<std::uint32_t>(a - b) < 0x80000000u;
}

} // namespace

void ByteWriter::f64(double v) {
    bytes(std::bit_cast<std::uint64_t>(v), 8);
}

void ByteWriter::text(const std::string& s) {
    u16(static_cast<std::uint16_t>(s.size()));
    out_.insert(out_.end(), s.begin(), s.end());
}

void ByteWriter::bytes(std::uint64_t v, int count) {
    for (int i = 0; i < count; ++i)
        out_.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

bool ByteReader::f64(double& v) {
    std::uint64_t bits = 0;
    if (!number(bits, 8))
        return false;
    v = std::bit_cast<double>(bits);
    return true;
}

bool ByteReader::text(std::string& s) {
    std::uint16_t length = 0;
    if (!u16(length) || length > left())
        return false;
    s.assign(reinterpret_cast<const char*>(in_.data() + at_), length);
    at_ += length;
    return true;
}

SlotStore::SlotStore(hal::Flash& flash, std::uint32_t magic, std::uint16_t version,
                     std::string what)
    : flash_(flash)
    , magic_(magic)
    , version_(version)
    , what_(std::move(what)) {
    const std::size_t block = flash.eraseBlockSize();
    if (block > 0)
        slotSize_ = flash.size() / 2 / block * block;
}

SlotStore::SlotContent SlotStore::readSlot(int slot) {
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
    ByteReader r(raw);
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
    if (magic != magic_ || headerSize != kHeaderSize)
        return corrupt("not a " + what_ + " slot");
    if (version != version_)
        return corrupt("format version " + std::to_string(version) + ", this firmware reads " +
                       std::to_string(version_));
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

std::array<SlotReport, 2> SlotStore::inspect() {
    return {readSlot(0).report, readSlot(1).report};
}

Result<StoredPayload> SlotStore::load(
    const std::function<std::optional<std::string>(std::span<const std::uint8_t>)>& check) {
    if (!isValid())
        return Error{"flash partition of " + std::to_string(flash_.size()) +
                     " bytes cannot hold two " + what_ + " slots"};
    std::array<SlotContent, 2> slots{readSlot(0), readSlot(1)};
    // Newest first; a valid slot whose payload the caller refuses is treated as corrupt.
    std::array<int, 2> order{0, 1};
    if (slots[1].report.state == SlotState::Valid &&
        (slots[0].report.state != SlotState::Valid ||
         newer(slots[1].report.sequence, slots[0].report.sequence)))
        order = {1, 0};
    for (int slot : order) {
        SlotContent& c = slots[static_cast<std::size_t>(slot)];
        if (c.report.state != SlotState::Valid)
            continue;
        if (std::optional<std::string> refused = check(c.payload); refused) {
            c.report.state = SlotState::Corrupt;
            c.report.why = std::move(*refused);
            continue;
        }
        const SlotReport& other = slots[static_cast<std::size_t>(1 - slot)].report;
        std::string problem;
        if (other.state == SlotState::Corrupt)
            problem = std::string(slot == 0 ? "slot B" : "slot A") + " corrupt (" + other.why + ")";
        return StoredPayload{std::move(c.payload), c.report.sequence, slot, std::move(problem)};
    }
    std::string why;
    for (int slot : {0, 1}) {
        const SlotReport& report = slots[static_cast<std::size_t>(slot)].report;
        why += (slot == 0 ? "slot A " : ", slot B ");
        why += report.state == SlotState::Empty ? "empty" : "corrupt (" + report.why + ")";
    }
    return Error{"no " + what_ + (what_ == "model" ? "s" : "") + " on flash: " + why};
}

Status SlotStore::save(std::span<const std::uint8_t> payload) {
    if (!isValid())
        return Error{"flash partition cannot hold two " + what_ + " slots"};
    if (payload.size() > capacityBytes())
        return Error{"the " + what_ + " payload takes " + std::to_string(payload.size()) +
                     " bytes; a slot holds " + std::to_string(capacityBytes())};
    const std::array<SlotReport, 2> slots = inspect();
    // Write over the slot that does not hold the newest valid payload.
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
        if (Status s = flash_.write(base + kHeaderSize + at, payload.subspan(at, length)); !s)
            return s;
    }
    // The header goes last: until it is whole, this slot does not count.
    std::vector<std::uint8_t> header;
    ByteWriter w(header);
    w.u32(magic_);
    w.u16(version_);
    w.u16(static_cast<std::uint16_t>(kHeaderSize));
    w.u32(sequence);
    w.u32(static_cast<std::uint32_t>(payload.size()));
    w.u32(crc32Of(payload));
    w.u32(0);
    w.u32(0);
    w.u32(crc32Of(header));
    return flash_.write(base, header);
}

} // namespace edgetrack::app
