// Linux backend: the LED ring strobe, push button and status LED on GPIO lines through libgpiod.
#pragma once

#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <string>
#include <thread>

#include "core/ring_buffer.hpp"
#include "hal/button.hpp"
#include "hal/clock.hpp"
#include "hal/led_ring.hpp"
#include "hal/status_led.hpp"

struct gpiod_chip;
struct gpiod_line;

namespace edgetrack::linux_hal {

/// \brief Where a line is: a gpiochip (name as gpiodetect prints it, or a /dev path) and the
/// line's name as gpioinfo prints it (or its offset in decimal).
struct GpioLineAddress {
    std::string chip = "gpiochip0";
    std::string line;
};

/**
 * \brief One GPIO line requested by edgetrack through libgpiod's v1 API (Debian 12 ships 1.6).
 *
 * A line that cannot be had now (no such chip or line, or EBUSY: another program holds it) leaves
 * the object unavailable with the reason in errorText(); retryIfDue() asks again at most once a
 * second, so a line released by its other user is taken over without a restart. The line is
 * released in the destructor.
 */
class GpiodLine {
public:
    enum class Direction { Output, BothEdges };

    GpiodLine(const GpioLineAddress& address, Direction direction, bool activeLow);
    ~GpiodLine();
    GpiodLine(const GpiodLine&) = delete;
    GpiodLine& operator=(const GpiodLine&) = delete;

    bool available() const { return line_ != nullptr; }
    /// \return why the line is unavailable (empty when it is available).
    const std::string& errorText() const { return errorText_; }
    /// \brief Ask again for an unavailable line, at most once a second.
    /// \return true when the line was unavailable and has just been taken.
    bool retryIfDue(hal::Nanoseconds now);

    /// \brief Drive an output line (logical level). \return false when the write failed.
    bool set(bool on);
    /// \return the file descriptor that becomes readable on an edge, or -1.
    int eventFd() const;
    /// \brief Read one pending edge without blocking. \return false when there is none.
    bool readEdge(hal::ButtonEdge& edge);

private:
    bool request();
    void release();

    GpioLineAddress address_;
    Direction direction_;
    bool activeLow_;
    hal::Nanoseconds nextRetry_ = 0;
    gpiod_chip* chip_ = nullptr;
    gpiod_line* line_ = nullptr;
    std::string errorText_;
};

/// \brief What the strobe thread did; read with GpiodLedRing::strobeCounters().
struct StrobeCounters {
    std::uint64_t pulses = 0;
    /// Pulses whose start had passed when the thread got to them: lit late, for what was left.
    std::uint64_t late = 0;
    /// Pulses whose end had passed: skipped.
    std::uint64_t missed = 0;
    /// Pulses while the line was unavailable.
    std::uint64_t lineUnavailable = 0;
    /// Worst delay of a rising edge after its scheduled time (ns).
    std::int64_t worstLatency_ns = 0;
};

/**
 * \brief The IR LED ring on one output line, strobed by a thread of its own.
 *
 * schedulePulse() only queues (never blocks the frame loop); the strobe thread waits until each
 * pulse's start on CLOCK_MONOTONIC (the clock of the sensors' timestamps), raises the line,
 * waits until its end and lowers it. The thread asks for SCHED_FIFO so that its wake-ups are not
 * delayed behind the pipeline; without the privilege it runs at normal priority and says so in
 * schedulingNote(). Continuous light overrides pulses.
 */
class GpiodLedRing : public hal::LedRing {
public:
    GpiodLedRing(const GpioLineAddress& address, const hal::Clock& clock,
                 std::size_t pulseQueueDepth = 8, int realtimePriority = 50);
    ~GpiodLedRing() override;
    GpiodLedRing(const GpiodLedRing&) = delete;
    GpiodLedRing& operator=(const GpiodLedRing&) = delete;

    void setContinuous(bool on) override;
    bool schedulePulse(hal::Nanoseconds onAt, hal::Nanoseconds offAt) override;
    std::uint64_t droppedPulses() const override;

    bool available() const;
    std::string errorText() const;
    StrobeCounters strobeCounters() const;
    /// \return how the strobe thread is scheduled ("SCHED_FIFO 50" or why not).
    std::string schedulingNote() const;

private:
    struct Pulse {
        hal::Nanoseconds onAt = 0, offAt = 0;
    };
    void run();
    /// \brief Take the line again if it was lost and the retry is due; restore its level.
    void retryIfDue(hal::Nanoseconds now);

    const hal::Clock& clock_;
    mutable std::mutex mutex_;
    std::condition_variable wake_;
    GpiodLine line_;
    RingBuffer<Pulse> pulses_;
    bool continuous_ = false;
    bool stopping_ = false;
    std::uint64_t dropped_ = 0;
    StrobeCounters counters_{};
    std::string schedulingNote_;
    std::thread thread_;
};

/**
 * \brief The push button on an input line with edge events (both edges).
 *
 * Raw edges with the kernel's timestamps (CLOCK_MONOTONIC); debouncing and press lengths are the
 * firmware's (button_input.hpp). \a activeLow: the button pulls the line low when pressed (the
 * usual wiring, with the line's pull-up bias requested); otherwise it drives the line high (with
 * a pull-down requested). `[gpio] button_active_low` chooses.
 */
class GpiodButton : public hal::Button {
public:
    GpiodButton(const GpioLineAddress& address, const hal::Clock& clock, bool activeLow = true);

    bool nextEdge(hal::ButtonEdge& edge) override;

    bool available() const { return line_.available(); }
    const std::string& errorText() const { return line_.errorText(); }

private:
    const hal::Clock& clock_;
    GpiodLine line_;
};

/// \brief The status LED on an output line; writes only on a change of level.
class GpiodStatusLed : public hal::StatusLed {
public:
    GpiodStatusLed(const GpioLineAddress& address, const hal::Clock& clock);

    void set(bool on) override;

    bool available() const { return line_.available(); }
    const std::string& errorText() const { return line_.errorText(); }

private:
    const hal::Clock& clock_;
    GpiodLine line_;
    bool level_ = false;
    bool written_ = false;
};

} // namespace edgetrack::linux_hal
