// Rig calibration by wand: essential matrix for a start, then a Ceres bundle adjustment.
#include "core/rig_calibration.hpp"

#include <algorithm>
#include <ceres/ceres.h>
#include <ceres/rotation.h>
#include <cmath>
#include <numeric>
#include <optional>
#include <random>

#include <Eigen/SVD>

#include "core/triangulation.hpp"

namespace edgetrack {

namespace {

constexpr double kPi = 3.14159265358979323846;

/// Marker k of camera \a c of a pair, read in the order the pair's resolution chose.
struct Ordered {
    const WandFramePair* pair = nullptr;
    std::array<bool, 2> reversed{};

    const Vec2& pixel(int c, std::size_t k) const {
        const WandSighting& s = pair->sightings[static_cast<std::size_t>(c)];
        return s.pixels[reversed[static_cast<std::size_t>(c)] ? s.markerCount - 1 - k : k];
    }
};

/// Undistorted normalized coordinates of both cameras' markers of one pair.
struct NormalizedPair {
    std::array<std::array<Vec2, kMaxWandMarkers>, 2> x{};
    bool valid = true;
};

NormalizedPair normalize(const StereoRig& rig, const Ordered& o, std::size_t markers) {
    NormalizedPair n;
    for (int c = 0; c < 2; ++c)
        for (std::size_t k = 0; k < markers; ++k) {
            const std::optional<Vec2> x = rig.camera(c).undistortPixel(o.pixel(c, k));
            if (!x) {
                n.valid = false;
                return n;
            }
            n.x[static_cast<std::size_t>(c)][k] = *x;
        }
    return n;
}

Mat3 skew(const Vec3& v) {
    Mat3 m;
    m << 0.0, -v.z(), v.y(), v.z(), 0.0, -v.x(), -v.y(), v.x(), 0.0;
    return m;
}

/// Sampson distance squared of x1^T E x0 = 0 (normalized units squared).
double sampson(const Mat3& E, const Vec2& x0, const Vec2& x1) {
    const Vec3 a = x0.homogeneous();
    const Vec3 b = x1.homogeneous();
    const Vec3 Ea = E * a;
    const Vec3 Etb = E.transpose() * b;
    const double r = b.dot(Ea);
    const double d = Ea.x() * Ea.x() + Ea.y() * Ea.y() + Etb.x() * Etb.x() + Etb.y() * Etb.y();
    return d > 0.0 ? r * r / d : 1e300;
}

/// Least-squares essential matrix of correspondences (x0[i], x1[i]), nearest of rank two.
std::optional<Mat3> eightPoint(std::span<const Vec2> x0, std::span<const Vec2> x1) {
    if (x0.size() < 8)
        return std::nullopt;
    Eigen::Matrix<double, 9, 9> AtA = Eigen::Matrix<double, 9, 9>::Zero();
    for (std::size_t i = 0; i < x0.size(); ++i) {
        Eigen::Matrix<double, 9, 1> row;
        row << x1[i].x() * x0[i].x(), x1[i].x() * x0[i].y(), x1[i].x(), x1[i].y() * x0[i].x(),
            x1[i].y() * x0[i].y(), x1[i].y(), x0[i].x(), x0[i].y(), 1.0;
        AtA.noalias() += row * row.transpose();
    }
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, 9, 9>> eigen(AtA);
    if (eigen.info() != Eigen::Success)
        return std::nullopt;
    const Eigen::Matrix<double, 9, 1> e = eigen.eigenvectors().col(0);
    Mat3 E;
    E << e(0), e(1), e(2), e(3), e(4), e(5), e(6), e(7), e(8);
    Eigen::JacobiSVD<Mat3> svd(E, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const double s = 0.5 * (svd.singularValues()(0) + svd.singularValues()(1));
    if (!(s > 0.0))
        return std::nullopt;
    return Mat3(svd.matrixU() * Vec3(s, s, 0.0).asDiagonal() * svd.matrixV().transpose());
}

/// A camera 1 pose p_cam1 = R p_rig + t.
struct Pose {
    Mat3 R = Mat3::Identity();
    Vec3 t = Vec3::Zero();
};

/// Depths of a correspondence's triangulation in both cameras (midpoint of rays).
bool inFront(const Pose& pose, const Vec2& x0, const Vec2& x1) {
    // Solve d0 * a0 = d1 * R^T a1 - R^T t  for the closest points.
    const Vec3 a0 = x0.homogeneous().normalized();
    const Vec3 a1 = (pose.R.transpose() * x1.homogeneous()).normalized();
    const Vec3 c1 = -pose.R.transpose() * pose.t;
    Eigen::Matrix<double, 3, 2> A;
    A.col(0) = a0;
    A.col(1) = -a1;
    const Eigen::Vector2d d = A.colPivHouseholderQr().solve(c1);
    return d(0) > 0.0 && d(1) > 0.0;
}

/// The pose of E (unit translation) that puts most correspondences in front of both cameras.
std::optional<Pose> decompose(const Mat3& E, std::span<const Vec2> x0, std::span<const Vec2> x1) {
    Eigen::JacobiSVD<Mat3> svd(E, Eigen::ComputeFullU | Eigen::ComputeFullV);
    Mat3 U = svd.matrixU();
    Mat3 V = svd.matrixV();
    if (U.determinant() < 0.0)
        U.col(2) *= -1.0;
    if (V.determinant() < 0.0)
        V.col(2) *= -1.0;
    Mat3 W;
    W << 0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0;
    const std::array<Mat3, 2> rotations{U * W * V.transpose(), U * W.transpose() * V.transpose()};
    const Vec3 u = U.col(2);
    std::optional<Pose> best;
    std::size_t bestCount = 0;
    for (const Mat3& R : rotations)
        for (double sign : {1.0, -1.0}) {
            const Pose pose{R, sign * u};
            std::size_t count = 0;
            const std::size_t step = std::max<std::size_t>(1, x0.size() / 400);
            for (std::size_t i = 0; i < x0.size(); i += step)
                count += inFront(pose, x0[i], x1[i]) ? 1u : 0u;
            if (count > bestCount) {
                bestCount = count;
                best = pose;
            }
        }
    return best;
}

CameraModel withPose(const CameraModel& camera, const Pose& pose) {
    CameraExtrinsics ex;
    ex.rotation_cam_from_rig = pose.R;
    ex.translation_cam_from_rig_mm = pose.t;
    return CameraModel(camera.intrinsics(), ex);
}

/// The markers of an ordered pair triangulated with \a rig (rig frame, mm).
bool triangulateWand(const StereoRig& rig, const Ordered& o, std::size_t markers,
                     std::array<Vec3, kMaxWandMarkers>& points) {
    for (std::size_t k = 0; k < markers; ++k) {
        const std::optional<Ray> r0 = rig.camera(0).ray(o.pixel(0, k));
        const std::optional<Ray> r1 = rig.camera(1).ray(o.pixel(1, k));
        if (!r0 || !r1)
            return false;
        const std::optional<TriangulatedPoint> p = triangulate(*r0, *r1);
        if (!p || p->range0_mm <= 0.0 || p->range1_mm <= 0.0)
            return false;
        points[k] = p->point_rig_mm;
    }
    return true;
}

/// How badly triangulated markers miss the wand's offsets from marker 0 (mm, summed squares).
double wandMisfit(const WandSpec& wand, const std::array<Vec3, kMaxWandMarkers>& points) {
    double sum = 0.0;
    for (std::size_t k = 1; k < wand.markerCount; ++k) {
        const double e = (points[k] - points[0]).norm() - wand.offset_mm(k);
        sum += e * e;
    }
    return sum;
}

// ------------------------------------------------------------------------------------------
// Bundle adjustment

/// Project a camera-frame point through pinhole + OpenCV distortion; false behind the camera.
template <typename T>
bool projectCamera(const T* intrinsics, const std::array<double, 5>& d, const T* p, T* uv) {
    if (p[2] <= T(1e-6))
        return false;
    const T x = p[0] / p[2];
    const T y = p[1] / p[2];
    const T r2 = x * x + y * y;
    const T radial = T(1.0) + r2 * (T(d[0]) + r2 * (T(d[1]) + r2 * T(d[4])));
    const T xd = x * radial + T(2.0 * d[2]) * x * y + T(d[3]) * (r2 + T(2.0) * x * x);
    const T yd = y * radial + T(d[2]) * (r2 + T(2.0) * y * y) + T(2.0 * d[3]) * x * y;
    uv[0] = intrinsics[0] * xd + intrinsics[2];
    uv[1] = intrinsics[1] * yd + intrinsics[3];
    return true;
}

/// Reprojection in camera 0 (the rig frame) of marker at \a offset_mm along a wand.
struct Camera0Reprojection {
    Vec2 observed_px;
    double offset_mm;
    std::array<double, 5> distortion;

    template <typename T>
    bool operator()(const T* intrinsics, const T* wandPose, T* residual) const {
        T p[3];
        for (int i = 0; i < 3; ++i)
            p[i] = wandPose[i] + T(offset_mm) * wandPose[3 + i];
        T uv[2];
        if (!projectCamera(intrinsics, distortion, p, uv))
            return false;
        residual[0] = uv[0] - T(observed_px.x());
        residual[1] = uv[1] - T(observed_px.y());
        return true;
    }
};

/// Reprojection in camera 1, posed by an angle-axis rotation and a translation (mm).
struct Camera1Reprojection {
    Vec2 observed_px;
    double offset_mm;
    std::array<double, 5> distortion;

    template <typename T>
    bool operator()(const T* intrinsics, const T* angleAxis, const T* translation,
                    const T* wandPose, T* residual) const {
        T p[3];
        for (int i = 0; i < 3; ++i)
            p[i] = wandPose[i] + T(offset_mm) * wandPose[3 + i];
        T q[3];
        ceres::AngleAxisRotatePoint(angleAxis, p, q);
        for (int i = 0; i < 3; ++i)
            q[i] += translation[i];
        T uv[2];
        if (!projectCamera(intrinsics, distortion, q, uv))
            return false;
        residual[0] = uv[0] - T(observed_px.x());
        residual[1] = uv[1] - T(observed_px.y());
        return true;
    }
};

/// Everything the adjustment changes.
struct Unknowns {
    std::array<std::array<double, 4>, 2> intrinsics{}; // fx, fy, cx, cy
    std::array<double, 3> angleAxis{};
    std::array<double, 3> translation{};
    /// Each wand pose: marker 0 (rig frame, mm), then the unit direction to the last marker.
    std::vector<std::array<double, 6>> wand;
};

StereoRig rigOf(const StereoRig& start, const Unknowns& u) {
    std::array<CameraModel, 2> cameras;
    for (int c = 0; c < 2; ++c) {
        CameraIntrinsics in = start.camera(c).intrinsics();
        in.fx_px = u.intrinsics[static_cast<std::size_t>(c)][0];
        in.fy_px = u.intrinsics[static_cast<std::size_t>(c)][1];
        in.cx_px = u.intrinsics[static_cast<std::size_t>(c)][2];
        in.cy_px = u.intrinsics[static_cast<std::size_t>(c)][3];
        CameraExtrinsics ex;
        if (c == 1) {
            double R[9];
            ceres::AngleAxisToRotationMatrix(u.angleAxis.data(), R); // column-major
            ex.rotation_cam_from_rig = Eigen::Map<const Eigen::Matrix<double, 3, 3>>(R);
            ex.translation_cam_from_rig_mm =
                Vec3(u.translation[0], u.translation[1], u.translation[2]);
        }
        cameras[static_cast<std::size_t>(c)] = CameraModel(in, ex);
    }
    return StereoRig(cameras[0], cameras[1]);
}

/// One adjustment over \a used (of the wand poses alone when \a fixRig); returns the solver's
/// iteration count, or nothing when it failed.
std::optional<int> adjust(const StereoRig& start, const WandSpec& wand,
                          std::span<const Ordered> used, const RigCalibrationConfig& config,
                          bool fixRig, Unknowns& u) {
    std::array<std::array<double, 5>, 2> distortion{start.camera(0).intrinsics().distortion,
                                                    start.camera(1).intrinsics().distortion};
    // Frame pair f's reprojections: its wand pose, through both cameras.
    const auto addFramePair = [&](ceres::Problem& problem, std::size_t f) {
        for (std::size_t k = 0; k < wand.markerCount; ++k) {
            const double offset = wand.offset_mm(k);
            auto* loss0 = new ceres::HuberLoss(config.robustLoss_px);
            problem.AddResidualBlock(
                new ceres::AutoDiffCostFunction<Camera0Reprojection, 2, 4, 6>(
                    new Camera0Reprojection{used[f].pixel(0, k), offset, distortion[0]}),
                loss0, u.intrinsics[0].data(), u.wand[f].data());
            auto* loss1 = new ceres::HuberLoss(config.robustLoss_px);
            problem.AddResidualBlock(
                new ceres::AutoDiffCostFunction<Camera1Reprojection, 2, 4, 3, 3, 6>(
                    new Camera1Reprojection{used[f].pixel(1, k), offset, distortion[1]}),
                loss1, u.intrinsics[1].data(), u.angleAxis.data(), u.translation.data(),
                u.wand[f].data());
        }
        problem.SetManifold(
            u.wand[f].data(),
            new ceres::ProductManifold<ceres::EuclideanManifold<3>, ceres::SphereManifold<3>>());
    };
    ceres::Solver::Options options;
    options.max_num_iterations = 100;
    options.function_tolerance = 1e-12;
    options.gradient_tolerance = 1e-14;
    options.parameter_tolerance = 1e-12;
    options.logging_type = ceres::SILENT;
    options.minimizer_progress_to_stdout = false;

    if (fixRig) {
        // With the rig held, no unknown links two frame pairs: each wand pose is a problem of
        // its own and stops when it has converged. Solved as one problem, every pose waited for
        // the slowest: a rig that fits badly took the 100 iterations on all of them (1.4 s of the
        // knocked-rig firmware test's 2.1 s on the host, most of it for poses long settled).
        // A pose whose steps keep leaving the cameras' view (the solver gives up) keeps its seed,
        // and the refusal of pairs that fit badly judges it as any other.
        options.linear_solver_type = ceres::DENSE_QR;
        std::size_t slowest = 0, solved = 0;
        for (std::size_t f = 0; f < used.size(); ++f) {
            const std::array<double, 6> seed = u.wand[f];
            ceres::Problem problem;
            addFramePair(problem, f);
            problem.SetParameterBlockConstant(u.intrinsics[0].data());
            problem.SetParameterBlockConstant(u.intrinsics[1].data());
            problem.SetParameterBlockConstant(u.angleAxis.data());
            problem.SetParameterBlockConstant(u.translation.data());
            ceres::Solver::Summary summary;
            ceres::Solve(options, &problem, &summary);
            if (!summary.IsSolutionUsable()) {
                u.wand[f] = seed;
                continue;
            }
            ++solved;
            slowest = std::max(slowest, summary.iterations.size());
        }
        if (solved == 0)
            return std::nullopt;
        return static_cast<int>(slowest);
    }

    ceres::Problem problem;
    for (std::size_t f = 0; f < used.size(); ++f)
        addFramePair(problem, f);
    if (!config.refineIntrinsics) {
        problem.SetParameterBlockConstant(u.intrinsics[0].data());
        problem.SetParameterBlockConstant(u.intrinsics[1].data());
    }

    // Wand poses first: the Schur complement leaves only the cameras' few unknowns.
    auto* ordering = new ceres::ParameterBlockOrdering;
    for (std::size_t f = 0; f < used.size(); ++f)
        ordering->AddElementToGroup(u.wand[f].data(), 0);
    ordering->AddElementToGroup(u.angleAxis.data(), 1);
    ordering->AddElementToGroup(u.translation.data(), 1);
    ordering->AddElementToGroup(u.intrinsics[0].data(), 1);
    ordering->AddElementToGroup(u.intrinsics[1].data(), 1);
    options.linear_solver_type = ceres::DENSE_SCHUR;
    options.linear_solver_ordering.reset(ordering);
    ceres::Solver::Summary summary;
    ceres::Solve(options, &problem, &summary);
    if (!summary.IsSolutionUsable())
        return std::nullopt;
    return static_cast<int>(summary.iterations.size());
}

/// Per marker reprojection errors of one ordered pair under \a rig (px), both cameras.
double worstError(const StereoRig& rig, const WandSpec& wand, const Ordered& o,
                  const std::array<double, 6>& wandPose, std::array<double, 2>& squaredSum) {
    double worst = 0.0;
    const Vec3 p0(wandPose[0], wandPose[1], wandPose[2]);
    const Vec3 d(wandPose[3], wandPose[4], wandPose[5]);
    for (std::size_t k = 0; k < wand.markerCount; ++k) {
        const Vec3 p = p0 + wand.offset_mm(k) * d;
        for (int c = 0; c < 2; ++c) {
            const std::optional<Vec2> uv = rig.camera(c).project(p);
            const double e = uv ? (*uv - o.pixel(c, k)).norm() : 1e6;
            squaredSum[static_cast<std::size_t>(c)] += e * e;
            worst = std::max(worst, e);
        }
    }
    return worst;
}

double percentile(std::vector<double> values, double share) {
    if (values.empty())
        return 0.0;
    std::sort(values.begin(), values.end());
    const auto at = static_cast<std::size_t>(
        std::min<double>(static_cast<double>(values.size() - 1),
                         std::ceil(share * static_cast<double>(values.size())) - 1.0));
    return values[at];
}

std::string percent(double share) {
    return std::to_string(static_cast<int>(std::lround(100.0 * share))) + "%";
}

/// The frame pairs used, at most \a maxFrames spread evenly over the whole session.
std::vector<Ordered> spread(std::span<const WandFramePair> pairs, std::size_t maxFrames,
                            RigCalibrationReport& report) {
    std::vector<Ordered> ordered;
    const std::size_t take = std::min(pairs.size(), maxFrames);
    for (std::size_t i = 0; i < take; ++i)
        ordered.push_back({&pairs[i * pairs.size() / take], {false, false}});
    report.framesSkipped = pairs.size() - take;
    return ordered;
}

/// E = [t]x R of a rig's camera 1 (unit baseline).
Mat3 essentialOf(const StereoRig& rig) {
    const CameraExtrinsics& ex = rig.camera(1).extrinsics();
    return skew(ex.translation_cam_from_rig_mm.normalized()) * ex.rotation_cam_from_rig;
}

/// Where a pair's wand ends are open in an image, read camera 1 the way round with the smaller
/// epipolar error under \a E. \return true when camera 1's reading was turned.
bool resolveOpenEnds(const Mat3& E, const NormalizedPair& x, std::size_t n, Ordered& o) {
    if (!o.pair->sightings[0].endsAmbiguous && !o.pair->sightings[1].endsAmbiguous)
        return false;
    double kept = 0.0;
    double flipped = 0.0;
    for (std::size_t k = 0; k < n; ++k) {
        kept += sampson(E, x.x[0][k], x.x[1][k]);
        flipped += sampson(E, x.x[0][k], x.x[1][n - 1 - k]);
    }
    if (flipped >= kept)
        return false;
    o.reversed[1] = !o.reversed[1];
    return true;
}

/// Steps 3 to 5 from \a initial: seed every wand pose, adjust (camera 1's pose and, when asked,
/// the intrinsics; nothing of the rig when \a fixRig), refuse what fits badly, adjust again,
/// report. \a start gives the lens models and the pose the report measures the change from.
Result<RigCalibrationResult> adjustAndReport(const StereoRig& start, const StereoRig& initial,
                                             const WandSpec& wand, std::vector<Ordered>& ordered,
                                             const std::vector<std::size_t>& all,
                                             RigCalibrationReport report,
                                             const RigCalibrationConfig& config, bool fixRig) {
    const std::size_t n = wand.markerCount;
    RigCalibrationResult result;
    std::array<Vec3, kMaxWandMarkers> points{};
    // Where both images left the ends open, the reading whose triangulation fits the wand's
    // spacings wins (a symmetric wand reads the same either way).
    Unknowns u;
    std::vector<Ordered> used;
    for (std::size_t i : all) {
        Ordered o = ordered[i];
        if (o.pair->sightings[0].endsAmbiguous && !wand.isSymmetric()) {
            Ordered flipped = o;
            flipped.reversed = {!o.reversed[0], !o.reversed[1]};
            std::array<Vec3, kMaxWandMarkers> a{}, b{};
            const bool okA = triangulateWand(initial, o, n, a);
            const bool okB = triangulateWand(initial, flipped, n, b);
            if (okB && (!okA || wandMisfit(wand, b) < wandMisfit(wand, a)))
                o = flipped;
        }
        if (!triangulateWand(initial, o, n, points)) {
            ++report.framesRefused;
            continue;
        }
        const Vec3 direction = (points[n - 1] - points[0]).normalized();
        Vec3 origin = Vec3::Zero();
        for (std::size_t k = 0; k < n; ++k)
            origin += points[k] - wand.offset_mm(k) * direction;
        origin /= static_cast<double>(n);
        used.push_back(o);
        u.wand.push_back(
            {origin.x(), origin.y(), origin.z(), direction.x(), direction.y(), direction.z()});
    }
    for (int c = 0; c < 2; ++c) {
        const CameraIntrinsics& in = initial.camera(c).intrinsics();
        u.intrinsics[static_cast<std::size_t>(c)] = {in.fx_px, in.fy_px, in.cx_px, in.cy_px};
    }
    {
        const CameraExtrinsics& ex = initial.camera(1).extrinsics();
        std::array<double, 9> columns{};
        Eigen::Map<Eigen::Matrix<double, 3, 3>> rotation(columns.data()); // column-major, as ceres
        rotation = ex.rotation_cam_from_rig;
        ceres::RotationMatrixToAngleAxis(columns.data(), u.angleAxis.data());
        const Vec3& t = ex.translation_cam_from_rig_mm;
        u.translation = {t.x(), t.y(), t.z()};
    }

    // (2) Adjust, (3) refuse what fits badly, adjust again.
    for (int round = 0; round < 2; ++round) {
        if (used.size() < config.minFrames)
            return Error{"only " + std::to_string(used.size()) +
                         " frame pairs agree on a rig, at least " +
                         std::to_string(config.minFrames) + " needed"};
        const std::optional<int> iterations = adjust(start, wand, used, config, fixRig, u);
        if (!iterations)
            return Error{"the bundle adjustment failed"};
        report.solverIterations += *iterations;
        if (round == 1)
            break;
        const StereoRig rig = rigOf(start, u);
        std::vector<double> worst(used.size());
        std::vector<double> rms(used.size());
        for (std::size_t f = 0; f < used.size(); ++f) {
            std::array<double, 2> squares{};
            worst[f] = worstError(rig, wand, used[f], u.wand[f], squares);
            rms[f] = std::sqrt((squares[0] + squares[1]) / static_cast<double>(2 * n));
        }
        const double limit =
            std::max(config.outlierFloor_px, config.outlierFactor * percentile(rms, 0.5));
        std::size_t kept = 0;
        for (std::size_t f = 0; f < used.size(); ++f) {
            if (worst[f] > limit) {
                ++report.framesRefused;
                continue;
            }
            used[kept] = used[f];
            u.wand[kept] = u.wand[f];
            ++kept;
        }
        used.resize(kept);
        u.wand.resize(kept);
    }

    result.rig = rigOf(start, u);
    if (!result.rig.isValid())
        return Error{"the adjusted rig is not valid (cameras at one place)"};
    report.framesUsed = used.size();

    // The report: reprojection, length of the wand triangulated freely, coverage.
    std::array<double, 2> squares{};
    std::vector<double> lengthErrors;
    std::array<std::array<bool, 64>, 2> cells{};
    for (std::size_t f = 0; f < used.size(); ++f) {
        worstError(result.rig, wand, used[f], u.wand[f], squares);
        if (triangulateWand(result.rig, used[f], n, points))
            lengthErrors.push_back(std::abs((points[n - 1] - points[0]).norm() - wand.length_mm()));
        for (int c = 0; c < 2; ++c) {
            const CameraIntrinsics& in = start.camera(c).intrinsics();
            for (std::size_t k = 0; k < n; ++k) {
                const Vec2& px = used[f].pixel(c, k);
                const int cx = std::clamp(static_cast<int>(8.0 * px.x() / in.width_px), 0, 7);
                const int cy = std::clamp(static_cast<int>(8.0 * px.y() / in.height_px), 0, 7);
                cells[static_cast<std::size_t>(c)][static_cast<std::size_t>(cy * 8 + cx)] = true;
            }
        }
    }
    for (std::size_t c = 0; c < 2; ++c) {
        report.reprojectionRms_px[c] =
            std::sqrt(squares[c] / static_cast<double>(std::max<std::size_t>(1, used.size() * n)));
        report.coverage[c] =
            static_cast<double>(std::count(cells[c].begin(), cells[c].end(), true)) / 64.0;
    }
    double sum = 0.0;
    for (double e : lengthErrors)
        sum += e * e;
    report.lengthErrorRms_mm =
        lengthErrors.empty() ? 0.0 : std::sqrt(sum / static_cast<double>(lengthErrors.size()));
    report.lengthError95_mm = percentile(lengthErrors, 0.95);
    report.lengthErrorMax_mm =
        lengthErrors.empty() ? 0.0 : *std::max_element(lengthErrors.begin(), lengthErrors.end());

    const CameraExtrinsics& before = start.camera(1).extrinsics();
    const CameraExtrinsics& after = result.rig.camera(1).extrinsics();
    const Eigen::AngleAxisd turn(after.rotation_cam_from_rig *
                                 before.rotation_cam_from_rig.transpose());
    report.rotationChange_deg = turn.angle() * 180.0 / kPi;
    report.positionChange_mm =
        (start.camera(1).centre_rig_mm() - result.rig.camera(1).centre_rig_mm()).norm();

    for (int c = 0; c < 2; ++c) {
        const std::size_t i = static_cast<std::size_t>(c);
        if (report.coverage[i] < config.poorCoverage)
            report.warnings.push_back("camera " + std::to_string(c) + ": the wand covered only " +
                                      percent(report.coverage[i]) +
                                      " of the image; wave it into every corner");
        if (report.reprojectionRms_px[i] > config.poorReprojection_px)
            report.warnings.push_back(
                "camera " + std::to_string(c) + ": reprojection RMS above " +
                std::to_string(config.poorReprojection_px).substr(0, 4) +
                " px: the blobs, the intrinsics or the wand spacings are off");
    }
    if (report.lengthErrorRms_mm > config.poorLength_mm)
        report.warnings.push_back("the wand's length comes out with an RMS error above " +
                                  std::to_string(config.poorLength_mm).substr(0, 4) + " mm");
    result.report = std::move(report);
    return result;
}

} // namespace

Result<RigCalibrationResult> calibrateRig(const StereoRig& start, const WandSpec& wand,
                                          std::span<const WandFramePair> pairs,
                                          const RigCalibrationConfig& config) {
    if (!start.camera(0).isValid() || !start.camera(1).isValid())
        return Error{"the starting rig's cameras are not valid"};
    if (!wand.isValid())
        return Error{"the wand needs two to eight markers at positive spacings"};
    const std::size_t n = wand.markerCount;

    RigCalibrationReport report;
    report.framePairs = pairs.size();
    if (pairs.size() < config.minFrames)
        return Error{"the wand was found in both images of only " + std::to_string(pairs.size()) +
                     " frame pairs, at least " + std::to_string(config.minFrames) +
                     " needed (check --wand and that the wand was in view of both cameras)"};

    std::vector<Ordered> ordered = spread(pairs, config.maxFrames, report);

    // (1) Essential matrix. Pairs whose ends both images name give correspondences at once;
    // where a wand's ends are open, camera 1's reading is the one the starting rig's epipolar
    // geometry prefers, unless enough named pairs give a better one first.
    auto isNamed = [](const Ordered& o) {
        return !o.pair->sightings[0].endsAmbiguous && !o.pair->sightings[1].endsAmbiguous;
    };
    std::mt19937_64 random(config.seed);
    const double focal =
        0.25 * (start.camera(0).intrinsics().fx_px + start.camera(0).intrinsics().fy_px +
                start.camera(1).intrinsics().fx_px + start.camera(1).intrinsics().fy_px);
    const double threshold = std::pow(config.ransacThreshold_px / focal, 2.0);

    std::vector<NormalizedPair> normalized(ordered.size());
    auto ransacEssential = [&](const std::vector<std::size_t>& members) -> std::optional<Mat3> {
        std::vector<Vec2> x0, x1;
        for (std::size_t i : members)
            for (std::size_t k = 0; k < n; ++k) {
                x0.push_back(normalized[i].x[0][k]);
                x1.push_back(normalized[i].x[1][k]);
            }
        if (members.size() < 8)
            return std::nullopt;
        std::optional<Mat3> best;
        std::size_t bestInliers = 0;
        std::uniform_int_distribution<std::size_t> pick(0, members.size() - 1);
        std::uniform_int_distribution<std::size_t> marker(0, n - 1);
        std::array<Vec2, 8> s0, s1;
        for (int iteration = 0; iteration < config.ransacIterations; ++iteration) {
            // Eight markers of eight different pairs: one pair's markers lie on one line.
            std::array<std::size_t, 8> chosen{};
            for (std::size_t j = 0; j < 8; ++j) {
                std::size_t candidate;
                do
                    candidate = pick(random);
                while (std::find(chosen.begin(), chosen.begin() + static_cast<long>(j),
                                 candidate) != chosen.begin() + static_cast<long>(j));
                chosen[j] = candidate;
                const std::size_t k = marker(random);
                s0[j] = normalized[members[candidate]].x[0][k];
                s1[j] = normalized[members[candidate]].x[1][k];
            }
            const std::optional<Mat3> E = eightPoint(s0, s1);
            if (!E)
                continue;
            std::size_t inliers = 0;
            for (std::size_t i = 0; i < x0.size(); ++i)
                inliers += sampson(*E, x0[i], x1[i]) < threshold ? 1u : 0u;
            if (inliers > bestInliers) {
                bestInliers = inliers;
                best = E;
            }
        }
        if (!best)
            return std::nullopt;
        std::vector<Vec2> in0, in1;
        for (std::size_t i = 0; i < x0.size(); ++i)
            if (sampson(*best, x0[i], x1[i]) < threshold) {
                in0.push_back(x0[i]);
                in1.push_back(x1[i]);
            }
        return eightPoint(in0, in1);
    };

    std::vector<std::size_t> named;
    for (std::size_t i = 0; i < ordered.size(); ++i) {
        normalized[i] = normalize(start, ordered[i], n);
        if (normalized[i].valid && isNamed(ordered[i]))
            named.push_back(i);
    }
    Mat3 E = essentialOf(start);
    if (named.size() >= config.minFrames / 2)
        if (const std::optional<Mat3> fromNamed = ransacEssential(named))
            E = *fromNamed;

    std::vector<std::size_t> all;
    for (std::size_t i = 0; i < ordered.size(); ++i) {
        if (!normalized[i].valid)
            continue;
        if (resolveOpenEnds(E, normalized[i], n, ordered[i]))
            normalized[i] = normalize(start, ordered[i], n);
        all.push_back(i);
    }
    const std::optional<Mat3> essential = ransacEssential(all);
    if (!essential)
        return Error{"no camera pose fits the wand sightings (essential matrix failed)"};
    std::vector<Vec2> x0, x1;
    for (std::size_t i : all)
        for (std::size_t k = 0; k < n; ++k) {
            x0.push_back(normalized[i].x[0][k]);
            x1.push_back(normalized[i].x[1][k]);
        }
    std::optional<Pose> pose = decompose(*essential, x0, x1);
    if (!pose)
        return Error{"no camera pose puts the wand in front of both cameras"};

    // Scale: the median end-to-end length of the wand triangulated with a unit baseline.
    StereoRig unit(start.camera(0), withPose(start.camera(1), *pose));
    std::vector<double> lengths;
    std::array<Vec3, kMaxWandMarkers> points{};
    for (std::size_t i : all)
        if (triangulateWand(unit, ordered[i], n, points))
            lengths.push_back((points[n - 1] - points[0]).norm());
    if (lengths.size() < config.minFrames)
        return Error{"the wand triangulates in front of both cameras in only " +
                     std::to_string(lengths.size()) + " frame pairs"};
    std::nth_element(lengths.begin(), lengths.begin() + static_cast<long>(lengths.size() / 2),
                     lengths.end());
    pose->t *= wand.length_mm() / lengths[lengths.size() / 2];
    const StereoRig initial(start.camera(0), withPose(start.camera(1), *pose));

    return adjustAndReport(start, initial, wand, ordered, all, std::move(report), config, false);
}

Result<RigCalibrationReport> assessRig(const StereoRig& rig, const WandSpec& wand,
                                       std::span<const WandFramePair> pairs,
                                       const RigCalibrationConfig& config) {
    if (!rig.isValid() || !wand.isValid())
        return Error{"the rig or the wand is not valid"};
    const std::size_t n = wand.markerCount;
    RigCalibrationReport report;
    report.framePairs = pairs.size();
    std::vector<Ordered> ordered = spread(pairs, config.maxFrames, report);
    const Mat3 E = essentialOf(rig);
    std::vector<std::size_t> all;
    for (std::size_t i = 0; i < ordered.size(); ++i) {
        const NormalizedPair x = normalize(rig, ordered[i], n);
        if (!x.valid)
            continue;
        resolveOpenEnds(E, x, n, ordered[i]);
        all.push_back(i);
    }
    Result<RigCalibrationResult> assessed =
        adjustAndReport(rig, rig, wand, ordered, all, std::move(report), config, true);
    if (!assessed)
        return assessed.error();
    return std::move(assessed->report);
}

} // namespace edgetrack
