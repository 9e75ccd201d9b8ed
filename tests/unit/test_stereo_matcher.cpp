// Tests of stereo correspondence: block solution equals the full-matrix SVD, markers are exact,
// the epipolar-only baseline makes false markers that SVD matching avoids.
#include <numbers>
#include <numeric>
#include <random>
#include <set>

#include <Eigen/SVD>
#include <gtest/gtest.h>

#include "core/correspondence.hpp"
#include "core/marker_tracker.hpp"
#include "core/stereo_matcher.hpp"
#include "hal/sim/random.hpp"
#include "hal/sim/random_rigs.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/world.hpp"
#include "tests/support/alloc_guard.hpp"

using namespace edgetrack;

namespace {

const StereoRig& simRig() {
    static const StereoRig rig = sim::makeRig(sim::RigSpec{});
    return rig;
}

// Blobs of both cameras for points in the rig frame (exact projections, optional pixel noise).
struct BlobSets {
    std::vector<Blob> camera[2];
    std::vector<int> truthIndex[2];
};

BlobSets project(const std::vector<Vec3>& points, double noise_px = 0.0, unsigned seed = 1) {
    BlobSets sets;
    std::mt19937 random(seed);
    std::normal_distribution<double> noise(0.0, noise_px > 0.0 ? noise_px : 1e-300);
    for (int c = 0; c < 2; ++c)
        for (std::size_t i = 0; i < points.size(); ++i)
            if (auto pixel = simRig().camera(c).project(points[i])) {
                Blob b;
                b.centre_px =
                    *pixel + (noise_px > 0.0 ? Vec2(noise(random), noise(random)) : Vec2::Zero());
                sets.camera[c].push_back(b);
                sets.truthIndex[c].push_back(static_cast<int>(i));
            }
    // Cameras report blobs in their own order, not the truth's.
    std::shuffle(sets.camera[1].begin(), sets.camera[1].end(), random);
    return sets;
}

std::vector<Vec3> randomMarkers(int count, unsigned seed) {
    std::mt19937 random(seed);
    std::uniform_real_distribution<double> x(-100, 220), y(-130, 130), z(450, 700);
    std::vector<Vec3> points;
    while (static_cast<int>(points.size()) < count) {
        const Vec3 p(x(random), y(random), z(random));
        bool apart = true;
        for (const Vec3& q : points)
            apart = apart && (p - q).norm() > 12.0;
        if (apart)
            points.push_back(p);
    }
    return points;
}

// The reference for the solver's shortcuts: the pairs of Scott and Longuet-Higgins from Eigen's
// SVD of the whole block (P = U V^T, mutual maxima of P; no proximity threshold).
std::set<std::pair<int, int>> svdPairs(const ProximityBlock& g) {
    const Eigen::MatrixXd dense = g;
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(dense, Eigen::ComputeThinU | Eigen::ComputeThinV);
    const Eigen::MatrixXd p = svd.matrixU() * svd.matrixV().transpose();
    std::set<std::pair<int, int>> pairs;
    for (Eigen::Index r = 0; r < p.rows(); ++r) {
        Eigen::Index c = 0, back = 0;
        p.row(r).maxCoeff(&c);
        p.col(c).maxCoeff(&back);
        if (back == r)
            pairs.insert({static_cast<int>(r), static_cast<int>(c)});
    }
    return pairs;
}

} // namespace

TEST(BipartiteBlocks, GroupsConnectedElements) {
    BipartiteBlocks blocks(8, 8);
    blocks.reset(5, 4);
    blocks.link(0, 0);
    blocks.link(1, 0);
    blocks.link(1, 1);
    blocks.link(3, 3);
    // Left 2 and 4 and right 2 are linked to nothing.
    blocks.build();
    ASSERT_EQ(blocks.blockCount(), 2u);
    std::set<std::vector<int>> lefts, rights;
    for (std::size_t b = 0; b < 2; ++b) {
        lefts.insert({blocks.leftOf(b).begin(), blocks.leftOf(b).end()});
        rights.insert({blocks.rightOf(b).begin(), blocks.rightOf(b).end()});
    }
    EXPECT_EQ(lefts, (std::set<std::vector<int>>{{0, 1}, {3}}));
    EXPECT_EQ(rights, (std::set<std::vector<int>>{{0, 1}, {3}}));
}

