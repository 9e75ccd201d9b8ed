// Linux backend: the LED ring strobe, push button and status LED on GPIO lines through libgpiod.
#include "hal/linux/gpiod_devices.hpp"

#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <gpiod.h>
#include <poll.h>
#include <pthread.h>
#include <sched.h>

namespace edgetrack::linux_hal {

namespace {

constexpr const char* kConsumer = "edgetrack";
/// A line that could not be had is asked for again this often.
constexpr hal::Nanoseconds kRetryInterval = hal::kNanosecondsPerSecond;

bool isOffset(const std::string& text) {
    return !text.empty() && text.find_first_not_of("0123456789") == std::string::npos;
}

} // namespace

// ---------------------------------------------------------------------------------------------
// GpiodLine

GpiodLine::GpiodLine(const GpioLineAddress& address, Direction direction, bool activeLow)
    : address_(address)
    , direction_(direction)
    , activeLow_(activeLow) {
    request();
}

GpiodLine::~GpiodLine() {
    release();
}

bool GpiodLine::request() {
    const std::string where = address_.chip + " line \"" + address_.line + "\"";
    chip_ = address_.chip.starts_with('/') ? gpiod_chip_open(address_.chip.c_str())
                                           : gpiod_chip_open_by_name(address_.chip.c_str());
    if (chip_ == nullptr) {
        errorText_ = "GPIO chip " + address_.chip + ": " + std::strerror(errno);
        return false;
    }
    gpiod_line* line =
        isOffset(address_.line)
            ? gpiod_chip_get_line(
                  chip_, static_cast<unsigned>(std::strtoul(address_.line.c_str(), nullptr, 10)))
            : gpiod_chip_find_line(chip_, address_.line.c_str());
    if (line == nullptr) {
        errorText_ = where + ": no such line (gpioinfo " + address_.chip + " lists them)";
        release();
        return false;
    }
    int flags = activeLow_ ? GPIOD_LINE_REQUEST_FLAG_ACTIVE_LOW : 0;
    int status = 0;
    if (direction_ == Direction::Output) {
        status = gpiod_line_request_output_flags(line, kConsumer, flags, 0);
    } else {
        // A released button leaves the line to the bias: up when it pulls low, down otherwise.
        flags |= activeLow_ ? GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_UP
                            : GPIOD_LINE_REQUEST_FLAG_BIAS_PULL_DOWN;
        status = gpiod_line_request_both_edges_events_flags(line, kConsumer, flags);
    }
    if (status != 0) {
        const int error = errno;
        const char* holder = gpiod_line_consumer(line);
        errorText_ = where + ": " + std::strerror(error);
        if (error == EBUSY && holder != nullptr)
            errorText_ += std::string(" (held by \"") + holder + "\")";
        release();
        return false;
    }
    line_ = line;
    errorText_.clear();
    return true;
}

void GpiodLine::release() {
    if (line_ != nullptr)
        gpiod_line_release(line_);
    line_ = nullptr;
    if (chip_ != nullptr)
        gpiod_chip_close(chip_);
    chip_ = nullptr;
}

bool GpiodLine::retryIfDue(hal::Nanoseconds now) {
    if (available() || now < nextRetry_)
        return false;
    nextRetry_ = now + kRetryInterval;
    release();
    return request();
}

bool GpiodLine::set(bool on) {
    return line_ != nullptr && gpiod_line_set_value(line_, on ? 1 : 0) == 0;
}

int GpiodLine::eventFd() const {
    return line_ != nullptr ? gpiod_line_event_get_fd(line_) : -1;
}

bool GpiodLine::readEdge(hal::ButtonEdge& edge) {
    const int fd = eventFd();
    if (fd < 0)
        return false;
    pollfd ready{fd, POLLIN, 0};
    if (::poll(&ready, 1, 0) != 1 || (ready.revents & POLLIN) == 0)
        return false;
    gpiod_line_event event{};
    if (gpiod_line_event_read_fd(fd, &event) != 0)
        return false;
    // The kernel stamps line events on CLOCK_MONOTONIC, the board clock's time base.
    edge.time = static_cast<hal::Nanoseconds>(event.ts.tv_sec) * hal::kNanosecondsPerSecond +
                event.ts.tv_nsec;
    // Edges are of the logical level: with active-low, pressing (line low) is a rising edge.
    edge.pressed = event.event_type == GPIOD_LINE_EVENT_RISING_EDGE;
    return true;
}

// ---------------------------------------------------------------------------------------------
// GpiodLedRing

GpiodLedRing::GpiodLedRing(const GpioLineAddress& address, const hal::Clock& clock,
                           std::size_t pulseQueueDepth, int realtimePriority)
    : clock_(clock)
    , line_(address, GpiodLine::Direction::Output, false)
    , pulses_(pulseQueueDepth) {
    thread_ = std::thread([this] { run(); });
    sched_param priority{};
    priority.sched_priority = realtimePriority;
    const int status = pthread_setschedparam(thread_.native_handle(), SCHED_FIFO, &priority);
    std::lock_guard lock(mutex_);
    schedulingNote_ =
        status == 0 ? "SCHED_FIFO " + std::to_string(realtimePriority)
                    : std::string("normal priority (SCHED_FIFO: ") + std::strerror(status) + ")";
}

GpiodLedRing::~GpiodLedRing() {
    {
        std::lock_guard lock(mutex_);
        stopping_ = true;
    }
    wake_.notify_all();
    thread_.join();
    line_.set(false);
}

void GpiodLedRing::retryIfDue(hal::Nanoseconds now) {
    if (line_.retryIfDue(now))
        line_.set(continuous_);
}

void GpiodLedRing::setContinuous(bool on) {
    std::lock_guard lock(mutex_);
    continuous_ = on;
    retryIfDue(clock_.now());
    line_.set(on);
}

bool GpiodLedRing::schedulePulse(hal::Nanoseconds onAt, hal::Nanoseconds offAt) {
    {
        std::lock_guard lock(mutex_);
        if (!pulses_.tryPush(Pulse{onAt, offAt})) {
            ++dropped_;
            return false;
        }
    }
    wake_.notify_one();
    return true;
}

std::uint64_t GpiodLedRing::droppedPulses() const {
    std::lock_guard lock(mutex_);
    return dropped_;
}

bool GpiodLedRing::available() const {
    std::lock_guard lock(mutex_);
    return line_.available();
}

std::string GpiodLedRing::errorText() const {
    std::lock_guard lock(mutex_);
    return line_.errorText();
}

StrobeCounters GpiodLedRing::strobeCounters() const {
    std::lock_guard lock(mutex_);
    return counters_;
}

std::string GpiodLedRing::schedulingNote() const {
    std::lock_guard lock(mutex_);
    return schedulingNote_;
}

void GpiodLedRing::run() {
    // libstdc++'s steady_clock is CLOCK_MONOTONIC: pulse times convert one to one, and a timed
    // wait on the condition variable (unlike a plain sleep) ends at once when the ring is closed.
    const auto at = [](hal::Nanoseconds t) {
        return std::chrono::steady_clock::time_point(std::chrono::nanoseconds(t));
    };
    const auto stopping = [this] { return stopping_; };
    std::unique_lock lock(mutex_);
    for (;;) {
        wake_.wait(lock, [&] { return stopping_ || !pulses_.empty(); });
        if (stopping_)
            return;
        Pulse pulse;
        pulses_.pop(pulse);
        ++counters_.pulses;
        retryIfDue(clock_.now());
        if (!line_.available()) {
            ++counters_.lineUnavailable;
            continue;
        }
        if (continuous_)
            continue;
        if (clock_.now() >= pulse.offAt) {
            ++counters_.missed;
            continue;
        }
        if (wake_.wait_until(lock, at(pulse.onAt), stopping))
            return;
        const bool lit = !continuous_ && line_.set(true);
        const hal::Nanoseconds latency = clock_.now() - pulse.onAt;
        const bool stop = wake_.wait_until(lock, at(pulse.offAt), stopping);
        if (lit && !continuous_)
            line_.set(false);
        if (stop)
            return;
        if (latency > counters_.worstLatency_ns)
            counters_.worstLatency_ns = latency;
        if (latency > (pulse.offAt - pulse.onAt) / 2)
            ++counters_.late;
    }
}

// ---------------------------------------------------------------------------------------------
// GpiodButton and GpiodStatusLed

GpiodButton::GpiodButton(const GpioLineAddress& address, const hal::Clock& clock, bool activeLow)
    : clock_(clock)
    , line_(address, GpiodLine::Direction::BothEdges, activeLow) {}

bool GpiodButton::nextEdge(hal::ButtonEdge& edge) {
    if (!line_.available() && !line_.retryIfDue(clock_.now()))
        return false;
    return line_.readEdge(edge);
}

GpiodStatusLed::GpiodStatusLed(const GpioLineAddress& address, const hal::Clock& clock)
    : clock_(clock)
    , line_(address, GpiodLine::Direction::Output, false) {}

void GpiodStatusLed::set(bool on) {
    if (!line_.available()) {
        if (!line_.retryIfDue(clock_.now()))
            return;
        written_ = false;
    }
    if (written_ && on == level_)
        return;
    written_ = line_.set(on);
    level_ = on;
}

} // namespace edgetrack::linux_hal
