// Fixed-capacity FIFO queue: storage allocated once, drop-oldest or refuse when full, both counted.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <utility>

namespace edgetrack {

/**
 * \brief A first-in first-out queue of at most capacity() elements, allocated once.
 *
 * Two ways to add: tryPush() refuses when full (the caller keeps its element), pushDropOldest()
 * makes room by discarding the oldest element (a capture queue: the newest frame matters most).
 * Both count what they lose, for the status view.
 */
template <typename T>
class RingBuffer {
public:
    explicit RingBuffer(std::size_t capacity)
        : storage_(std::make_unique<T[]>(capacity))
        , capacity_(capacity) {}

    std::size_t size() const { return size_; }
    std::size_t capacity() const { return capacity_; }
    bool empty() const { return size_ == 0; }
    bool full() const { return size_ == capacity_; }

    /// \return false, with one refusal counted, when the queue is full.
    bool tryPush(const T& value) {
        if (full()) {
            ++refused_;
            return false;
        }
        storage_[(head_ + size_) % capacity_] = value;
        ++size_;
        return true;
    }

    /// \return true when the oldest element was dropped (and counted) to make room.
    bool pushDropOldest(const T& value) {
        if (capacity_ == 0) {
            ++dropped_;
            return true;
        }
        const bool drop = full();
        if (drop) {
            head_ = (head_ + 1) % capacity_;
            --size_;
            ++dropped_;
        }
        storage_[(head_ + size_) % capacity_] = value;
        ++size_;
        return drop;
    }

    /// \brief Move the oldest element into \a out. \return false when empty.
    bool pop(T& out) {
        if (empty())
            return false;
        out = std::move(storage_[head_]);
        head_ = (head_ + 1) % capacity_;
        --size_;
        return true;
    }

    /// \return the oldest element; the queue must not be empty.
    const T& front() const { return storage_[head_]; }
    /// \return the element \a index places after the oldest.
    const T& at(std::size_t index) const { return storage_[(head_ + index) % capacity_]; }

    void clear() {
        head_ = 0;
        size_ = 0;
    }

    std::uint64_t droppedCount() const { return dropped_; }
    std::uint64_t refusedCount() const { return refused_; }

private:
    std::unique_ptr<T[]> storage_;
    std::size_t capacity_;
    std::size_t head_ = 0;
    std::size_t size_ = 0;
    std::uint64_t dropped_ = 0;
    std::uint64_t refused_ = 0;
};

} // namespace edgetrack