// The proximity against eq. 1-4 written out by brute force on the rectified blob centres: the
// region R of each blob (the other blobs within S/2 in x and in y; when there are more than 32, the
// 32 nearest in y), eq. 2's mean closest distance, eq. 4's product of Gaussians. A dense cluster
// gives some blobs more neighbours than a list holds.
TEST(StereoMatcher, ProximityFollowsTheEquationsOfThePaper) {
    constexpr std::size_t kListCapacity = 32;
    std::vector<Vec3> points = randomMarkers(60, 3);
    std::mt19937 random(8);
    std::uniform_real_distribution<double> clusterXy(0.0, 45.0), clusterZ(500.0, 510.0);
    for (int i = 0; i < 45; ++i)
        points.push_back({clusterXy(random), clusterXy(random), clusterZ(random)});
    const BlobSets sets = project(points, 0.3, 3);
    const StereoConfig config;
    StereoMatcher matcher(simRig(), config, 256);
    matcher.prepare(sets.camera[0], sets.camera[1]);

    std::vector<std::optional<Vec2>> rectified[2];
    for (int c = 0; c < 2; ++c)
        for (const Blob& b : sets.camera[c])
            rectified[c].push_back(simRig().rectify(c, b.centre_px));
    const double half = 0.5 * config.neighbourhood_px;
    auto regionOf = [&](int c, std::size_t i) {
        std::vector<Vec2> offsets;
        for (std::size_t k = 0; k < rectified[c].size(); ++k)
            if (k != i && rectified[c][k]) {
                const Vec2 d = *rectified[c][k] - *rectified[c][i];
                if (std::abs(d.x()) < half && std::abs(d.y()) < half)
                    offsets.push_back(d);
            }
        if (offsets.size() > kListCapacity) {
            std::sort(offsets.begin(), offsets.end(), [](const Vec2& a, const Vec2& b) {
                return std::abs(a.y()) < std::abs(b.y());
            });
            offsets.resize(kListCapacity);
        }
        return offsets;
    };
    std::size_t compared = 0, crowded = 0;
    for (std::size_t i = 0; i < sets.camera[0].size(); ++i) {
        const std::vector<Vec2> region0 = regionOf(0, i);
        crowded += region0.size() == kListCapacity;
        for (std::size_t j = 0; j < sets.camera[1].size(); ++j) {
            const double g = matcher.proximity(static_cast<int>(i), static_cast<int>(j));
            if (g == 0.0)
                continue; // outside the band or the disparity range
            const std::vector<Vec2> region1 = regionOf(1, j);
            const auto& smaller = region0.size() <= region1.size() ? region0 : region1;
            const auto& larger = region0.size() <= region1.size() ? region1 : region0;
            double sum = 0.0;
            for (const Vec2& q : smaller) {
                double closest = std::numeric_limits<double>::infinity();
                for (const Vec2& r : larger)
                    closest = std::min(closest, (q - r).norm());
                sum += closest;
            }
            const double d = smaller.empty() ? 0.0 : sum / static_cast<double>(smaller.size());
            const double dy = rectified[0][i]->y() - rectified[1][j]->y();
            const double expected =
                std::exp(-dy * dy / (2.0 * config.sigmaEpipolar_px * config.sigmaEpipolar_px) -
                         d * d / (2.0 * config.sigmaSimilarity_px * config.sigmaSimilarity_px));
            // The matcher keeps neighbour offsets in float.
            EXPECT_NEAR(g, expected, 1e-5 * expected + 1e-12) << i << " " << j;
            ++compared;
        }
    }
    EXPECT_GT(compared, 100u);
    EXPECT_GT(crowded, 10u);
}

