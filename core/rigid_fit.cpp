// Least-squares rigid fit of two point sets (Kabsch / Umeyama without scale).
#include "core/rigid_fit.hpp"

#include <cmath>

#include <Eigen/Geometry>
#include <Eigen/SVD>

namespace edgetrack {

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

} // namespace edgetrack
