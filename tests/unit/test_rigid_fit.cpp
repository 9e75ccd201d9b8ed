// Tests of the least-squares rigid fit against known transforms and against Eigen::umeyama.
#include <random>
#include <vector>

#include <Eigen/Geometry>
#include <gtest/gtest.h>

#include "core/rigid_fit.hpp"
#include "tests/support/alloc_guard.hpp"

using namespace edgetrack;

namespace {

struct PointSets {
    std::vector<Vec3> model_mm;
    std::vector<Vec3> rig_mm;
    RigidTransform T_rig_from_model;
};

PointSets makeSets(int count, double noise_mm, unsigned seed) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> cube(-35.0, 35.0);
    std::normal_distribution<double> noise(0.0, noise_mm);
    PointSets s;
    s.T_rig_from_model.rotation = Quat(Eigen::AngleAxisd(2.1, Vec3(0.3, 0.9, -0.2).normalized()));
    s.T_rig_from_model.translation_mm = {-20.0, 35.0, 560.0};
    for (int i = 0; i < count; ++i) {
        const Vec3 p{cube(random), cube(random), cube(random)};
        s.model_mm.push_back(p);
        s.rig_mm.push_back(s.T_rig_from_model.apply(p) +
                           Vec3{noise(random), noise(random), noise(random)});
    }
    return s;
}

} // namespace

TEST(RigidFit, RecoversExactTransform) {
    const PointSets s = makeSets(12, 0.0, 1);
    const auto fit = fitRigid(s.model_mm, s.rig_mm);
    ASSERT_TRUE(fit);
    EXPECT_LT(fit->rms_mm, 1e-9);
    EXPECT_LT((fit->transform.translation_mm - s.T_rig_from_model.translation_mm).norm(), 1e-9);
    EXPECT_LT(rotationAngleBetween_rad(fit->transform.rotation, s.T_rig_from_model.rotation), 1e-7);
}

TEST(RigidFit, AgreesWithEigenUmeyamaOnNoisyData) {
    const PointSets s = makeSets(30, 0.2, 2);
    const auto fit = fitRigid(s.model_mm, s.rig_mm);
    ASSERT_TRUE(fit);

    Eigen::Matrix3Xd from(3, 30), to(3, 30);
    for (int i = 0; i < 30; ++i) {
        from.col(i) = s.model_mm[static_cast<std::size_t>(i)];
        to.col(i) = s.rig_mm[static_cast<std::size_t>(i)];
    }
    const Eigen::Matrix4d reference = Eigen::umeyama(from, to, false);
    EXPECT_LT((fit->transform.rotationMatrix() - reference.topLeftCorner<3, 3>()).norm(), 1e-9);
    EXPECT_LT((fit->transform.translation_mm - reference.topRightCorner<3, 1>()).norm(), 1e-9);
    // Residual of 0.2 mm per axis: sqrt(3) * 0.2 expected, less the fit's degrees of freedom.
    EXPECT_GT(fit->rms_mm, 0.2);
    EXPECT_LT(fit->rms_mm, 0.45);
}

TEST(RigidFit, PlanarPointsGiveAProperRotation) {
    // Four coplanar points: the SVD alone could return a reflection.
    const std::vector<Vec3> model{{0, 0, 0}, {50, 0, 0}, {0, 50, 0}, {50, 50, 0}};
    RigidTransform T;
    T.rotation = Quat(Eigen::AngleAxisd(3.0, Vec3(1, 1, 0).normalized()));
    T.translation_mm = {5, 6, 7};
    std::vector<Vec3> rig;
    for (const Vec3& p : model)
        rig.push_back(T.apply(p));
    const auto fit = fitRigid(model, rig);
    ASSERT_TRUE(fit);
    EXPECT_NEAR(fit->transform.rotationMatrix().determinant(), 1.0, 1e-12);
    EXPECT_LT(fit->rms_mm, 1e-9);
}

TEST(RigidFit, RefusesDegenerateInput) {
    const std::vector<Vec3> two{{0, 0, 0}, {1, 0, 0}};
    EXPECT_FALSE(fitRigid(two, two));
    const std::vector<Vec3> collinear{{0, 0, 0}, {10, 0, 0}, {25, 0, 0}, {-3, 0, 0}};
    EXPECT_FALSE(fitRigid(collinear, collinear));
    const std::vector<Vec3> three{{0, 0, 0}, {10, 0, 0}, {0, 10, 0}};
    EXPECT_FALSE(fitRigid(three, collinear));
    EXPECT_TRUE(fitRigid(three, three));
}

TEST(RigidFit, DoesNotAllocate) {
    const PointSets s = makeSets(30, 0.1, 3);
    double sink = 0.0;
    const auto count = test::countAllocations([&] {
        for (int i = 0; i < 100; ++i)
            sink += fitRigid(s.model_mm, s.rig_mm)->rms_mm;
    });
    EXPECT_EQ(count, 0u);
    EXPECT_GT(sink, 0.0);
}