TEST(StereoMatcher, BlocksGiveTheSameAnswerAsTheWholeMatrix) {
    for (unsigned seed = 1; seed <= 20; ++seed) {
        // Up to 48 markers: the whole matrix then fits one SVD of the solver's own fixed size.
        const std::vector<Vec3> points = randomMarkers(8 + static_cast<int>(seed) * 2, seed);
        const BlobSets sets = project(points, 0.3, seed);
        StereoMatcher matcher(simRig(), StereoConfig{}, 256);
        matcher.prepare(sets.camera[0], sets.camera[1]);
        BoundedVector<IndexPair> pairs(256);
        matcher.correspond(pairs);

        // The whole proximity matrix, decomposed by one SVD.
        const auto rows = static_cast<Eigen::Index>(sets.camera[0].size());
        const auto cols = static_cast<Eigen::Index>(sets.camera[1].size());
        ASSERT_LE(std::max(rows, cols), kMaxCorrespondenceBlock);
        ProximityBlock g(rows, cols);
        for (Eigen::Index i = 0; i < rows; ++i)
            for (Eigen::Index j = 0; j < cols; ++j)
                g(i, j) = matcher.proximity(static_cast<int>(i), static_cast<int>(j));
        std::set<std::pair<int, int>> whole;
        SlhSolver().solve(g, StereoConfig{}.minProximity, [&](int r, int c) {
            whole.insert({r, c});
        });
        std::set<std::pair<int, int>> blocked;
        for (const IndexPair& pair : pairs)
            blocked.insert({pair.left, pair.right});
        EXPECT_EQ(blocked, whole) << "seed " << seed;
        EXPECT_GT(matcher.counters().blocks, 1u);
    }
}

TEST(StereoMatcher, FindsEveryMarkerExactly) {
    const std::vector<Vec3> points = randomMarkers(60, 7);
    const BlobSets sets = project(points);
    StereoMatcher matcher(simRig(), StereoConfig{}, 256);
    ASSERT_TRUE(matcher.isValid());
    BoundedVector<StereoMarker> markers(256);
    matcher.match(sets.camera[0], sets.camera[1], markers);
    ASSERT_EQ(markers.size(), points.size());
    for (const StereoMarker& m : markers) {
        double nearest = 1e9;
        for (const Vec3& p : points)
            nearest = std::min(nearest, (p - m.position_rig_mm).norm());
        EXPECT_LT(nearest, 1e-6);
        EXPECT_LT(m.rayGap_mm, 1e-6f);
    }
}

TEST(StereoMatcher, SharedEpipolarLinesFoolTheBaselineNotTheSvd) {
    // Six pairs of markers; the two of a pair share an epipolar line (0.2 mm apart in height) at
    // different depths, so each blob of camera 0 has two candidates in camera 1, as in the
    // paper's Figure 6. Only the neighbourhood term can tell them apart.
    std::mt19937 random(11);
    std::uniform_real_distribution<double> wobble(-0.2, 0.2);
    std::vector<Vec3> points;
    for (int pair = 0; pair < 6; ++pair) {
        const double row = -75.0 + 30.0 * pair;
        const double x = 20.0 + 15.0 * (pair % 3);
        points.emplace_back(x, row, 540.0 + 10.0 * pair);
        points.emplace_back(x + 45.0 + 5.0 * pair, row + wobble(random), 600.0 - 6.0 * pair);
    }
    const BlobSets sets = project(points);
    StereoMatcher matcher(simRig(), StereoConfig{}, 64);
    BoundedVector<StereoMarker> svd(64), baseline(64);
    matcher.match(sets.camera[0], sets.camera[1], svd);
    matcher.matchEpipolarOnly(sets.camera[0], sets.camera[1], baseline);
    auto falseMarkers = [&](const BoundedVector<StereoMarker>& markers) {
        int count = 0;
        for (const StereoMarker& m : markers) {
            double nearest = 1e9;
            for (const Vec3& p : points)
                nearest = std::min(nearest, (p - m.position_rig_mm).norm());
            count += nearest > 0.01 ? 1 : 0;
        }
        return count;
    };
    EXPECT_EQ(svd.size(), points.size());
    EXPECT_EQ(falseMarkers(svd), 0);
    EXPECT_GE(falseMarkers(baseline), 6);
}

// The blob of a 10 mm sphere at \a point_rig_mm as camera \a camera sees it: its centre, and
// the area of its disc.
Blob sphereBlob(int camera, const Vec3& point_rig_mm) {
    const CameraModel& model = simRig().camera(camera);
    const Vec3 centre = model.centre_rig_mm();
    const Vec3 across = (point_rig_mm - centre).cross(Vec3::UnitY()).normalized();
    const Vec2 pixel = *model.project(point_rig_mm);
    const double radius_px = (*model.project(point_rig_mm + 5.0 * across) - pixel).norm();
    Blob blob;
    blob.centre_px = pixel;
    blob.area_px = static_cast<float>(std::numbers::pi * radius_px * radius_px);
    return blob;
}

