// Poses on CAN: one table of signals drives both the encoder and the DBC file that documents it.
#include "firmware_app/firmware/can_pose.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <span>

namespace edgetrack::app {

namespace {

/// One DBC signal: little-endian (Intel) bit order, as every signal here.
struct Signal {
    const char* name;
    unsigned start;
    unsigned length;
    bool isSigned;
    double factor;
    double minimum;
    double maximum;
    const char* unit;
};

struct Message {
    const char* suffix;
    unsigned length;
    bool fd;
    std::span<const Signal> signals;
    const char* comment;
};

constexpr double kQ15 = 1.0 / 16383.0;
constexpr double kQ16 = 1.0 / 32767.0;

constexpr Signal kPosition[] = {
    {"Counter", 0, 4, false, 1.0, 0.0, 15.0, ""},
    {"PositionX", 4, 20, true, 0.01, -5242.88, 5242.87, "mm"},
    {"PositionY", 24, 20, true, 0.01, -5242.88, 5242.87, "mm"},
    {"PositionZ", 44, 20, true, 0.01, -5242.88, 5242.87, "mm"},
};
constexpr Signal kOrientation[] = {
    {"Counter", 0, 4, false, 1.0, 0.0, 15.0, ""}, {"QuatW", 4, 15, true, kQ15, -1.0, 1.0, ""},
    {"QuatX", 19, 15, true, kQ15, -1.0, 1.0, ""}, {"QuatY", 34, 15, true, kQ15, -1.0, 1.0, ""},
    {"QuatZ", 49, 15, true, kQ15, -1.0, 1.0, ""},
};
constexpr Signal kStatus[] = {
    {"Counter", 0, 4, false, 1.0, 0.0, 15.0, ""},
    {"Found", 4, 1, false, 1.0, 0.0, 1.0, ""},
    {"Markers", 8, 8, false, 1.0, 0.0, 255.0, ""},
    {"FrameNumber", 16, 32, false, 1.0, 0.0, 4294967295.0, ""},
    {"Latency", 48, 16, false, 1.0, 0.0, 65535.0, "us"},
};
constexpr Signal kFd[] = {
    {"FrameNumber", 0, 32, false, 1.0, 0.0, 4294967295.0, ""},
    {"PositionX", 32, 32, true, 0.001, -2147483.648, 2147483.647, "mm"},
    {"PositionY", 64, 32, true, 0.001, -2147483.648, 2147483.647, "mm"},
    {"PositionZ", 96, 32, true, 0.001, -2147483.648, 2147483.647, "mm"},
    {"QuatW", 128, 16, true, kQ16, -1.0, 1.0, ""},
    {"QuatX", 144, 16, true, kQ16, -1.0, 1.0, ""},
    {"QuatY", 160, 16, true, kQ16, -1.0, 1.0, ""},
    {"QuatZ", 176, 16, true, kQ16, -1.0, 1.0, ""},
    {"Markers", 192, 8, false, 1.0, 0.0, 255.0, ""},
    {"Found", 200, 1, false, 1.0, 0.0, 1.0, ""},
    {"Rms", 208, 16, false, 0.001, 0.0, 65.535, "mm"},
    {"Latency", 224, 32, false, 1.0, 0.0, 4294967295.0, "us"},
};

constexpr Message kClassicMessages[] = {
    {"POSITION", 8, false, kPosition,
     "position of the model origin in the rig frame (camera 0: x right, y down, z forward)"},
    {"ORIENTATION", 8, false, kOrientation, "unit quaternion model to rig, scalar first, w >= 0"},
    {"STATUS", 8, false, kStatus,
     "Found, matched markers, frame number, latency from mid-exposure to sending"},
};
constexpr Message kFdMessage = {"POSE_FD", 32, true, kFd,
                                "the whole pose in one CAN FD frame; check Found first"};

/// Put \a value's low \a length bits at bit \a start (Intel order: bit k is byte k/8, bit k%8).
void putBits(std::array<std::uint8_t, 64>& data, unsigned start, unsigned length,
             std::uint64_t value) {
    for (unsigned i = 0; i < length; ++i) {
        const unsigned bit = start + i;
        const auto mask = static_cast<std::uint8_t>(1u << (bit % 8));
        if ((value >> i) & 1u)
            data[bit / 8] |= mask;
        else
            data[bit / 8] = static_cast<std::uint8_t>(data[bit / 8] & ~mask);
    }
}

/// Encode physical \a value into \a signal of \a data, clamped to the signal's range.
void put(std::array<std::uint8_t, 64>& data, const Signal& signal, double value) {
    const double clamped =
        std::clamp(std::isfinite(value) ? value : 0.0, signal.minimum, signal.maximum);
    const auto raw = static_cast<std::int64_t>(std::llround(clamped / signal.factor));
    putBits(data, signal.start, signal.length, static_cast<std::uint64_t>(raw));
}

const Signal& find(std::span<const Signal> signals, const char* name) {
    for (const Signal& s : signals)
        if (std::string_view(s.name) == name)
            return s;
    return signals.front(); // unreachable: every name used below is in its table
}

hal::CanFrame frameOf(std::uint32_t id, const Message& message) {
    hal::CanFrame frame;
    frame.id = id;
    frame.fd = message.fd;
    frame.bitRateSwitch = message.fd;
    frame.length = static_cast<std::uint8_t>(message.length);
    return frame;
}

} // namespace

std::array<hal::CanFrame, 3> encodeClassicPose(const CanPose& pose, const CanPoseLayout& layout) {
    const std::uint32_t base = layout.classicBaseId + 3 * pose.body;
    std::array<hal::CanFrame, 3> frames{frameOf(base, kClassicMessages[0]),
                                        frameOf(base + 1, kClassicMessages[1]),
                                        frameOf(base + 2, kClassicMessages[2])};
    const auto counter = static_cast<double>(pose.frame % 16);
    const Vec3 t = pose.found ? pose.T_rig_from_model.translation_mm : Vec3::Zero();
    const std::array<double, 4> q = pose.found ? wxyzFromQuaternion(pose.T_rig_from_model.rotation)
                                               : std::array<double, 4>{0.0, 0.0, 0.0, 0.0};
    put(frames[0].data, find(kPosition, "Counter"), counter);
    put(frames[0].data, find(kPosition, "PositionX"), t.x());
    put(frames[0].data, find(kPosition, "PositionY"), t.y());
    put(frames[0].data, find(kPosition, "PositionZ"), t.z());
    put(frames[1].data, find(kOrientation, "Counter"), counter);
    put(frames[1].data, find(kOrientation, "QuatW"), q[0]);
    put(frames[1].data, find(kOrientation, "QuatX"), q[1]);
    put(frames[1].data, find(kOrientation, "QuatY"), q[2]);
    put(frames[1].data, find(kOrientation, "QuatZ"), q[3]);
    put(frames[2].data, find(kStatus, "Counter"), counter);
    put(frames[2].data, find(kStatus, "Found"), pose.found ? 1.0 : 0.0);
    put(frames[2].data, find(kStatus, "Markers"), static_cast<double>(pose.markers));
    put(frames[2].data, find(kStatus, "FrameNumber"),
        static_cast<double>(pose.frame % 4294967296u));
    put(frames[2].data, find(kStatus, "Latency"), pose.latency_s * 1e6);
    return frames;
}

hal::CanFrame encodeFdPose(const CanPose& pose, const CanPoseLayout& layout) {
    hal::CanFrame frame = frameOf(layout.fdBaseId + pose.body, kFdMessage);
    const Vec3 t = pose.found ? pose.T_rig_from_model.translation_mm : Vec3::Zero();
    const std::array<double, 4> q = pose.found ? wxyzFromQuaternion(pose.T_rig_from_model.rotation)
                                               : std::array<double, 4>{0.0, 0.0, 0.0, 0.0};
    put(frame.data, find(kFd, "FrameNumber"), static_cast<double>(pose.frame % 4294967296u));
    put(frame.data, find(kFd, "PositionX"), t.x());
    put(frame.data, find(kFd, "PositionY"), t.y());
    put(frame.data, find(kFd, "PositionZ"), t.z());
    put(frame.data, find(kFd, "QuatW"), q[0]);
    put(frame.data, find(kFd, "QuatX"), q[1]);
    put(frame.data, find(kFd, "QuatY"), q[2]);
    put(frame.data, find(kFd, "QuatZ"), q[3]);
    put(frame.data, find(kFd, "Markers"), static_cast<double>(pose.markers));
    put(frame.data, find(kFd, "Found"), pose.found ? 1.0 : 0.0);
    put(frame.data, find(kFd, "Rms"), pose.rms_mm);
    put(frame.data, find(kFd, "Latency"), pose.latency_s * 1e6);
    return frame;
}

namespace {

/// \a value to 12 significant digits as a plain decimal ("0.0000610388817677", never
/// "6.10388817677e-05"): some DBC readers take no exponent and drop the signal.
std::string plainDecimal(double value) {
    if (value == 0.0)
        return "0";
    const int magnitude = static_cast<int>(std::floor(std::log10(std::abs(value))));
    const int decimals = std::max(0, 11 - magnitude);
    char text[64];
    std::snprintf(text, sizeof text, "%.*f", decimals, value);
    std::string out(text);
    if (out.find('.') != std::string::npos) {
        out.erase(out.find_last_not_of('0') + 1);
        if (out.back() == '.')
            out.pop_back();
    }
    return out;
}

} // namespace

std::string poseDbc(const CanPoseLayout& layout) {
    std::string out;
    char line[512];
    auto add = [&](const char* text) { out += text; };
    add("VERSION \"edgetrack pose frames 1\"\n\n");
    add("NS_ :\n\tCM_\n\tBA_DEF_\n\tBA_\n\tBA_DEF_DEF_\n\n");
    add("BS_:\n\nBU_: EDGETRACK HOST\n\n");
    struct Placed {
        std::uint32_t id;
        std::string name;
        const Message* message;
        std::uint32_t body;
    };
    std::vector<Placed> placed;
    for (std::uint32_t b = 0; b < layout.maxBodies; ++b) {
        for (std::uint32_t k = 0; k < 3; ++k)
            placed.push_back({layout.classicBaseId + 3 * b + k,
                              "BODY" + std::to_string(b) + "_" + kClassicMessages[k].suffix,
                              &kClassicMessages[k], b});
        placed.push_back({layout.fdBaseId + b, "BODY" + std::to_string(b) + "_" + kFdMessage.suffix,
                          &kFdMessage, b});
    }
    std::sort(placed.begin(), placed.end(),
              [](const Placed& a, const Placed& b) { return a.id < b.id; });
    for (const Placed& p : placed) {
        std::snprintf(line, sizeof line, "BO_ %u %s: %u EDGETRACK\n", p.id, p.name.c_str(),
                      p.message->length);
        add(line);
        for (const Signal& s : p.message->signals) {
            std::snprintf(line, sizeof line, " SG_ %s : %u|%u@1%c (%s,0) [%s|%s] \"%s\" HOST\n",
                          s.name, s.start, s.length, s.isSigned ? '-' : '+',
                          plainDecimal(s.factor).c_str(), plainDecimal(s.minimum).c_str(),
                          plainDecimal(s.maximum).c_str(), s.unit);
            add(line);
        }
        add("\n");
    }
    for (const Placed& p : placed) {
        std::snprintf(line, sizeof line, "CM_ BO_ %u \"Body %u: %s.\";\n", p.id, p.body,
                      p.message->comment);
        add(line);
    }
    add("BA_DEF_ BO_ \"VFrameFormat\" ENUM \"StandardCAN\",\"ExtendedCAN\",\"reserved\","
        "\"J1939PG\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\","
        "\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"reserved\",\"StandardCAN_FD\","
        "\"ExtendedCAN_FD\";\n");
    add("BA_DEF_ \"BusType\" STRING ;\n");
    add("BA_DEF_DEF_ \"VFrameFormat\" \"StandardCAN\";\n");
    add("BA_DEF_DEF_ \"BusType\" \"CAN FD\";\n");
    add("BA_ \"BusType\" \"CAN FD\";\n");
    for (const Placed& p : placed)
        if (p.message->fd) {
            std::snprintf(line, sizeof line, "BA_ \"VFrameFormat\" BO_ %u 14;\n", p.id);
            add(line);
        }
    return out;
}

} // namespace edgetrack::app
