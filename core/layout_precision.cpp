// Joint least squares of a marker layout over many poses: its normal equations and its precision.
#include "core/layout_precision.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include "core/marker_set.hpp"

namespace edgetrack {

void addToReducedSystem(const RigidTransform& T_rig_from_body, std::span<const Vec3> markers_mm,
                        std::span<const Vec3> points_mm, std::span<const std::size_t> which,
                        Eigen::MatrixXd& reduced, Eigen::VectorXd& rhs) {
    if (which.size() < 3)
        return;
    const Mat3 rotation = T_rig_from_body.rotationMatrix();
    Eigen::Matrix<double, 6, 6> hpp = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> gp = Eigen::Matrix<double, 6, 1>::Zero();
    // Per observation: its pose Jacobian (3 x 6) and residual, kept for the second pass.
    constexpr std::size_t kMaxObservations = MarkerSet::kCapacity;
    const std::size_t count = std::min(which.size(), kMaxObservations);
    std::array<Eigen::Matrix<double, 3, 6>, kMaxObservations> jp;
    std::array<Vec3, kMaxObservations> residual;
    for (std::size_t i = 0; i < count; ++i) {
        const Vec3 turned = rotation * markers_mm[i];
        residual[i] = turned + T_rig_from_body.translation_mm - points_mm[i];
        Mat3 skew;
        skew << 0.0, -turned.z(), turned.y(), turned.z(), 0.0, -turned.x(), -turned.y(), turned.x(),
            0.0;
        jp[i].leftCols<3>() = -skew;
        jp[i].rightCols<3>().setIdentity();
        hpp += jp[i].transpose() * jp[i];
        gp += jp[i].transpose() * residual[i];
    }
    const Eigen::LDLT<Eigen::Matrix<double, 6, 6>> poseBlock(hpp);
    if (poseBlock.info() != Eigen::Success || !poseBlock.isPositive())
        return;
    // H_mm = R^T R = I per observation; H_pm = J_p^T R; g_m = R^T r.
    const Eigen::Matrix<double, 6, 1> hppInvGp = poseBlock.solve(gp);
    std::array<Eigen::Matrix<double, 6, 3>, kMaxObservations> hpm;
    std::array<Eigen::Matrix<double, 6, 3>, kMaxObservations> hppInvHpm;
    for (std::size_t i = 0; i < count; ++i) {
        hpm[i] = jp[i].transpose() * rotation;
        hppInvHpm[i] = poseBlock.solve(hpm[i]);
    }
    for (std::size_t i = 0; i < count; ++i) {
        const auto a = static_cast<Eigen::Index>(3 * which[i]);
        reduced.block<3, 3>(a, a) += Mat3::Identity();
        rhs.segment<3>(a) -= rotation.transpose() * residual[i] - hpm[i].transpose() * hppInvGp;
        // The system is symmetric (H_pp is): each block below the diagonal is one above it,
        // transposed.
        reduced.block<3, 3>(a, a) -= hpm[i].transpose() * hppInvHpm[i];
        for (std::size_t j = i + 1; j < count; ++j) {
            const auto b = static_cast<Eigen::Index>(3 * which[j]);
            const Mat3 block = hpm[i].transpose() * hppInvHpm[j];
            reduced.block<3, 3>(a, b) -= block;
            reduced.block<3, 3>(b, a) -= block.transpose();
        }
    }
}

LayoutPrecision layoutPrecision(const Eigen::MatrixXd& reduced,
                                std::span<const std::uint32_t> counts, double squaredResiduals_mm2,
                                double degreesOfFreedom) {
    LayoutPrecision precision;
    std::vector<Eigen::Index> seen;
    for (std::size_t k = 0; k < counts.size(); ++k)
        if (counts[k] > 0)
            seen.push_back(static_cast<Eigen::Index>(k));
    // Six of the modes are the layout moved as a whole, which the poses take up: what is left
    // needs three markers off one line.
    if (seen.size() < 3 || degreesOfFreedom <= 0.0)
        return precision;
    const auto dimension = static_cast<Eigen::Index>(3 * seen.size());
    Eigen::MatrixXd information(dimension, dimension);
    for (Eigen::Index i = 0; i < static_cast<Eigen::Index>(seen.size()); ++i)
        for (Eigen::Index j = 0; j < static_cast<Eigen::Index>(seen.size()); ++j)
            information.block<3, 3>(3 * i, 3 * j) = reduced.block<3, 3>(
                3 * seen[static_cast<std::size_t>(i)], 3 * seen[static_cast<std::size_t>(j)]);
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> modes(information);
    if (modes.info() != Eigen::Success)
        return precision;
    const Eigen::VectorXd& stiffness = modes.eigenvalues(); // ascending
    const double variance_mm2 = squaredResiduals_mm2 / degreesOfFreedom;
    precision.pointSigma_mm = std::sqrt(variance_mm2);
    // A mode this much softer than the stiffest is one no frame constrains: rounding leaves
    // the six rigid modes and a loose one near 1e-15 of it, while the weakest tie of a sparse
    // layout in the sweeps (a car's two sides seen together in few frames) is near 1e-5.
    constexpr double kLoose = 1e-9;
    constexpr Eigen::Index kRigidModes = 6;
    const double loose = kLoose * stiffness(dimension - 1);
    Eigen::VectorXd markerVariance = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(seen.size()));
    for (Eigen::Index mode = kRigidModes; mode < dimension; ++mode) {
        if (stiffness(mode) <= loose) {
            ++precision.looseModes;
            continue;
        }
        const Eigen::VectorXd shape = modes.eigenvectors().col(mode);
        for (Eigen::Index i = 0; i < markerVariance.size(); ++i)
            markerVariance(i) += shape.segment<3>(3 * i).squaredNorm() / stiffness(mode);
    }
    if (precision.looseModes > 0) {
        precision.markerRms_mm = std::numeric_limits<double>::infinity();
        precision.worstMarker_mm = std::numeric_limits<double>::infinity();
        return precision;
    }
    precision.markerRms_mm = std::sqrt(variance_mm2 * markerVariance.mean());
    precision.worstMarker_mm = std::sqrt(variance_mm2 * markerVariance.maxCoeff());
    return precision;
}

} // namespace edgetrack
