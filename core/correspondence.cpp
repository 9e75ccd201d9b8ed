// Scott and Longuet-Higgins correspondence (SVD of a proximity matrix), solved per independent
// block.
#include "core/correspondence.hpp"

#include <algorithm>
#include <cmath>

#include <Eigen/LU>

namespace edgetrack {

namespace {
constexpr std::size_t idx(int i) {
    return static_cast<std::size_t>(i);
}

// Longest side of a block whose polar factor is taken by Newton's iteration below.
constexpr int kMaxNewtonSide = 8;

// The orthogonal polar factor U V^T of a block whose shorter side is N, by Higham's scaled Newton
// iteration X <- (z X + X^+T / z) / 2 (X^+T is X^-T for a square block, X (X^T X)^-1 for a tall
// one; a wide block is taken transposed). A few NxN inverses replace a Jacobi SVD, about four
// times faster. The polar factor of a matrix of full rank is unique, so this is the SVD's U V^T
// to rounding. Returns false (and the caller takes the SVD) when the block is close to rank
// deficient, where U V^T depends on how the SVD picks its null space, or when the iteration does
// not settle.
template <int N, typename Matrix>
bool newtonPolarIteration(Matrix& x) {
    using Square = Eigen::Matrix<double, N, N>;
    constexpr bool kSquare = Matrix::RowsAtCompileTime == N;
    const double scale = x.norm();
    if (!(scale > 0.0))
        return false;
    x /= scale;
    constexpr int kMaxIterations = 20;
    for (int i = 0; i < kMaxIterations; ++i) {
        Square inverse;
        double determinant = 0.0;
        bool invertible = false;
        Matrix pseudoInverseT;
        if constexpr (kSquare) {
            x.computeInverseAndDetWithCheck(inverse, determinant, invertible, 0.0);
            pseudoInverseT = inverse.transpose();
        } else {
            const Square gram = x.transpose() * x;
            gram.computeInverseAndDetWithCheck(inverse, determinant, invertible, 0.0);
            determinant = std::sqrt(std::abs(determinant));
            pseudoInverseT.noalias() = x * inverse;
        }
        // A unit-norm matrix has no singular value below |det| (of the Gram matrix, its square
        // root): the test admits blocks well away from rank deficiency only.
        if (!invertible || !(std::abs(determinant) > 1e-6))
            return false;
        const double z = std::sqrt(std::sqrt(pseudoInverseT.squaredNorm() / x.squaredNorm()));
        const Matrix next = 0.5 * (z * x + pseudoInverseT / z);
        const double change = (next - x).norm();
        x = next;
        // Convergence is quadratic: after a step of 1e-7 the error is about 1e-14.
        if (change < 1e-7)
            return true;
    }
    return false;
}

template <int N>
bool newtonPolarFactor(const ProximityBlock& proximity, ProximityBlock& orthogonal) {
    const bool wide = proximity.rows() < proximity.cols();
    if (proximity.rows() == proximity.cols()) {
        Eigen::Matrix<double, N, N> x = proximity;
        if (!newtonPolarIteration<N>(x))
            return false;
        orthogonal = x;
        return true;
    }
    using Tall = Eigen::Matrix<double, Eigen::Dynamic, N, Eigen::ColMajor, kMaxNewtonSide, N>;
    Tall x(wide ? proximity.cols() : proximity.rows(), N);
    if (wide)
        x = proximity.transpose();
    else
        x = proximity;
    if (!newtonPolarIteration<N>(x))
        return false;
    if (wide)
        orthogonal = x.transpose();
    else
        orthogonal = x;
    return true;
}

} // namespace

const ProximityBlock& SlhSolver::orthogonalFactor(const ProximityBlock& proximity) {
    const Eigen::Index shorter = std::min(proximity.rows(), proximity.cols());
    const Eigen::Index longer = std::max(proximity.rows(), proximity.cols());
    if (longer <= kMaxNewtonSide) {
        if (shorter == 3 && newtonPolarFactor<3>(proximity, orthogonal_))
            return orthogonal_;
        if (shorter == 4 && newtonPolarFactor<4>(proximity, orthogonal_))
            return orthogonal_;
    }
    svd_.compute(proximity, Eigen::ComputeThinU | Eigen::ComputeThinV);
    orthogonal_.noalias() = svd_.matrixU() * svd_.matrixV().transpose();
    return orthogonal_;
}

BipartiteBlocks::BipartiteBlocks(std::size_t maxLeft, std::size_t maxRight)
    : maxLeft_(maxLeft)
    , maxRight_(maxRight)
    , sets_(maxLeft + maxRight)
    , root_(std::make_unique<int[]>(maxLeft + maxRight))
    , blockOfRoot_(std::make_unique<int[]>(maxLeft + maxRight))
    , leftStart_(std::make_unique<int[]>(maxLeft + maxRight + 1))
    , rightStart_(std::make_unique<int[]>(maxLeft + maxRight + 1))
    , leftMembers_(std::make_unique<int[]>(maxLeft))
    , rightMembers_(std::make_unique<int[]>(maxRight)) {}

void BipartiteBlocks::reset(std::size_t left, std::size_t right) {
    left_ = std::min(left, maxLeft_);
    right_ = std::min(right, maxRight_);
    sets_.reset(left_ + right_);
    blockCount_ = 0;
}

void BipartiteBlocks::link(std::size_t i, std::size_t j) {
    if (i >= left_ || j >= right_)
        return;
    sets_.unite(i, left_ + j);
}

void BipartiteBlocks::build() {
    const std::size_t nodes = left_ + right_;
    // Only components with members on both sides can hold a correspondence.
    std::fill_n(blockOfRoot_.get(), nodes, -1);
    std::fill_n(leftStart_.get(), nodes + 1, 0);
    std::fill_n(rightStart_.get(), nodes + 1, 0);
    // Roots are the smallest node of their component; root[n] is n's, looked up once.
    for (std::size_t n = 0; n < nodes; ++n)
        root_[n] = static_cast<int>(sets_.find(n));

    // A component is a block when it has a right member; number blocks in order of their roots.
    for (std::size_t j = 0; j < right_; ++j) {
        const int r = root_[left_ + j];
        if (blockOfRoot_[idx(r)] < 0)
            blockOfRoot_[idx(r)] = 0;
    }
    for (std::size_t i = 0; i < left_; ++i) {
        const int r = root_[i];
        if (blockOfRoot_[idx(r)] == 0)
            blockOfRoot_[idx(r)] = 1;
    }
    blockCount_ = 0;
    for (std::size_t n = 0; n < nodes; ++n)
        blockOfRoot_[n] = blockOfRoot_[n] == 1 ? static_cast<int>(blockCount_++) : -1;

    // Counting sort of members by block.
    for (std::size_t i = 0; i < left_; ++i)
        if (const int b = blockOfRoot_[idx(root_[i])]; b >= 0)
            ++leftStart_[idx(b) + 1];
    for (std::size_t j = 0; j < right_; ++j)
        if (const int b = blockOfRoot_[idx(root_[left_ + j])]; b >= 0)
            ++rightStart_[idx(b) + 1];
    for (std::size_t b = 0; b < blockCount_; ++b) {
        leftStart_[b + 1] += leftStart_[b];
        rightStart_[b + 1] += rightStart_[b];
    }
    // Place members using each block's start as a cursor, which leaves it at the block's end.
    for (std::size_t i = 0; i < left_; ++i) {
        const int b = blockOfRoot_[idx(root_[i])];
        if (b < 0)
            continue;
        int& cursor = leftStart_[idx(b)];
        leftMembers_[idx(cursor)] = static_cast<int>(i);
        ++cursor;
    }
    for (std::size_t j = 0; j < right_; ++j) {
        const int b = blockOfRoot_[idx(root_[left_ + j])];
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
