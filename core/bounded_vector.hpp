// Fixed-capacity vectors whose overflow is a counted, reported event, never undefined behaviour.
#pragma once

#include <array>
#include <cassert>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <utility>

namespace edgetrack {

/**
 * \brief Size-erased interface of a fixed-capacity vector (the ETL `ivector` idea).
 *
 * Functions take `BoundedVectorView<T>&` and work for any capacity, whether the storage lives
 * inline (FixedVector, capacity in the type) or was allocated once at start-up from the
 * configuration (BoundedVector). Adding past capacity does nothing, returns false and counts one
 * overflow; the owner reports overflowCount() in its status counters.
 *
 * Elements live in default-constructed storage and are assigned on insertion, so T must be
 * default-constructible and assignable (plain data records in practice).
 */
template <typename T>
class BoundedVectorView {
public:
    using value_type = T;
    using iterator = T*;
    using const_iterator = const T*;

    BoundedVectorView(const BoundedVectorView&) = delete;
    BoundedVectorView& operator=(const BoundedVectorView&) = delete;

    std::size_t size() const { return size_; }
    std::size_t capacity() const { return capacity_; }
    bool empty() const { return size_ == 0; }
    bool full() const { return size_ == capacity_; }

    T* data() { return data_; }
    const T* data() const { return data_; }
    T* begin() { return data_; }
    T* end() { return data_ + size_; }
    const T* begin() const { return data_; }
    const T* end() const { return data_ + size_; }

    T& operator[](std::size_t index) {
        assert(index < size_);
        return data_[index];
    }
    const T& operator[](std::size_t index) const {
        assert(index < size_);
        return data_[index];
    }
    T& back() {
        assert(size_ > 0);
        return data_[size_ - 1];
    }
    const T& back() const {
        assert(size_ > 0);
        return data_[size_ - 1];
    }

    std::span<T> span() { return {data_, size_}; }
    std::span<const T> span() const { return {data_, size_}; }

    /**
     * \brief Append a copy of \a value.
     * \return false, and one more overflow counted, when the vector is full.
     */
    bool push_back(const T& value) {
        if (full()) {
            ++overflowCount_;
            return false;
        }
        data_[size_++] = value;
        return true;
    }

    /**
     * \brief Append a default element and return it for filling in.
     * \return nullptr, and one more overflow counted, when the vector is full.
     */
    T* append() {
        if (full()) {
            ++overflowCount_;
            return nullptr;
        }
        data_[size_] = T{};
        return &data_[size_++];
    }

    void pop_back() {
        assert(size_ > 0);
        --size_;
    }

    /// \brief Remove the element at \a index by moving the last one into its place (O(1)).
    void swapRemove(std::size_t index) {
        assert(index < size_);
        data_[index] = std::move(data_[size_ - 1]);
        --size_;
    }

    void clear() { size_ = 0; }

    /**
     * \brief Shrink, or grow with default elements, to \a count.
     * \return false, with one overflow counted and the size set to capacity(), when count is too
     * large.
     */
    bool resize(std::size_t count) {
        bool fits = count <= capacity_;
        if (!fits) {
            ++overflowCount_;
            count = capacity_;
        }
        for (std::size_t i = size_; i < count; ++i)
            data_[i] = T{};
        size_ = count;
        return fits;
    }

    /// \return how many insertions were refused because the vector was full.
    std::uint64_t overflowCount() const { return overflowCount_; }
    void resetOverflowCount() { overflowCount_ = 0; }

protected:
    BoundedVectorView(T* storage, std::size_t capacity)
        : data_(storage)
        , capacity_(capacity) {}
    ~BoundedVectorView() = default;

    void copyContentFrom(const BoundedVectorView& other) {
        size_ = other.size_ < capacity_ ? other.size_ : capacity_;
        for (std::size_t i = 0; i < size_; ++i)
            data_[i] = other.data_[i];
        overflowCount_ = other.overflowCount_;
    }
    void swapState(BoundedVectorView& other) noexcept {
        std::swap(data_, other.data_);
        std::swap(size_, other.size_);
        std::swap(capacity_, other.capacity_);
        std::swap(overflowCount_, other.overflowCount_);
    }

private:
    T* data_;
    std::size_t size_ = 0;
    std::size_t capacity_;
    std::uint64_t overflowCount_ = 0;
};

namespace detail {
template <typename T, std::size_t N>
struct InlineStorage {
    std::array<T, N> items{};
};
} // namespace detail

/**
 * \brief Vector of at most N elements stored inline; no heap, ever.
 *
 * For bounds that are properties of the algorithm (a 4-clique, one SVD block), not of the
 * configuration.
 */
template <typename T, std::size_t N>
class FixedVector : private detail::InlineStorage<T, N>, public BoundedVectorView<T> {
    using Storage = detail::InlineStorage<T, N>;

public:
    FixedVector()
        : BoundedVectorView<T>(Storage::items.data(), N) {}
    FixedVector(const FixedVector& other)
        : Storage()
        , BoundedVectorView<T>(Storage::items.data(), N) {
        this->copyContentFrom(other);
    }
    FixedVector& operator=(const FixedVector& other) {
        if (this != &other)
            this->copyContentFrom(other);
        return *this;
    }
    ~FixedVector() = default;

    static constexpr std::size_t kCapacity = N;
};

/**
 * \brief Vector whose capacity is chosen at run time and allocated once, in the constructor.
 *
 * For capacities that come from the configuration (markers per frame, objects, blobs). It never
 * reallocates; after construction it touches no heap.
 */
template <typename T>
class BoundedVector : public BoundedVectorView<T> {
public:
    /// \brief An empty vector with capacity 0; assign a sized one before use.
    BoundedVector()
        : BoundedVectorView<T>(nullptr, 0) {}
    explicit BoundedVector(std::size_t capacity)
        : BoundedVector(std::make_unique<T[]>(capacity), capacity) {}
    BoundedVector(BoundedVector&& other) noexcept
        : BoundedVector() {
        swapWith(other);
    }
    BoundedVector& operator=(BoundedVector&& other) noexcept {
        if (this != &other) {
            BoundedVector emptied;
            swapWith(other);
            other.swapWith(emptied);
        }
        return *this;
    }
    ~BoundedVector() = default;

private:
    BoundedVector(std::unique_ptr<T[]> storage, std::size_t capacity)
        : BoundedVectorView<T>(storage.get(), capacity)
        , storage_(std::move(storage)) {}
    void swapWith(BoundedVector& other) noexcept {
        this->swapState(other);
        std::swap(storage_, other.storage_);
    }

    std::unique_ptr<T[]> storage_;
};

} // namespace edgetrack
