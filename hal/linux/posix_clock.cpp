// Linux backend: the board's clock on CLOCK_MONOTONIC, wall time from CLOCK_REALTIME.
#include "hal/linux/posix_clock.hpp"

#include <cerrno>
#include <ctime>

namespace edgetrack::linux_hal {

namespace {
hal::Nanoseconds read(clockid_t clock) {
    timespec now{};
    clock_gettime(clock, &now);
    return static_cast<hal::Nanoseconds>(now.tv_sec) * hal::kNanosecondsPerSecond + now.tv_nsec;
}
} // namespace

hal::Nanoseconds PosixClock::now() const {
    return read(CLOCK_MONOTONIC);
}

void PosixClock::sleepUntil(hal::Nanoseconds deadline) {
    timespec until{};
    until.tv_sec = static_cast<time_t>(deadline / hal::kNanosecondsPerSecond);
    until.tv_nsec = static_cast<long>(deadline % hal::kNanosecondsPerSecond);
    // A signal (SIGUSR1 for the status view) interrupts the sleep; the deadline stays the same.
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &until, nullptr) == EINTR) {
    }
}

hal::Nanoseconds PosixClock::utcOffset() const {
    // Read monotonic on both sides of the wall clock: the offset is good to their difference.
    const hal::Nanoseconds before = read(CLOCK_MONOTONIC);
    const hal::Nanoseconds wall = read(CLOCK_REALTIME);
    const hal::Nanoseconds after = read(CLOCK_MONOTONIC);
    return wall - (before + (after - before) / 2);
}

} // namespace edgetrack::linux_hal
