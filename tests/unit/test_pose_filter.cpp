// Unit tests of the pose filter: raw by default, less jitter, no lag on steady motion, prediction.
#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "core/pose_filter.hpp"

namespace edgetrack {
namespace {

/// A body moving at 200 mm/s and turning at 2 rad/s about a tilted axis.
RigidTransform truthAt(double t) {
    RigidTransform T;
    T.translation_mm = Vec3(200.0 * t, -50.0 * t, 600.0);
    T.rotation = Quat(Eigen::AngleAxisd(2.0 * t, Vec3(1.0, 2.0, 2.0).normalized()));
    return T;
}

struct Errors {
    double position_mm = 0.0;
    double rotation_rad = 0.0;
};

/// RMS errors of \a filter over 3 s of noisy measurements at 100 Hz, after a 0.5 s settling,
/// against the truth \a compareAhead_s after each measurement; and of the raw measurements.
std::pair<Errors, Errors> run(PoseFilter& filter, double compareAhead_s) {
    std::mt19937 random(5);
    std::normal_distribution<double> positionNoise(0.0, 0.1);
    std::normal_distribution<double> angleNoise(0.0, 0.002);
    Errors filtered, raw;
    int count = 0;
    for (int f = 0; f < 300; ++f) {
        const double t = 0.01 * f;
        RigidTransform measured = truthAt(t);
        measured.translation_mm +=
            Vec3(positionNoise(random), positionNoise(random), positionNoise(random));
        measured.rotation = Quat(Eigen::AngleAxisd(angleNoise(random), Vec3::UnitX())) *
                            Quat(Eigen::AngleAxisd(angleNoise(random), Vec3::UnitY())) *
                            measured.rotation;
        const RigidTransform out = filter.update(t, measured);
        if (f < 50)
            continue;
        const RigidTransform truth = truthAt(t + compareAhead_s);
        filtered.position_mm += (out.translation_mm - truth.translation_mm).squaredNorm();
        filtered.rotation_rad +=
            std::pow(rotationAngleBetween_rad(out.rotation, truth.rotation), 2);
        raw.position_mm += (measured.translation_mm - truth.translation_mm).squaredNorm();
        raw.rotation_rad +=
            std::pow(rotationAngleBetween_rad(measured.rotation, truth.rotation), 2);
        ++count;
    }
    for (Errors* e : {&filtered, &raw}) {
        e->position_mm = std::sqrt(e->position_mm / count);
        e->rotation_rad = std::sqrt(e->rotation_rad / count);
    }
    return {filtered, raw};
}

TEST(PoseFilter, PassesPosesThroughByDefault) {
    PoseFilter filter;
    const RigidTransform measured = truthAt(0.3);
    for (double t : {0.0, 0.01, 0.02}) {
        const RigidTransform out = filter.update(t, measured);
        EXPECT_EQ(out.translation_mm, measured.translation_mm);
        EXPECT_EQ(out.rotation.coeffs(), measured.rotation.coeffs());
    }
    EXPECT_FALSE(filter.predict(0.03));
}

TEST(PoseFilter, SmoothsJitterWithoutLaggingASteadyMotion) {
    PoseFilterConfig config;
    config.enabled = true;
    config.poseGain = 0.3;
    config.rateGain = 0.05;
    PoseFilter filter(config);
    const auto [filtered, raw] = run(filter, 0.0);
    // Less jitter than the measurements, and no lag: a lagging filter on 200 mm/s would be
    // millimetres behind.
    EXPECT_LT(filtered.position_mm, 0.8 * raw.position_mm);
    EXPECT_LT(filtered.rotation_rad, 0.8 * raw.rotation_rad);
}

TEST(PoseFilter, PredictsAheadToHideLatency) {
    PoseFilterConfig config;
    config.enabled = true;
    config.predictAhead_s = 0.02;
    PoseFilter filter(config);
    const auto [filtered, raw] = run(filter, 0.02);
    // The raw pose is 20 ms old by then: 4 mm and 2.3 degrees behind.
    EXPECT_GT(raw.position_mm, 3.5);
    EXPECT_LT(filtered.position_mm, 0.5);
    EXPECT_LT(filtered.rotation_rad, 0.01);
    // And between measurements, the state alone predicts as far.
    const std::optional<RigidTransform> between = filter.predict(2.995);
    ASSERT_TRUE(between);
    EXPECT_LT((between->translation_mm - truthAt(2.995).translation_mm).norm(), 0.5);
}

TEST(PoseFilter, StartsAfreshAfterAGap) {
    PoseFilterConfig config;
    config.enabled = true;
    PoseFilter filter(config);
    for (int f = 0; f < 20; ++f)
        filter.update(0.01 * f, truthAt(0.01 * f));
    EXPECT_FALSE(filter.predict(1.0)) << "unseen longer than resetAfter_s";
    RigidTransform elsewhere = truthAt(1.0);
    elsewhere.translation_mm += Vec3(100.0, 0.0, 0.0);
    const RigidTransform out = filter.update(1.0, elsewhere);
    EXPECT_LT((out.translation_mm - elsewhere.translation_mm).norm(), 1e-9);
}

TEST(PoseFilter, TurnsThroughHalfARevolutionWithoutFlipping) {
    PoseFilterConfig config;
    config.enabled = true;
    PoseFilter filter(config);
    // 3 rad/s for 2 s: past pi, where q and -q meet.
    for (int f = 0; f < 200; ++f) {
        const double t = 0.01 * f;
        RigidTransform T;
        T.rotation = Quat(Eigen::AngleAxisd(3.0 * t, Vec3::UnitZ()));
        // Quaternion signs as a tracker may report them: alternating.
        if (f % 2)
            T.rotation.coeffs() *= -1.0;
        const RigidTransform out = filter.update(t, T);
        if (f > 20) {
            EXPECT_LT(rotationAngleBetween_rad(out.rotation, T.rotation), 1e-3) << "frame " << f;
        }
    }
}

} // namespace
} // namespace edgetrack
