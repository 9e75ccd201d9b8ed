// Disjoint sets (union-find) of fixed capacity: blobs, stereo blocks, cliques, model copies.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

namespace edgetrack {

/**
 * \brief Disjoint sets of the elements 0, 1, ..., size() - 1, at most capacity() of them.
 *
 * Storage is allocated once, at construction; reset() and add() never allocate, and add() past
 * the capacity is refused. The root of a set is its smallest element, so that sets come out in
 * the order of their first elements whatever order they were united in. find() halves the path
 * it walks.
 */
class DisjointSets {
public:
    explicit DisjointSets(std::size_t capacity)
        : parent_(capacity) {}

    std::size_t capacity() const { return parent_.size(); }
    std::size_t size() const { return size_; }

    /// \brief \a count elements (at most capacity()), each in a set of its own.
    void reset(std::size_t count) {
        size_ = count < parent_.size() ? count : parent_.size();
        for (std::size_t i = 0; i < size_; ++i)
            parent_[i] = static_cast<std::uint32_t>(i);
    }

    /// \brief One more element, in a set of its own.
    /// \return false when the sets already hold capacity() elements.
    bool add() {
        if (size_ == parent_.size())
            return false;
        parent_[size_] = static_cast<std::uint32_t>(size_);
        ++size_;
        return true;
    }

    /// \brief The root (smallest element) of \a element's set.
    std::size_t find(std::size_t element) {
        auto e = static_cast<std::uint32_t>(element);
        while (parent_[e] != e) {
            parent_[e] = parent_[parent_[e]];
            e = parent_[e];
        }
        return e;
    }

    /// \brief Whether \a element is the root of its set (no path is shortened).
    bool isRoot(std::size_t element) const { return parent_[element] == element; }

    /// \brief The sets of \a a and \a b made one.
    /// \return the root of the joined set.
    std::size_t unite(std::size_t a, std::size_t b) {
        const std::size_t ra = find(a), rb = find(b);
        if (ra == rb)
            return ra;
        const std::size_t keep = ra < rb ? ra : rb;
        parent_[ra < rb ? rb : ra] = static_cast<std::uint32_t>(keep);
        return keep;
    }

private:
    std::vector<std::uint32_t> parent_;
    std::size_t size_ = 0;
};

} // namespace edgetrack
