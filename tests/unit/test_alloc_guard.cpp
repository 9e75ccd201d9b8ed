// Tests of the allocation guard: it must catch every kind of heap allocation, and nothing else.
#include <cstdlib>
#include <vector>

#include <Eigen/Core>
#include <gtest/gtest.h>

#include "core/bounded_vector.hpp"
#include "core/correspondence.hpp"
#include "tests/support/alloc_guard.hpp"

using edgetrack::test::AllocationGuard;
using edgetrack::test::countAllocations;

namespace {
// Escapes pointers so the compiler cannot elide a new/delete pair.
void* volatile g_sink = nullptr;
} // namespace

TEST(AllocationGuard, CountsOperatorNew) {
    int* p = nullptr;
    const auto count = countAllocations([&] {
        p = new int(7);
        g_sink = p;
    });
    delete p;
    EXPECT_EQ(count, 1u);
}

TEST(AllocationGuard, CountsMallocCallocRealloc) {
    void* a = nullptr;
    void* b = nullptr;
    const auto count = countAllocations([&] {
        a = std::malloc(64);
        g_sink = a;
        b = std::calloc(4, 16);
        g_sink = b;
        a = std::realloc(a, 4096);
        g_sink = a;
    });
    std::free(a);
    std::free(b);
    EXPECT_EQ(count, 3u);
}

TEST(AllocationGuard, CountsAlignedAllocation) {
    void* p = nullptr;
    const auto count = countAllocations([&] {
        p = std::aligned_alloc(64, 256);
        g_sink = p;
    });
    std::free(p);
    EXPECT_EQ(count, 1u);
}

TEST(AllocationGuard, CountsStandardContainers) {
    std::vector<int> grown;
    const auto count = countAllocations([&] {
        for (int i = 0; i < 100; ++i)
            grown.push_back(i);
    });
    EXPECT_GT(count, 0u);
}

TEST(AllocationGuard, CountsEigenDynamicMatrices) {
    // With assertions on, EIGEN_RUNTIME_NO_MALLOC aborts; the count is checked in either build.
#ifdef NDEBUG
    const auto count = countAllocations([] {
        Eigen::MatrixXd m = Eigen::MatrixXd::Random(50, 50);
        g_sink = m.data();
    });
    EXPECT_GT(count, 0u);
#else
    GTEST_FLAG_SET(death_test_style, "threadsafe");
    EXPECT_DEATH(
        {
            AllocationGuard guard;
            Eigen::MatrixXd m = Eigen::MatrixXd::Random(50, 50);
            g_sink = m.data();
        },
        "heap allocation is forbidden");
#endif
}

TEST(AllocationGuard, FixedSizeWorkDoesNotAllocate) {
    edgetrack::BoundedVector<double> preallocated(256);
    const auto count = countAllocations([&] {
        // The correspondence SVD on a matrix of fixed maximum size, as every frame runs it.
        edgetrack::ProximityBlock proximity(6, 5);
        proximity.setRandom();
        edgetrack::SlhSolver solver;
        solver.solve(proximity.cwiseAbs(), 0.0,
                     [&](int row, int) { preallocated.push_back(static_cast<double>(row)); });
    });
    EXPECT_EQ(count, 0u);
    EXPECT_GT(preallocated.size(), 0u);
}

TEST(AllocationGuard, CountsOnlyWhileArmed) {
    std::vector<int> before(10);
    const auto count = countAllocations([] {});
    std::vector<int> after(10);
    EXPECT_EQ(count, 0u);
}
