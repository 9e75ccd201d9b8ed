// A set of up to 128 marker indices in two machine words: the adjacency rows of calibration graphs.
#pragma once

#include <array>
#include <bit>
#include <cstddef>
#include <cstdint>

namespace edgetrack {

/**
 * \brief Bit set of marker indices 0..127 (members of one object graph).
 *
 * Clique search and clustering work on whole rows at once: an intersection of neighbourhoods is
 * two ANDs, a size two popcounts. The bound of 128 markers per object is a property of this type;
 * the configured capacity must not exceed kCapacity (the calibrator checks it at construction).
 */
class MarkerSet {
public:
    static constexpr std::size_t kCapacity = 128;

    constexpr MarkerSet() = default;

    /// \brief The set {0, 1, ..., count - 1}.
    static constexpr MarkerSet firstN(std::size_t count) {
        MarkerSet s;
        for (std::size_t w = 0; w < kWords; ++w) {
            const std::size_t start = w * 64;
            if (count >= start + 64)
                s.words_[w] = ~std::uint64_t{0};
            else if (count > start)
                s.words_[w] = (std::uint64_t{1} << (count - start)) - 1;
        }
        return s;
    }

    constexpr void insert(std::size_t index) { words_[index >> 6] |= bit(index); }
    constexpr void erase(std::size_t index) { words_[index >> 6] &= ~bit(index); }
    constexpr bool contains(std::size_t index) const {
        return (words_[index >> 6] & bit(index)) != 0;
    }
    constexpr bool empty() const { return (words_[0] | words_[1]) == 0; }
    constexpr std::size_t size() const {
        return static_cast<std::size_t>(std::popcount(words_[0]) + std::popcount(words_[1]));
    }
    /// \return the smallest index in the set; the set must not be empty.
    constexpr std::size_t first() const {
        return words_[0] != 0 ? static_cast<std::size_t>(std::countr_zero(words_[0]))
                              : 64 + static_cast<std::size_t>(std::countr_zero(words_[1]));
    }
    constexpr std::size_t popFirst() {
        const std::size_t index = first();
        erase(index);
        return index;
    }

    constexpr MarkerSet operator&(const MarkerSet& o) const {
        return MarkerSet(words_[0] & o.words_[0], words_[1] & o.words_[1]);
    }
    constexpr MarkerSet operator|(const MarkerSet& o) const {
        return MarkerSet(words_[0] | o.words_[0], words_[1] | o.words_[1]);
    }
    /// \return the elements of this set that are not in \a o.
    constexpr MarkerSet minus(const MarkerSet& o) const {
        return MarkerSet(words_[0] & ~o.words_[0], words_[1] & ~o.words_[1]);
    }
    constexpr MarkerSet& operator|=(const MarkerSet& o) {
        words_[0] |= o.words_[0];
        words_[1] |= o.words_[1];
        return *this;
    }
    constexpr bool isSubsetOf(const MarkerSet& o) const { return minus(o).empty(); }
    constexpr bool operator==(const MarkerSet&) const = default;

    /// \brief Call \a visit(index) for every element, smallest first.
    template <typename Visit>
    constexpr void forEach(Visit&& visit) const {
        for (std::size_t w = 0; w < kWords; ++w)
            for (std::uint64_t bits = words_[w]; bits != 0; bits &= bits - 1)
                visit(w * 64 + static_cast<std::size_t>(std::countr_zero(bits)));
    }

private:
    static constexpr std::size_t kWords = 2;
    constexpr MarkerSet(std::uint64_t low, std::uint64_t high)
        : words_{low, high} {}
    static constexpr std::uint64_t bit(std::size_t index) {
        return std::uint64_t{1} << (index & 63);
    }

    std::array<std::uint64_t, kWords> words_{};
};

} // namespace edgetrack