TEST(RigidFit, TriangleFitIsTheLeastSquaresFit) {
    // Triangles of nearly equal sides in every attitude, corners paired by index: the closed form
    // must give fitRigid's transform (its SVD the reference).
    std::mt19937 random(4);
    std::uniform_real_distribution<double> coordinate(-40.0, 40.0);
    std::normal_distribution<double> noise(0.0, 0.3);
    std::uniform_real_distribution<double> angle(-3.1, 3.1);
    int compared = 0;
    for (int trial = 0; trial < 500; ++trial) {
        std::array<Vec3, 3> from, to;
        RigidTransform T;
        T.rotation = Quat(Eigen::AngleAxisd(
            angle(random),
            Vec3(coordinate(random), coordinate(random), coordinate(random)).normalized()));
        T.translation_mm = {coordinate(random), coordinate(random), 500.0};
        for (std::size_t i = 0; i < 3; ++i) {
            from[i] = {coordinate(random), coordinate(random), coordinate(random)};
            to[i] = T.apply(from[i]) + Vec3{noise(random), noise(random), noise(random)};
        }
        const auto reference = fitRigid(from, to);
        const auto closed = fitTriangle(from, to);
        ASSERT_EQ(reference.has_value(), closed.has_value());
        if (!reference)
            continue;
        EXPECT_LT((closed->rotationMatrix() - reference->transform.rotationMatrix()).norm(), 1e-9);
        EXPECT_LT((closed->translation_mm - reference->transform.translation_mm).norm(), 1e-7);
        ++compared;
    }
    EXPECT_GT(compared, 490);
    const std::array<Vec3, 3> line{Vec3{0, 0, 0}, Vec3{10, 0, 0}, Vec3{25, 0, 0}};
    const std::array<Vec3, 3> corner{Vec3{0, 0, 0}, Vec3{10, 0, 0}, Vec3{0, 10, 0}};
    EXPECT_FALSE(fitTriangle(line, corner));
    EXPECT_FALSE(fitTriangle(corner, line));
}

// Outlier trimming takes the RMS of every leave-one-out fit from leaveOneOutRms instead of a fit
// each, and a search judges its cliques by fitRms: both must be fitRigid's, on noisy, planar,
// outlying and tiny sets far from the origin.
TEST(RigidFit, LeaveOneOutRmsIsThatOfTheFitWithoutEachPair) {
    auto expectLikeFits = [](const std::vector<Vec3>& from, const std::vector<Vec3>& to) {
        std::vector<double> rms(from.size(), -1.0);
        ASSERT_TRUE(leaveOneOutRms(from, to, rms));
        const std::optional<double> whole = fitRms(from, to);
        ASSERT_TRUE(whole);
        EXPECT_NEAR(*whole, fitRigid(from, to)->rms_mm, 1e-6 + 1e-8 * *whole);
        for (std::size_t k = 0; k < from.size(); ++k) {
            std::vector<Vec3> a = from, b = to;
            a.erase(a.begin() + static_cast<std::ptrdiff_t>(k));
            b.erase(b.begin() + static_cast<std::ptrdiff_t>(k));
            const std::optional<RigidFit> fit = fitRigid(a, b);
            ASSERT_TRUE(fit);
            // Taken from spreads of thousands of mm^2, a residual near zero is known to about a
            // micrometre; the tracker's lie at 0.01-1 mm, known to 1e-10.
            EXPECT_NEAR(rms[k], fit->rms_mm, 1e-6 + 1e-8 * fit->rms_mm)
                << k << " of " << a.size() + 1;
        }
    };
    for (unsigned seed = 1; seed <= 20; ++seed) {
        PointSets s = makeSets(4 + static_cast<int>(seed) * 2, 0.05 * seed, seed);
        expectLikeFits(s.model_mm, s.rig_mm);
        // One point 5 mm off: its own leave-one-out fits best.
        s.rig_mm[seed % s.rig_mm.size()] += Vec3(3.0, -4.0, 0.0);
        std::vector<double> rms(s.model_mm.size());
        ASSERT_TRUE(leaveOneOutRms(s.model_mm, s.rig_mm, rms));
        EXPECT_EQ(static_cast<std::size_t>(std::min_element(rms.begin(), rms.end()) - rms.begin()),
                  seed % s.rig_mm.size());
        expectLikeFits(s.model_mm, s.rig_mm);
        // Flat, as markers on a plate are.
        for (Vec3& p : s.model_mm)
            p.z() = 0.0;
        PointSets flat = s;
        for (std::size_t i = 0; i < flat.model_mm.size(); ++i)
            flat.rig_mm[i] = s.T_rig_from_model.apply(flat.model_mm[i]) +
                             Vec3(0.01 * static_cast<double>(i % 3), -0.02, 0.0);
        expectLikeFits(flat.model_mm, flat.rig_mm);
    }
    // Exact, and a square of four (each three left are a right triangle).
    PointSets exact = makeSets(9, 0.0, 3);
    expectLikeFits(exact.model_mm, exact.rig_mm);
    const std::vector<Vec3> square = {{0, 0, 0}, {40, 0, 0}, {40, 40, 0}, {0, 40, 0}};
    std::vector<Vec3> placed;
    for (const Vec3& p : square)
        placed.push_back(exact.T_rig_from_model.apply(p) + Vec3(0.1, 0.0, -0.05));
    expectLikeFits(square, placed);
    // Refused: too few pairs, or unequal spans.
    std::vector<double> rms(4);
    EXPECT_FALSE(leaveOneOutRms(std::span(square).first(3), std::span(placed).first(3), rms));
    EXPECT_FALSE(leaveOneOutRms(square, std::span(placed).first(3), rms));
    EXPECT_FALSE(fitRms(std::span(square).first(2), std::span(placed).first(2)));
    // A mirror image has the same distances but no rotation onto it.
    std::vector<Vec3> mirrored;
    const PointSets tetra = makeSets(4, 0.0, 5);
    for (const Vec3& p : tetra.rig_mm)
        mirrored.emplace_back(-p.x(), p.y(), p.z());
    EXPECT_NEAR(*fitRms(tetra.model_mm, mirrored), fitRigid(tetra.model_mm, mirrored)->rms_mm,
                1e-8);
    EXPECT_GT(fitRigid(tetra.model_mm, mirrored)->rms_mm, 1.0);
}