TEST(StereoMatcher, OfTwoBlobsOnAMarkersEpipolarLineTakesTheOneOfTheSameSphere) {
    // Marker A is seen by both cameras; marker B, farther on the same epipolar plane, by camera 1
    // only (hidden from camera 0). A's blob in camera 0 has two partners on its line, equal for
    // eq. 1 and with no neighbours to tell them apart; only the sizes do: B's blob is of a
    // sphere at another range than the point the pair (A, B) would make.
    const Vec3 c0 = simRig().camera(0).centre_rig_mm();
    const Vec3 c1 = simRig().camera(1).centre_rig_mm();
    const Vec3 a(40.0, 10.0, 480.0);
    const Vec3 b = a + 30.0 * (c1 - c0).normalized() + 120.0 * (a - c0).normalized();
    const std::vector<Blob> camera0{sphereBlob(0, a)};
    for (const bool bFirst : {false, true}) {
        const std::vector<Blob> camera1 =
            bFirst ? std::vector<Blob>{sphereBlob(1, b), sphereBlob(1, a)}
                   : std::vector<Blob>{sphereBlob(1, a), sphereBlob(1, b)};
        StereoMatcher matcher(simRig(), StereoConfig{}, 8);
        BoundedVector<StereoMarker> markers(8);
        matcher.match(camera0, camera1, markers);
        ASSERT_EQ(markers.size(), 1U) << bFirst;
        EXPECT_LT((markers[0].position_rig_mm - a).norm(), 1e-6) << bFirst;
        // A weight, not a refusal: the ghost pair keeps a proximity above the minimum.
        EXPECT_GT(matcher.proximity(0, bFirst ? 0 : 1), StereoConfig{}.minProximity);
        EXPECT_LT(matcher.proximity(0, bFirst ? 0 : 1), 0.5 * matcher.proximity(0, bFirst ? 1 : 0));
    }
}

TEST(StereoMatcher, ASphereTellsOneRadiusToBothCamerasOfAnyRig) {
    // The exact image of a sphere (its tangent cone's conic, through the lens) anywhere in the
    // common view of rigs nobody picked: converging, rolled, distorted. Blob radius times range
    // alone differs between the cameras by up to tens of percent there; over pixelsPerRadian()
    // it tells the same radius, so the size weight of a true pair is 1.
    StereoConfig config;
    config.sizeSigma = 0.01;
    config.sizeRimSigma_px = 0.0;
    std::size_t checked = 0, rawOff = 0;
    for (std::uint64_t seed = 1; seed <= 50; ++seed) {
        sim::Scene scene;
        scene.rig = sim::randomRig(seed);
        sim::MarkerObject ball;
        ball.markerDiameter_mm = 4.0 + 0.3 * static_cast<double>(seed % 50);
        ball.markers.push_back({});
        scene.objects.push_back({ball, sim::Motion{}});
        const sim::World world(scene, seed);
        StereoMatcher matcher(world.rig(), config, 2);
        sim::Random random(seed);
        for (int k = 0; k < 20; ++k) {
            // A point in front of the rig, anywhere both cameras may see it. Drawn one statement
            // at a time: the order in which a constructor's arguments are evaluated differs
            // between compilers' targets (x86-64 and aarch64 drew different points).
            const double x = random.uniform(-250.0, 250.0);
            const double y = random.uniform(-200.0, 200.0);
            const double z = random.uniform(-150.0, 200.0);
            const Vec3 offset(x, y, z);
            sim::Observation observation;
            const sim::World placed(
                [&] {
                    sim::Scene moved = scene;
                    // A default motion holds the object at kSceneCentre_mm, unturned, at 0 s.
                    moved.objects[0].object.markers[0].position_object_mm = offset;
                    return moved;
                }(),
                seed);
            placed.observe(0, observation);
            const sim::MarkerView& view = observation.markers[0];
            if (!view.visible[0] || !view.visible[1])
                continue;
            std::vector<Blob> blobs[2];
            for (int c = 0; c < 2; ++c) {
                Blob blob;
                blob.centre_px = view.spotCentre_px[static_cast<std::size_t>(c)];
                blob.area_px = static_cast<float>(
                    std::numbers::pi *
                    std::abs(view.shape_px[static_cast<std::size_t>(c)].determinant()));
                blobs[c].push_back(blob);
            }
            matcher.prepare(blobs[0], blobs[1]);
            const double weight = matcher.proximity(0, 0);
            // proximity is the size weight times eq. 1's term of an exact pair (under 1e-3 px off),
            // so it tells the log ratio of the two radii. The small-sphere model holds to 0.2%
            // at worst over these places (rig 18, a 9.4 mm ball), where radius times range is off
            // by tens of percent.
            const double sizeLogRatio = config.sizeSigma * std::sqrt(-2.0 * std::log(weight));
            EXPECT_LT(sizeLogRatio, 0.005) << "rig " << seed << " at " << offset.transpose();
            const double range0 =
                (view.position_rig_mm - world.rig().camera(0).centre_rig_mm()).norm();
            const double range1 =
                (view.position_rig_mm - world.rig().camera(1).centre_rig_mm()).norm();
            rawOff +=
                std::abs(std::log(view.radius_px[0] * range0 / (view.radius_px[1] * range1))) >
                0.05;
            ++checked;
        }
    }
    EXPECT_GT(checked, 400U);
    // The rule this replaces, radius times range alike in both images, fails for many of them.
    EXPECT_GT(rawOff, checked / 20);
}

