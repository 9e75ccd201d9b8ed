// Scott and Longuet-Higgins correspondence (SVD of a proximity matrix), solved per independent
// block.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>

#include <Eigen/Core>
#include <Eigen/SVD>

#include "core/disjoint_sets.hpp"

namespace edgetrack {

/// \brief Largest block the SVD solves; bigger blocks fall back to mutual-best pairing (counted).
inline constexpr int kMaxCorrespondenceBlock = 48;

/// \brief A proximity block with a fixed maximum size: Eigen never allocates it on the heap.
using ProximityBlock = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                     kMaxCorrespondenceBlock, kMaxCorrespondenceBlock>;

/**
 * \brief Splits a bipartite "can match" relation into connected components.
 *
 * Two sets (left: camera 0 blobs or this frame's markers; right: camera 1 blobs or the previous
 * frame's markers). Rows and columns in different components have zero proximity, so the SVD of
 * the whole matrix is the union of the SVDs of the blocks: solving per block changes nothing but
 * the cost. Storage is sized in the constructor.
 */
class BipartiteBlocks {
public:
    BipartiteBlocks(std::size_t maxLeft, std::size_t maxRight);

    /// \brief Start over with \a left and \a right elements, none linked.
    void reset(std::size_t left, std::size_t right);
    /// \brief Left element \a i may correspond to right element \a j.
    void link(std::size_t i, std::size_t j);
    /// \brief Group the elements into blocks; call after the last link().
    void build();

    std::size_t blockCount() const { return blockCount_; }
    std::span<const int> leftOf(std::size_t block) const;
    std::span<const int> rightOf(std::size_t block) const;

private:
    std::size_t maxLeft_, maxRight_;
    std::size_t left_ = 0, right_ = 0;
    /// Left elements are nodes 0 .. left_ - 1, right ones left_ .. left_ + right_ - 1.
    DisjointSets sets_;
    std::unique_ptr<int[]> root_;
    std::unique_ptr<int[]> blockOfRoot_;
    std::unique_ptr<int[]> leftStart_, rightStart_;
    std::unique_ptr<int[]> leftMembers_, rightMembers_;
    std::size_t blockCount_ = 0;
};

/**
 * \brief Solves one block by Scott and Longuet-Higgins: G = U D V^T, P = U V^T (all singular values
 * set to one), and a pair is accepted when P(r, c) is the largest of its row and of its column and
 * G(r, c) >= minProximity.
 */
class SlhSolver {
public:
    /// \brief Calls accept(r, c) for each accepted pair of \a proximity.
    template <typename Accept>
    void solve(const ProximityBlock& proximity, double minProximity, Accept&& accept) {
        const Eigen::Index rows = proximity.rows(), cols = proximity.cols();
        if (rows == 0 || cols == 0)
            return;
        if (rows == 1 || cols == 1) {
            // A single row or column is its own rank-one SVD: U V^T is G scaled by 1 / |G|, so
            // the SVD would pick the same maxima as G itself.
            acceptMutualMaxima(proximity, proximity, minProximity, accept);
            return;
        }
        if (rows == 2 && cols == 2) {
            // The orthogonal polar factor of a non-singular 2x2 block in closed form:
            // G + sign(det G) adj(G)^T is a multiple of U V^T.
            const double a = proximity(0, 0), b = proximity(0, 1);
            const double c = proximity(1, 0), d = proximity(1, 1);
            const double det = a * d - b * c;
            if (std::abs(det) > 1e-12 * (a * a + b * b + c * c + d * d)) {
                const double sign = det > 0.0 ? 1.0 : -1.0;
                Eigen::Matrix2d polar;
                polar << a + sign * d, b - sign * c, c - sign * b, d + sign * a;
                acceptMutualMaxima(polar, proximity, minProximity, accept);
                return;
            }
        }
        acceptMutualMaxima(orthogonalFactor(proximity), proximity, minProximity, accept);
    }

    /// \brief The fallback for oversized blocks: mutual maxima of the proximity itself.
    template <typename Matrix, typename Accept>
    static void mutualBest(const Matrix& proximity, double minProximity, Accept&& accept) {
        acceptMutualMaxima(proximity, proximity, minProximity, accept);
    }

private:
    /// \brief U V^T of the SVD G = U S V^T: by Newton's iteration for the polar factor when the
    /// block's shorter side is 3 or 4 and it is well away from rank deficiency, by the SVD
    /// otherwise. Out of line so that one translation unit alone instantiates Eigen's SVD (it
    /// dominated the build time of every user of this header).
    const ProximityBlock& orthogonalFactor(const ProximityBlock& proximity);

    template <typename Score, typename Matrix, typename Accept>
    static void acceptMutualMaxima(const Score& score, const Matrix& proximity, double minProximity,
                                   Accept&& accept) {
        for (Eigen::Index r = 0; r < score.rows(); ++r) {
            Eigen::Index best = 0;
            score.row(r).maxCoeff(&best);
            Eigen::Index bestRow = 0;
            score.col(best).maxCoeff(&bestRow);
            if (bestRow == r && proximity(r, best) >= minProximity)
                accept(static_cast<int>(r), static_cast<int>(best));
        }
    }

    Eigen::JacobiSVD<ProximityBlock> svd_;
    ProximityBlock orthogonal_;
};

/**
 * \brief Solves the blocks of a BipartiteBlocks split with a proximity given as a function of the
 * elements' own indices: SVD for blocks up to kMaxCorrespondenceBlock, mutual best proximity
 * (counted by the caller) for larger ones. Owns its fixed-size scratch, so it never allocates.
 */
class BlockSolver {
public:
    /**
     * \brief Pair the elements of one block.
     * \param proximity (left, right) -> G, with the elements' own indices.
     * \param accept called with (left, right) for each accepted pair.
     * \return false when the block was too big for the SVD and the fallback paired it.
     */
    template <typename Proximity, typename Accept>
    bool solve(std::span<const int> left, std::span<const int> right, double minProximity,
               Proximity&& proximity, Accept&& accept) {
        constexpr auto kMax = static_cast<std::size_t>(kMaxCorrespondenceBlock);
        if (left.size() == 1 && right.size() == 1) {
            // Most blocks are a lone pair (markers that move less than their spacing): skip the
            // matrix; the pair is its own mutual maximum.
            if (proximity(left[0], right[0]) >= minProximity)
                accept(left[0], right[0]);
            return true;
        }
        if (left.size() > kMax || right.size() > kMax) {
            for (const int l : left) {
                int best = -1;
                double bestProximity = minProximity;
                for (const int r : right)
                    if (const double g = proximity(l, r); g >= bestProximity) {
                        bestProximity = g;
                        best = r;
                    }
                bool mutual = best >= 0;
                for (const int other : left)
                    mutual = mutual && (other == l || proximity(other, best) <= bestProximity);
                if (mutual)
                    accept(l, best);
            }
            return false;
        }
        block_.resize(static_cast<Eigen::Index>(left.size()),
                      static_cast<Eigen::Index>(right.size()));
        for (std::size_t r = 0; r < left.size(); ++r)
            for (std::size_t c = 0; c < right.size(); ++c)
                block_(static_cast<Eigen::Index>(r), static_cast<Eigen::Index>(c)) =
                    proximity(left[r], right[c]);
        solver_.solve(block_, minProximity, [&](int r, int c) {
            accept(left[static_cast<std::size_t>(r)], right[static_cast<std::size_t>(c)]);
        });
        return true;
    }

private:
    SlhSolver solver_;
    ProximityBlock block_;
};

} // namespace edgetrack
