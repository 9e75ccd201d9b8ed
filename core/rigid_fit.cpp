// Least-squares rigid fit of two point sets (Kabsch / Umeyama without scale).
#include "core/rigid_fit.hpp"

#include <cmath>

#include <Eigen/Geometry>
#include <Eigen/LU>
#include <Eigen/SVD>

namespace edgetrack {

bool offOneLine(std::span<const Vec3> points, double minSpread_mm) {
    if (points.size() < 3)
        return false;
    std::size_t a = 0, b = 1;
    double widest = -1.0;
    for (std::size_t i = 0; i < points.size(); ++i)
        for (std::size_t j = i + 1; j < points.size(); ++j)
            if (const double d = (points[i] - points[j]).squaredNorm(); d > widest) {
                widest = d;
                a = i;
                b = j;
            }
    const Vec3 direction = (points[b] - points[a]).normalized();
    for (const Vec3& p : points) {
        const Vec3 off = p - points[a];
        if ((off - off.dot(direction) * direction).norm() >= minSpread_mm)
            return true;
    }
    return false;
}

std::optional<RigidFit> fitRigid(std::span<const Vec3> from, std::span<const Vec3> to) {
    const std::size_t n = from.size();
    if (n != to.size() || n < 3)
        return std::nullopt;

    Vec3 centroidFrom = Vec3::Zero();
    Vec3 centroidTo = Vec3::Zero();
    for (std::size_t i = 0; i < n; ++i) {
        centroidFrom += from[i];
        centroidTo += to[i];
    }
    const double inverseCount = 1.0 / static_cast<double>(n);
    centroidFrom *= inverseCount;
    centroidTo *= inverseCount;

    Mat3 covariance = Mat3::Zero();
    double spread = 0.0;
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3 a = from[i] - centroidFrom;
        covariance += (to[i] - centroidTo) * a.transpose();
        spread += a.squaredNorm();
    }

    const Eigen::JacobiSVD<Mat3> svd(covariance, Eigen::ComputeFullU | Eigen::ComputeFullV);
    const Vec3 singular = svd.singularValues();
    // Collinear (or coincident) points leave two singular values at zero; a relative test keeps
    // this independent of the object's size.
    if (!(singular(1) > 1e-9 * (singular(0) + spread)))
        return std::nullopt;

    Mat3 reflectionFix = Mat3::Identity();
    if ((svd.matrixU() * svd.matrixV().transpose()).determinant() < 0.0)
        reflectionFix(2, 2) = -1.0;
    const Mat3 rotation = svd.matrixU() * reflectionFix * svd.matrixV().transpose();

    RigidFit fit;
    fit.transform = RigidTransform::fromMatrix(rotation, centroidTo - rotation * centroidFrom);
    double sumSquares = 0.0;
    for (std::size_t i = 0; i < n; ++i)
        sumSquares += (to[i] - fit.transform.apply(from[i])).squaredNorm();
    fit.rms_mm = std::sqrt(sumSquares * inverseCount);
    return fit;
}

std::optional<RigidTransform> fitTriangle(const std::array<Vec3, 3>& from,
                                          const std::array<Vec3, 3>& to) {
    const Vec3 normalFrom = (from[1] - from[0]).cross(from[2] - from[0]);
    const Vec3 normalTo = (to[1] - to[0]).cross(to[2] - to[0]);
    // Twice the area against the squared sides: a test of flatness that, like fitRigid's,
    // does not depend on the triangle's size.
    auto flat = [](const Vec3& normal, const std::array<Vec3, 3>& t) {
        return !(normal.norm() >
                 1e-9 * ((t[1] - t[0]).squaredNorm() + (t[2] - t[0]).squaredNorm()));
    };
    if (flat(normalFrom, from) || flat(normalTo, to))
        return std::nullopt;
    const Vec3 centroidFrom = (from[0] + from[1] + from[2]) / 3.0;
    const Vec3 centroidTo = (to[0] + to[1] + to[2]) / 3.0;
    const Vec3 axis = normalTo.normalized();
    const Quat tilt = Quat::FromTwoVectors(normalFrom, normalTo);
    double sine = 0.0, cosine = 0.0;
    for (std::size_t i = 0; i < 3; ++i) {
        const Vec3 a = tilt * (from[i] - centroidFrom);
        const Vec3 b = to[i] - centroidTo;
        sine += axis.dot(a.cross(b));
        cosine += a.dot(b);
    }
    RigidTransform transform;
    transform.rotation =
        (Quat(Eigen::AngleAxisd(std::atan2(sine, cosine), axis)) * tilt).normalized();
    transform.translation_mm = centroidTo - transform.rotation * centroidFrom;
    return transform;
}

