// A small DBC reader and decoder for tests, independent of the CAN pose encoder.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "hal/can_bus.hpp"

namespace edgetrack::test {

/// deploy/edgetrack.dbc of the source tree.
inline std::filesystem::path deployedDbc() {
    return std::filesystem::path(EDGETRACK_SOURCE_DIR) / "deploy" / "edgetrack.dbc";
}

/// What a DBC says about one message: enough to decode Intel-order signals.
struct DbcSignal {
    std::string name;
    unsigned start = 0, length = 0;
    bool isSigned = false;
    double factor = 1.0, offset = 0.0, minimum = 0.0, maximum = 0.0;
};
struct DbcMessage {
    std::string name;
    unsigned length = 0;
    bool fd = false;
    std::vector<DbcSignal> signals;
};

/// A small DBC reader, independent of the encoder: BO_, SG_ and the VFrameFormat attribute.
inline std::map<std::uint32_t, DbcMessage> readDbc(const std::string& text) {
    std::map<std::uint32_t, DbcMessage> messages;
    std::istringstream in(text);
    std::string line;
    DbcMessage* current = nullptr;
    while (std::getline(in, line)) {
        unsigned id = 0, length = 0;
        char name[128] = {};
        if (std::sscanf(line.c_str(), "BO_ %u %127[^:]: %u", &id, name, &length) == 3) {
            current = &messages[id];
            current->name = name;
            current->length = length;
            continue;
        }
        DbcSignal s;
        char order = 0, sign = 0;
        if (current && std::sscanf(line.c_str(), " SG_ %127s : %u|%u@%c%c (%lf,%lf) [%lf|%lf]",
                                   name, &s.start, &s.length, &order, &sign, &s.factor, &s.offset,
                                   &s.minimum, &s.maximum) == 9) {
            EXPECT_EQ(order, '1') << "only Intel byte order is expected";
            s.name = name;
            s.isSigned = sign == '-';
            current->signals.push_back(s);
            continue;
        }
        unsigned format = 0;
        if (std::sscanf(line.c_str(), "BA_ \"VFrameFormat\" BO_ %u %u;", &id, &format) == 2)
            messages[id].fd = format == 14 || format == 15;
    }
    return messages;
}

/// The physical value of every signal of \a frame.
inline std::map<std::string, double> decode(const DbcMessage& message, const hal::CanFrame& frame) {
    std::map<std::string, double> values;
    for (const DbcSignal& s : message.signals) {
        std::uint64_t raw = 0;
        for (unsigned i = 0; i < s.length; ++i) {
            const unsigned bit = s.start + i;
            raw |= static_cast<std::uint64_t>(
                       (static_cast<unsigned>(frame.data[bit / 8]) >> (bit % 8)) & 1u)
                   << i;
        }
        double value = static_cast<double>(raw);
        if (s.isSigned && s.length < 64 && ((raw >> (s.length - 1)) & 1u))
            value -= std::ldexp(1.0, static_cast<int>(s.length));
        values[s.name] = value * s.factor + s.offset;
    }
    return values;
}

inline std::string readText(const std::filesystem::path& path) {
    std::ifstream in(path);
    std::stringstream text;
    text << in.rdbuf();
    return text.str();
}

} // namespace edgetrack::test
