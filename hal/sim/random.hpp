// Deterministic random numbers for the simulator: the same seed gives the same bytes.
#pragma once

#include <cmath>
#include <cstdint>
#include <numbers>

namespace edgetrack::sim {

/**
 * \brief xoshiro256** seeded through SplitMix64, with uniform and normal draws.
 *
 * Written out rather than taken from <random> so that the distributions, not only the engine, are
 * fixed: std::normal_distribution may differ between standard libraries.
 */
class Random {
public:
    explicit Random(std::uint64_t seed) {
        for (auto& word : state_) {
            seed += 0x9E3779B97F4A7C15ull;
            std::uint64_t z = seed;
            z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
            z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
            word = z ^ (z >> 31);
        }
    }

    std::uint64_t next() {
        const std::uint64_t result = rotl(state_[1] * 5, 7) * 9;
        const std::uint64_t t = state_[1] << 17;
        state_[2] ^= state_[0];
        state_[3] ^= state_[1];
        state_[1] ^= state_[2];
        state_[0] ^= state_[3];
        state_[2] ^= t;
        state_[3] = rotl(state_[3], 45);
        return result;
    }

    /// \return uniform in [0, 1).
    double uniform() { return static_cast<double>(next() >> 11) * 0x1.0p-53; }
    double uniform(double low, double high) { return low + (high - low) * uniform(); }
    /// \return uniform integer in [0, count).
    std::uint64_t below(std::uint64_t count) { return count == 0 ? 0 : next() % count; }
    bool chance(double probability) { return uniform() < probability; }

    /// \return standard normal (Box-Muller; the second value is kept for the next call).
    double normal() {
        if (haveSpare_) {
            haveSpare_ = false;
            return spare_;
        }
        double u1 = uniform();
        while (u1 <= 0.0)
            u1 = uniform();
        const double u2 = uniform();
        const double radius = std::sqrt(-2.0 * std::log(u1));
        spare_ = radius * std::sin(2.0 * std::numbers::pi * u2);
        haveSpare_ = true;
        return radius * std::cos(2.0 * std::numbers::pi * u2);
    }
    double normal(double sigma) { return sigma * normal(); }

private:
    static std::uint64_t rotl(std::uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }

    std::uint64_t state_[4]{};
    double spare_ = 0.0;
    bool haveSpare_ = false;
};

} // namespace edgetrack::sim