namespace {

/// The centroids of two point sets and the sum of (from_i - centroid)(to_i - centroid)^T with
/// the two spreads (sums of squared distances from the centroids), for the closed-form RMS.
struct CentredSums {
    Vec3 centroidFrom = Vec3::Zero();
    Vec3 centroidTo = Vec3::Zero();
    Mat3 crossCovariance = Mat3::Zero();
    double spread = 0.0;
};

CentredSums centredSums(std::span<const Vec3> from, std::span<const Vec3> to) {
    const std::size_t n = from.size();
    CentredSums sums;
    for (std::size_t i = 0; i < n; ++i) {
        sums.centroidFrom += from[i];
        sums.centroidTo += to[i];
    }
    sums.centroidFrom /= static_cast<double>(n);
    sums.centroidTo /= static_cast<double>(n);
    for (std::size_t i = 0; i < n; ++i) {
        const Vec3 a = from[i] - sums.centroidFrom, b = to[i] - sums.centroidTo;
        sums.crossCovariance += a * b.transpose();
        sums.spread += a.squaredNorm() + b.squaredNorm();
    }
    return sums;
}

/// The largest eigenvalue of the quaternion key matrix of \a m (sum of a b^T over centred pairs),
/// which is the largest trace(R m) over rotations R: Newton's method on the characteristic
/// polynomial, from \a above, a value no smaller than it ((|a|^2 + |b|^2) / 2 summed).
std::optional<double> largestKeyEigenvalue(const Mat3& m, double above) {
    const double sxx = m(0, 0), sxy = m(0, 1), sxz = m(0, 2);
    const double syx = m(1, 0), syy = m(1, 1), syz = m(1, 2);
    const double szx = m(2, 0), szy = m(2, 1), szz = m(2, 2);
    Eigen::Matrix4d key;
    key << sxx + syy + szz, syz - szy, szx - sxz, sxy - syx, //
        syz - szy, sxx - syy - szz, sxy + syx, szx + sxz,    //
        szx - sxz, sxy + syx, -sxx + syy - szz, syz + szy,   //
        sxy - syx, szx + sxz, syz + szy, -sxx - syy + szz;
    // lambda^4 + c2 lambda^2 + c1 lambda + c0: the key matrix has no trace.
    const double c2 = -2.0 * m.squaredNorm();
    const double c1 = -8.0 * m.determinant();
    const double c0 = key.determinant();
    double lambda = above;
    for (int step = 0; step < 50; ++step) {
        const double square = lambda * lambda;
        const double value = ((square + c2) * lambda + c1) * lambda + c0;
        const double slope = (4.0 * square + 2.0 * c2) * lambda + c1;
        if (!(slope != 0.0))
            return std::nullopt;
        const double next = lambda - value / slope;
        if (!std::isfinite(next))
            return std::nullopt;
        if (std::abs(next - lambda) <= 1e-11 * std::abs(next))
            return next;
        lambda = next;
    }
    return std::nullopt;
}

} // namespace

std::optional<double> fitRms(std::span<const Vec3> from, std::span<const Vec3> to) {
    const std::size_t n = from.size();
    if (n != to.size() || n < 3)
        return std::nullopt;
    const CentredSums sums = centredSums(from, to);
    const std::optional<double> lambda =
        largestKeyEigenvalue(sums.crossCovariance, 0.5 * sums.spread);
    if (!lambda)
        return std::nullopt;
    return std::sqrt(std::max(0.0, sums.spread - 2.0 * *lambda) / static_cast<double>(n));
}

bool leaveOneOutRms(std::span<const Vec3> from, std::span<const Vec3> to,
                    std::span<double> rms_mm) {
    const std::size_t n = from.size();
    if (n != to.size() || n < 4 || rms_mm.size() < n)
        return false;
    const CentredSums sums = centredSums(from, to);
    // Without pair k the centroids move by -a_k / (n - 1) and -b_k / (n - 1), which takes
    // n / (n - 1) times its own term out of each sum.
    const double remaining = static_cast<double>(n - 1);
    const double scale = static_cast<double>(n) / remaining;
    for (std::size_t k = 0; k < n; ++k) {
        const Vec3 a = from[k] - sums.centroidFrom, b = to[k] - sums.centroidTo;
        const Mat3 m = sums.crossCovariance - scale * a * b.transpose();
        const double spread = sums.spread - scale * (a.squaredNorm() + b.squaredNorm());
        const std::optional<double> lambda = largestKeyEigenvalue(m, 0.5 * spread);
        if (!lambda)
            return false;
        rms_mm[k] = std::sqrt(std::max(0.0, spread - 2.0 * *lambda) / remaining);
    }
    return true;
}

} // namespace edgetrack
