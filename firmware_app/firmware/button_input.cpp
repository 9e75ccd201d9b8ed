// Debouncing and press classification of the push button.
#include "firmware_app/firmware/button_input.hpp"

namespace edgetrack::app {

void ButtonInput::emit(ButtonEvent event) {
    // Four events between two polls would take a person pressing 50 times a second: the oldest
    // stays, later ones are dropped.
    if (pendingCount_ < pending_.size())
        pending_[pendingCount_++] = event;
}

void ButtonInput::settle(hal::Nanoseconds until) {
    if (raw_ != stable_ && until - rawSince_ >= debounce_) {
        stable_ = raw_;
        if (stable_) {
            pressedAt_ = rawSince_;
            longReported_ = false;
        } else if (!longReported_) {
            // A press held past the long-press time was reported when its release edge arrived.
            releaseShort(rawSince_);
        }
    }
    if (stable_ && !longReported_ && until - pressedAt_ >= longPress_) {
        longReported_ = true;
        // A short press waiting for a partner was just a short press, then came a long one.
        if (shortPending_) {
            shortPending_ = false;
            emit(ButtonEvent::ShortPress);
        }
        emit(ButtonEvent::LongPress);
    }
    // No second press within the window: the waiting press was a single one.
    if (shortPending_ && !stable_ && until - shortReleasedAt_ >= doublePress_) {
        shortPending_ = false;
        emit(ButtonEvent::ShortPress);
    }
}

void ButtonInput::releaseShort(hal::Nanoseconds releasedAt) {
    if (doublePress_ <= 0) {
        emit(ButtonEvent::ShortPress);
        return;
    }
    if (shortPending_ && pressedAt_ - shortReleasedAt_ <= doublePress_) {
        shortPending_ = false;
        emit(ButtonEvent::DoublePress);
        return;
    }
    shortPending_ = true;
    shortReleasedAt_ = releasedAt;
}

void ButtonInput::edge(const hal::ButtonEdge& edge) {
    settle(edge.time);
    if (edge.pressed != raw_) {
        raw_ = edge.pressed;
        rawSince_ = edge.time;
    }
}

ButtonEvent ButtonInput::poll(hal::Nanoseconds now) {
    settle(now);
    if (pendingCount_ == 0)
        return ButtonEvent::None;
    const ButtonEvent event = pending_[0];
    for (std::size_t i = 1; i < pendingCount_; ++i)
        pending_[i - 1] = pending_[i];
    --pendingCount_;
    return event;
}

} // namespace edgetrack::app