TEST(StereoMatcher, BlobSeenByOneCameraOnlyMakesNoMarker) {
    std::vector<Vec3> points = randomMarkers(10, 3);
    BlobSets sets = project(points);
    Blob lonely;
    lonely.centre_px = {50.0, 60.0};
    sets.camera[0].push_back(lonely);
    StereoMatcher matcher(simRig(), StereoConfig{}, 64);
    BoundedVector<StereoMarker> markers(64);
    matcher.match(sets.camera[0], sets.camera[1], markers);
    EXPECT_EQ(markers.size(), 10u);
}

TEST(StereoMatcher, MarkerOverflowIsCounted) {
    const BlobSets sets = project(randomMarkers(30, 4));
    StereoConfig config;
    config.maxMarkers = 10;
    StereoMatcher matcher(simRig(), config, 64);
    BoundedVector<StereoMarker> markers(config.maxMarkers);
    matcher.match(sets.camera[0], sets.camera[1], markers);
    EXPECT_EQ(markers.size(), 10u);
    EXPECT_EQ(matcher.counters().markerOverflow, 20u);
}

TEST(StereoMatcher, MatchingDoesNotAllocate) {
    const BlobSets sets = project(randomMarkers(60, 5), 0.2);
    StereoMatcher matcher(simRig(), StereoConfig{}, 256);
    BoundedVector<StereoMarker> markers(256);
    matcher.match(sets.camera[0], sets.camera[1], markers); // warm-up
    const auto count = test::countAllocations([&] {
        for (int i = 0; i < 100; ++i)
            matcher.match(sets.camera[0], sets.camera[1], markers);
    });
    EXPECT_EQ(count, 0u);
    EXPECT_GE(markers.size(), 58u); // real work was done (noise may cost a marker or two)
}

TEST(MarkerTrackingPipeline, ThousandFramesWithoutAllocating) {
    // Blob detection, stereo and frame-to-frame over 1,000 frames of a rendered scene.
    const sim::World world(*sim::makeScene("two_cubes", 3), 3);
    const sim::RigSpec& rig = world.scene().rig;
    const sim::FrameRenderer renderer(rig.width_px, rig.height_px, 10.0, 2.0, 3);
    constexpr int kRendered = 8;
    std::vector<std::vector<std::uint8_t>> images(2 * kRendered);
    sim::Observation observation;
    for (int f = 0; f < kRendered; ++f) {
        world.observe(static_cast<std::uint64_t>(f), observation);
        for (int c = 0; c < 2; ++c) {
            auto& image = images[static_cast<std::size_t>(2 * f + c)];
            image.resize(static_cast<std::size_t>(rig.width_px * rig.height_px));
            renderer.render(image, rig.width_px, c, observation, 1.0,
                            static_cast<std::uint64_t>(f));
        }
    }
    const BlobDetectorConfig blobConfig;
    BlobDetector detector(blobConfig, rig.width_px, rig.height_px);
    StereoMatcher stereo(world.rig(), StereoConfig{}, blobConfig.maxBlobs);
    MarkerTracker tracker{FrameToFrameConfig{}};
    BoundedVector<Blob> blobs0(blobConfig.maxBlobs), blobs1(blobConfig.maxBlobs);
    BoundedVector<StereoMarker> markers(256);
    BoundedVector<Vec3> points(256);
    auto frame = [&](int f) {
        const auto k = static_cast<std::size_t>(f % kRendered);
        detector.detect(images[2 * k].data(), rig.width_px, blobs0);
        detector.detect(images[2 * k + 1].data(), rig.width_px, blobs1);
        stereo.match(blobs0.span(), blobs1.span(), markers);
        points.clear();
        for (const StereoMarker& m : markers)
            points.push_back(m.position_rig_mm);
        tracker.update(f * 0.01, points.span());
    };
    for (int f = 0; f < 20; ++f)
        frame(f); // warm-up
    const auto allocations = test::countAllocations([&] {
        for (int f = 20; f < 1020; ++f)
            frame(f);
    });
    EXPECT_EQ(allocations, 0u);
    EXPECT_GT(markers.size(), 10u);
}

