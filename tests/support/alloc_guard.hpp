// AllocationGuard: counts heap allocations (malloc family and operator new) while it is alive.
#pragma once

#include <cstdint>

namespace edgetrack::test {

/**
 * \brief Counts every heap allocation made, by any thread, between construction and destruction.
 *
 * malloc, calloc, realloc, memalign, aligned_alloc, posix_memalign and operator new (which
 * allocates through malloc) are all counted. While armed, Eigen's EIGEN_RUNTIME_NO_MALLOC check is
 * on as well, so an Eigen heap allocation also fails an assertion in builds with assertions.
 * Guards do not nest.
 *
 * In sanitizer builds the sanitizer owns malloc, and the count comes from its allocation hook.
 */
class AllocationGuard {
public:
    AllocationGuard();
    ~AllocationGuard();
    AllocationGuard(const AllocationGuard&) = delete;
    AllocationGuard& operator=(const AllocationGuard&) = delete;

    /// \return the number of allocations since this guard was armed.
    std::uint64_t allocations() const;
};

/// \brief Run \a work under a guard and return how many allocations it made.
template <typename Work>
std::uint64_t countAllocations(Work&& work) {
    AllocationGuard guard;
    work();
    return guard.allocations();
}

/// \return true when allocations are counted by the sanitizer's hook rather than by interposition.
bool countingThroughSanitizer();

} // namespace edgetrack::test
