// AllocationGuard: counts heap allocations (malloc family and operator new) while it is alive.
#include "tests/support/alloc_guard.hpp"

#include <atomic>
#include <cassert>
#include <cerrno>
#include <cstddef>

#include <Eigen/Core>

#if defined(__SANITIZE_ADDRESS__)
#define EDGETRACK_ALLOC_VIA_SANITIZER 1
// Part of the sanitizer runtime's public interface; GCC ships no header for it.
extern "C" int __sanitizer_install_malloc_and_free_hooks(void (*mallocHook)(const volatile void*,
                                                                            std::size_t),
                                                         void (*freeHook)(const volatile void*));
#else
#define EDGETRACK_ALLOC_VIA_SANITIZER 0
#endif

namespace {

std::atomic<bool> g_armed{false};
std::atomic<std::uint64_t> g_allocations{0};

inline void noteAllocation() {
    if (g_armed.load(std::memory_order_relaxed))
        g_allocations.fetch_add(1, std::memory_order_relaxed);
}

} // namespace

#if EDGETRACK_ALLOC_VIA_SANITIZER

namespace {
void onSanitizerMalloc(const volatile void*, std::size_t) {
    noteAllocation();
}
void onSanitizerFree(const volatile void*) {}

struct HookInstaller {
    HookInstaller() {
        __sanitizer_install_malloc_and_free_hooks(onSanitizerMalloc, onSanitizerFree);
    }
};
const HookInstaller g_hookInstaller;
} // namespace

#else

// Interpose the C allocator: definitions in the executable take precedence over glibc's for every
// caller, libstdc++'s operator new included. glibc's own entry points do the work. The noexcept
// matches glibc's declarations in C++.
extern "C" {
void* __libc_malloc(std::size_t size);
void* __libc_calloc(std::size_t count, std::size_t size);
void* __libc_realloc(void* pointer, std::size_t size);
void* __libc_memalign(std::size_t alignment, std::size_t size);
void __libc_free(void* pointer);

void* malloc(std::size_t size) noexcept {
    noteAllocation();
    return __libc_malloc(size);
}
void* calloc(std::size_t count, std::size_t size) noexcept {
    noteAllocation();
    return __libc_calloc(count, size);
}
void* realloc(void* pointer, std::size_t size) noexcept {
    noteAllocation();
    return __libc_realloc(pointer, size);
}
void free(void* pointer) noexcept {
    __libc_free(pointer);
}
void* memalign(std::size_t alignment, std::size_t size) noexcept {
    noteAllocation();
    return __libc_memalign(alignment, size);
}
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
    noteAllocation();
    return __libc_memalign(alignment, size);
}
int posix_memalign(void** result, std::size_t alignment, std::size_t size) noexcept {
    if (alignment < sizeof(void*) || (alignment & (alignment - 1)) != 0)
        return EINVAL;
    noteAllocation();
    void* pointer = __libc_memalign(alignment, size);
    if (pointer == nullptr)
        return ENOMEM;
    *result = pointer;
    return 0;
}
}

#endif

namespace edgetrack::test {

AllocationGuard::AllocationGuard() {
    const bool wasArmed = g_armed.exchange(true);
    assert(!wasArmed && "AllocationGuards do not nest");
    (void)wasArmed;
    g_allocations.store(0);
    Eigen::internal::set_is_malloc_allowed(false);
}

AllocationGuard::~AllocationGuard() {
    Eigen::internal::set_is_malloc_allowed(true);
    g_armed.store(false);
}

std::uint64_t AllocationGuard::allocations() const {
    return g_allocations.load();
}

bool countingThroughSanitizer() {
    return EDGETRACK_ALLOC_VIA_SANITIZER != 0;
}

} // namespace edgetrack::test
