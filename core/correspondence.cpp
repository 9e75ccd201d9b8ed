// Scott and Longuet-Higgins correspondence (SVD of a proximity matrix), solved per independent
// block.
#include "core/correspondence.hpp"

#include <algorithm>

namespace edgetrack {

namespace {
constexpr std::size_t idx(int i) {
    return static_cast<std::size_t>(i);
}
} // namespace

const ProximityBlock& SlhSolver::orthogonalFactor(const ProximityBlock& proximity) {
    svd_.compute(proximity, Eigen::ComputeThinU | Eigen::ComputeThinV);
    orthogonal_.noalias() = svd_.matrixU() * svd_.matrixV().transpose();
    return orthogonal_;
}

BipartiteBlocks::BipartiteBlocks(std::size_t maxLeft, std::size_t maxRight)
    : maxLeft_(maxLeft)
    , maxRight_(maxRight)
    , parent_(std::make_unique<int[]>(maxLeft + maxRight))
    , blockOfRoot_(std::make_unique<int[]>(maxLeft + maxRight))
    , leftStart_(std::make_unique<int[]>(maxLeft + maxRight + 1))
    , rightStart_(std::make_unique<int[]>(maxLeft + maxRight + 1))
    , leftMembers_(std::make_unique<int[]>(maxLeft))
    , rightMembers_(std::make_unique<int[]>(maxRight)) {}

void BipartiteBlocks::reset(std::size_t left, std::size_t right) {
    left_ = std::min(left, maxLeft_);
    right_ = std::min(right, maxRight_);
    for (std::size_t i = 0; i < left_ + right_; ++i)
        parent_[i] = static_cast<int>(i);
    blockCount_ = 0;
}

int BipartiteBlocks::root(int node) {
    while (parent_[idx(node)] != node) {
        parent_[idx(node)] = parent_[idx(parent_[idx(node)])];
        node = parent_[idx(node)];
    }
    return node;
}

void BipartiteBlocks::link(std::size_t i, std::size_t j) {
    if (i >= left_ || j >= right_)
        return;
    const int a = root(static_cast<int>(i));
    const int b = root(static_cast<int>(left_ + j));
    if (a != b)
        parent_[idx(std::max(a, b))] = std::min(a, b);
}

void BipartiteBlocks::build() {
    const std::size_t nodes = left_ + right_;
    // Only components with members on both sides can hold a correspondence.
    std::fill_n(blockOfRoot_.get(), nodes, -1);
    std::fill_n(leftStart_.get(), nodes + 1, 0);
    std::fill_n(rightStart_.get(), nodes + 1, 0);
    for (std::size_t n = 0; n < nodes; ++n)
        parent_[n] = root(static_cast<int>(n));

    // A component is a block when it has a right member; number blocks in order of their roots.
    for (std::size_t j = 0; j < right_; ++j) {
        const int r = parent_[left_ + j];
        if (blockOfRoot_[idx(r)] < 0)
            blockOfRoot_[idx(r)] = 0;
    }
    for (std::size_t i = 0; i < left_; ++i) {
        const int r = parent_[i];
        if (blockOfRoot_[idx(r)] == 0)
            blockOfRoot_[idx(r)] = 1;
    }
    blockCount_ = 0;
    for (std::size_t n = 0; n < nodes; ++n)
        blockOfRoot_[n] = blockOfRoot_[n] == 1 ? static_cast<int>(blockCount_++) : -1;

    // Counting sort of members by block.
    for (std::size_t i = 0; i < left_; ++i)
        if (const int b = blockOfRoot_[idx(parent_[i])]; b >= 0)
            ++leftStart_[idx(b) + 1];
    for (std::size_t j = 0; j < right_; ++j)
        if (const int b = blockOfRoot_[idx(parent_[left_ + j])]; b >= 0)
            ++rightStart_[idx(b) + 1];
    for (std::size_t b = 0; b < blockCount_; ++b) {
        leftStart_[b + 1] += leftStart_[b];
        rightStart_[b + 1] += rightStart_[b];
    }
    // Place members using each block's start as a cursor, which leaves it at the block's end.
    for (std::size_t i = 0; i < left_; ++i) {
        const int b = blockOfRoot_[idx(parent_[i])];
        if (b < 0)
            continue;
        int& cursor = leftStart_[idx(b)];
        leftMembers_[idx(cursor)] = static_cast<int>(i);
        ++cursor;
    }
    for (std::size_t j = 0; j < right_; ++j) {
        const int b = blockOfRoot_[idx(parent_[left_ + j])];
        if (b < 0)
            continue;
        int& cursor = rightStart_[idx(b)];
        rightMembers_[idx(cursor)] = static_cast<int>(j);
        ++cursor;
    }
    // The cursors now sit at each block's end, which is the next block's start: shift back.
    for (std::size_t b = blockCount_; b > 0; --b) {
        leftStart_[b] = leftStart_[b - 1];
        rightStart_[b] = rightStart_[b - 1];
    }
    leftStart_[0] = 0;
    rightStart_[0] = 0;
}

std::span<const int> BipartiteBlocks::leftOf(std::size_t block) const {
    return {leftMembers_.get() + leftStart_[block], idx(leftStart_[block + 1] - leftStart_[block])};
}

std::span<const int> BipartiteBlocks::rightOf(std::size_t block) const {
    return {rightMembers_.get() + rightStart_[block],
            idx(rightStart_[block + 1] - rightStart_[block])};
}

} // namespace edgetrack
