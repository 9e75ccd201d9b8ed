// DTrack ASCII frames: a fixed-buffer writer for the frame loop and a strict reader for tests.
#include "firmware_app/firmware/dtrack.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <string>

namespace edgetrack::app {

namespace {

/// Appends to a fixed buffer; remembers when something did not fit.
class Appender {
public:
    explicit Appender(std::span<char> out)
        : out_(out) {}

    // The attribute lets the compiler check every format against its arguments.
    __attribute__((format(printf, 2, 3))) void print(const char* format, ...) {
        if (failed_)
            return;
        const std::size_t room = out_.size() - used_;
        std::va_list args;
        va_start(args, format);
        const int n = std::vsnprintf(out_.data() + used_, room, format, args);
        va_end(args);
        if (n < 0 || static_cast<std::size_t>(n) >= room) {
            failed_ = true;
            return;
        }
        used_ += static_cast<std::size_t>(n);
    }
    std::size_t length() const { return failed_ ? 0 : used_; }

private:
    std::span<char> out_;
    std::size_t used_ = 0;
    bool failed_ = false;
};

} // namespace

std::uint32_t dtrackCalibratedCount(std::span<const NamedModel> models) {
    std::uint32_t count = 0;
    for (const NamedModel& m : models)
        count = std::max(count, m.model.id + 1);
    return count;
}

std::size_t formatDtrack(const DtrackFrame& frame, std::span<char> out) {
    Appender a(out);
    constexpr std::int64_t kNanosPerSecond = 1'000'000'000;
    constexpr std::int64_t kNanosPerDay = 86'400 * kNanosPerSecond;
    const std::int64_t sinceMidnight_ns =
        ((frame.midExposureUtc_ns % kNanosPerDay) + kNanosPerDay) % kNanosPerDay;
    a.print("fr %llu\r\n", static_cast<unsigned long long>(frame.frame));
    // Whole microseconds, rounded down as in ts2, so that the two name the same instant.
    const std::int64_t sinceMidnight_us = sinceMidnight_ns / 1000;
    a.print("ts %lld.%06lld\r\n", static_cast<long long>(sinceMidnight_us / 1'000'000),
            static_cast<long long>(sinceMidnight_us % 1'000'000));
    if (frame.latency_s) {
        // Whole microseconds, rounded down, so that seconds and microseconds stay one instant.
        const std::int64_t utc_us = frame.midExposureUtc_ns / 1000;
        const double latency_us = std::clamp(*frame.latency_s * 1e6, 0.0, 4294967295.0);
        a.print("ts2 %lld %lld %lu\r\n", static_cast<long long>(utc_us / 1'000'000),
                static_cast<long long>(utc_us % 1'000'000),
                static_cast<unsigned long>(std::lround(latency_us)));
    }
    a.print("6dcal %u\r\n", frame.calibrated);
    a.print("6d %zu", frame.bodies.size());
    for (const DtrackBody& body : frame.bodies) {
        const Vec3& t = body.T_rig_from_model.translation_mm;
        const Mat3 r = body.T_rig_from_model.rotationMatrix();
        a.print(" [%u %.3f][%.3f %.3f %.3f]", body.id, body.quality, t.x(), t.y(), t.z());
        // Column-wise: r0 r1 r2 is the first column.
        a.print("[%.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f %.6f]", r(0, 0), r(1, 0), r(2, 0),
                r(0, 1), r(1, 1), r(2, 1), r(0, 2), r(1, 2), r(2, 2));
    }
    a.print("\r\n");
    a.print("3d %zu", frame.markers.size());
    for (const DtrackMarker& m : frame.markers)
        a.print(" [%u %.3f][%.3f %.3f %.3f]", m.id, m.quality, m.position_mm.x(), m.position_mm.y(),
                m.position_mm.z());
    a.print("\r\n");
    return a.length();
}

Result<ParsedDtrack> parseDtrack(std::string_view datagram) {
    ParsedDtrack parsed;
    bool haveFrame = false;
    std::size_t start = 0;
    while (start < datagram.size()) {
        const std::size_t end = datagram.find("\r\n", start);
        if (end == std::string_view::npos)
            return Error{"dtrack: line without CRLF at byte " + std::to_string(start)};
        const std::string line(datagram.substr(start, end - start));
        start = end + 2;
        const char* c = line.c_str();
        char* next = nullptr;
        auto number = [&](double& value) {
            while (*c == ' ' || *c == '[' || *c == ']')
                ++c;
            value = std::strtod(c, &next);
            if (next == c)
                return false;
            c = next;
            return true;
        };
        // A count or an id: a whole number a std::uint32_t holds (a cast of any other double is
        // undefined behaviour).
        auto whole = [](double x, std::uint32_t& out) {
            if (!(x >= 0.0 && x <= 4294967295.0 && x == std::floor(x)))
                return false;
            out = static_cast<std::uint32_t>(x);
            return true;
        };
        if (line.rfind("fr ", 0) == 0) {
            parsed.frame = std::strtoull(c + 3, nullptr, 10);
            haveFrame = true;
        } else if (line.rfind("ts ", 0) == 0) {
            parsed.timestamp_s = std::strtod(c + 3, nullptr);
        } else if (line.rfind("6dcal ", 0) == 0) {
            parsed.calibrated = static_cast<std::uint32_t>(std::strtoul(c + 6, nullptr, 10));
        } else if (line.rfind("6d ", 0) == 0) {
            c += 3;
            double countValue = 0.0;
            std::uint32_t count = 0;
            if (!number(countValue) || !whole(countValue, count))
                return Error{"dtrack: 6d without a count"};
            for (std::uint32_t b = 0; b < count; ++b) {
                std::array<double, 14> v{};
                for (double& x : v)
                    if (!number(x))
                        return Error{"dtrack: 6d body " + std::to_string(b) + " is short"};
                DtrackBody body;
                if (!whole(v[0], body.id))
                    return Error{"dtrack: 6d body " + std::to_string(b) + " has no id"};
                body.quality = v[1];
                Mat3 r;
                r << v[5], v[8], v[11], v[6], v[9], v[12], v[7], v[10], v[13];
                if (!((r * r.transpose() - Mat3::Identity()).norm() < 1e-4) ||
                    !(std::abs(r.determinant() - 1.0) < 1e-4))
                    return Error{"dtrack: 6d body " + std::to_string(b) +
                                 " has no rotation matrix"};
                body.T_rig_from_model = RigidTransform::fromMatrix(r, Vec3(v[2], v[3], v[4]));
                parsed.bodies.push_back(body);
            }
        } else if (line.rfind("3d ", 0) == 0) {
            c += 3;
            parsed.hasMarkerLine = true;
            double countValue = 0.0;
            std::uint32_t count = 0;
            if (!number(countValue) || !whole(countValue, count))
                return Error{"dtrack: 3d without a count"};
            for (std::uint32_t m = 0; m < count; ++m) {
                std::array<double, 5> v{};
                for (double& x : v)
                    if (!number(x))
                        return Error{"dtrack: 3d marker " + std::to_string(m) + " is short"};
                std::uint32_t id = 0;
                if (!whole(v[0], id))
                    return Error{"dtrack: 3d marker " + std::to_string(m) + " has no id"};
                parsed.markers.push_back({id, v[1], Vec3(v[2], v[3], v[4])});
            }
        } else if (line.rfind("ts2 ", 0) == 0) {
            // Three unsigned integers, as DTrackSDK reads them.
            c += 4;
            std::array<unsigned long long, 3> v{};
            for (unsigned long long& x : v) {
                while (*c == ' ')
                    ++c;
                if (*c < '0' || *c > '9')
                    return Error{"dtrack: ts2 needs seconds, microseconds and latency"};
                x = std::strtoull(c, &next, 10);
                c = next;
            }
            if (v[1] >= 1'000'000 || v[2] > 0xFFFFFFFFull)
                return Error{"dtrack: ts2 is out of range"};
            parsed.ts2 =
                DtrackTs2{v[0], static_cast<std::uint32_t>(v[1]), static_cast<std::uint32_t>(v[2])};
        }
    }
    if (!haveFrame)
        return Error{"dtrack: no fr line"};
    return parsed;
}

} // namespace edgetrack::app