TEST(BlockSolver, OversizedBlockFallsBackToMutualBest) {
    // 60 x 60 is past the SVD's fixed size: pairs still come out, and the fallback is reported.
    std::vector<int> left(60), right(60);
    std::iota(left.begin(), left.end(), 0);
    std::iota(right.begin(), right.end(), 0);
    auto proximity = [](int i, int j) { return i == (j + 7) % 60 ? 0.9 : 0.01 / (1 + i + j); };
    BlockSolver solver;
    std::vector<std::pair<int, int>> pairs;
    const bool solved =
        solver.solve(left, right, 1e-3, proximity, [&](int i, int j) { pairs.emplace_back(i, j); });
    EXPECT_FALSE(solved);
    ASSERT_EQ(pairs.size(), 60u);
    for (const auto& [i, j] : pairs)
        EXPECT_EQ(i, (j + 7) % 60);

    // A small block of the same kind goes through the SVD and agrees.
    std::vector<int> few(6);
    std::iota(few.begin(), few.end(), 0);
    pairs.clear();
    auto small = [](int i, int j) { return i == (j + 2) % 6 ? 0.9 : 0.05; };
    EXPECT_TRUE(
        solver.solve(few, few, 1e-3, small, [&](int i, int j) { pairs.emplace_back(i, j); }));
    ASSERT_EQ(pairs.size(), 6u);
    for (const auto& [i, j] : pairs)
        EXPECT_EQ(i, (j + 2) % 6);
}

TEST(SlhSolver, ClosedFormTwoByTwoAgreesWithTheSvd) {
    std::mt19937 random(5);
    std::uniform_real_distribution<double> value(0.0, 1.0);
    SlhSolver solver;
    for (int trial = 0; trial < 2000; ++trial) {
        ProximityBlock g(2, 2);
        for (Eigen::Index i = 0; i < 4; ++i)
            g.data()[i] = value(random);
        std::set<std::pair<int, int>> closedForm;
        solver.solve(g, 0.0, [&](int r, int c) { closedForm.insert({r, c}); });
        EXPECT_EQ(closedForm, svdPairs(g)) << g;
    }
}

// Blocks whose shorter side is 3 or 4 take the polar factor by Newton's iteration instead of the
// SVD: the pairs must be the SVD's, for blocks of full rank and for nearly rank-deficient ones
// (which fall back to the SVD), square, tall and wide.
TEST(SlhSolver, NewtonPolarFactorAgreesWithTheSvd) {
    constexpr std::pair<Eigen::Index, Eigen::Index> kShapes[] = {{3, 3}, {4, 4}, {3, 4}, {4, 3},
                                                                 {3, 7}, {8, 4}, {2, 3}, {5, 5}};
    std::mt19937 random(11);
    std::uniform_real_distribution<double> value(0.0, 1.0);
    SlhSolver solver;
    int nearlyDeficient = 0;
    for (std::size_t trial = 0; trial < 8000; ++trial) {
        const auto [rows, cols] = kShapes[trial % std::size(kShapes)];
        ProximityBlock g(rows, cols);
        for (Eigen::Index i = 0; i < rows * cols; ++i)
            g.data()[i] = value(random);
        if (trial % 5 == 0) {
            // Two rows and two columns almost alike: blobs whose neighbourhoods look the same.
            g.row(1) = g.row(0) * (1.0 + 1e-9 * value(random));
            g.col(1) = g.col(0) * (1.0 + 1e-9 * value(random));
            ++nearlyDeficient;
        }
        std::set<std::pair<int, int>> fast;
        solver.solve(g, 0.0, [&](int r, int c) { fast.insert({r, c}); });
        EXPECT_EQ(fast, svdPairs(g)) << g;
    }
    EXPECT_EQ(nearlyDeficient, 1600);
}
