// Tests of rigid transforms and quaternion conversions.
#include <numbers>

#include <gtest/gtest.h>

#include "core/rigid_transform.hpp"

using namespace edgetrack;

namespace {
RigidTransform sampleTransform() {
    RigidTransform t;
    t.rotation = Quat(Eigen::AngleAxisd(0.7, Vec3(1.0, -2.0, 0.5).normalized()));
    t.translation_mm = {12.0, -40.0, 530.0};
    return t;
}
} // namespace

TEST(RigidTransform, InverseUndoes) {
    const RigidTransform T_rig_from_model = sampleTransform();
    const Vec3 p_model{3.0, -4.0, 5.0};
    const Vec3 p_rig = T_rig_from_model.apply(p_model);
    EXPECT_LT((T_rig_from_model.inverse().apply(p_rig) - p_model).norm(), 1e-12);
    const RigidTransform identity = T_rig_from_model * T_rig_from_model.inverse();
    EXPECT_LT(identity.translation_mm.norm(), 1e-12);
    EXPECT_LT(rotationAngleBetween_rad(identity.rotation, Quat::Identity()), 1e-7);
}

TEST(RigidTransform, ComposesRightToLeft) {
    const RigidTransform a = sampleTransform();
    RigidTransform b;
    b.rotation = Quat(Eigen::AngleAxisd(-1.1, Vec3::UnitZ()));
    b.translation_mm = {1.0, 2.0, 3.0};
    const Vec3 p{-7.0, 0.5, 2.0};
    EXPECT_LT(((a * b).apply(p) - a.apply(b.apply(p))).norm(), 1e-12);
}

TEST(RigidTransform, MatrixRoundTrip) {
    const RigidTransform t = sampleTransform();
    const RigidTransform back = RigidTransform::fromMatrix(t.rotationMatrix(), t.translation_mm);
    EXPECT_LT(rotationAngleBetween_rad(t.rotation, back.rotation), 1e-7);
    EXPECT_EQ(back.translation_mm, t.translation_mm);
}

TEST(Quaternion, ScalarFirstRoundTripWithCanonicalSign) {
    const Quat q = sampleTransform().rotation;
    const auto wxyz = wxyzFromQuaternion(q);
    EXPECT_GE(wxyz[0], 0.0);
    const Quat back = quaternionFromWxyz(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
    EXPECT_LT(rotationAngleBetween_rad(q, back), 1e-7);

    // -q is the same rotation and must print the same numbers.
    const Quat negated(-q.w(), -q.x(), -q.y(), -q.z());
    const auto wxyzNegated = wxyzFromQuaternion(negated);
    for (std::size_t i = 0; i < 4; ++i)
        EXPECT_DOUBLE_EQ(wxyzNegated[i], wxyz[i]);
}

TEST(Quaternion, FromWxyzNormalisesAndFollowsEigenOrder) {
    // 90 degrees about z, scalar first, scaled by 2: (w, z) = 2 * (cos 45, sin 45).
    const double c = 2.0 * std::cos(std::numbers::pi / 4.0);
    const Quat q = quaternionFromWxyz(c, 0.0, 0.0, c);
    EXPECT_NEAR(q.norm(), 1.0, 1e-15);
    EXPECT_LT((q * Vec3::UnitX() - Vec3::UnitY()).norm(), 1e-12);
}

TEST(Quaternion, AngleBetweenRotations) {
    const Quat a = Quat::Identity();
    const Quat b(Eigen::AngleAxisd(std::numbers::pi / 2.0, Vec3::UnitZ()));
    EXPECT_NEAR(rotationAngleBetween_rad(a, b), std::numbers::pi / 2.0, 1e-12);
    const Quat bNegated(-b.w(), -b.x(), -b.y(), -b.z());
    EXPECT_NEAR(rotationAngleBetween_rad(b, bNegated), 0.0, 1e-7);
}
