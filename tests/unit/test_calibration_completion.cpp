// Tests of the completion stage: pieces of a body completed and joined, riders left out, order.
#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <optional>
#include <random>
#include <set>
#include <tuple>
#include <vector>

#include <gtest/gtest.h>

#include "core/calibration_completion.hpp"
#include "core/calibration_session.hpp"
#include "core/completion_geometry.hpp"
#include "core/object_calibrator.hpp"
#include "core/session_buffer.hpp"
#include "tests/support/layouts.hpp"
#include "tests/support/model_alignment.hpp"

namespace edgetrack {
namespace {

// Rig from body (mm): a body turning steadily about a tilted axis in front of the cameras, so
// that it is seen from the same directions again every turn.
RigidTransform turning(double t_s, const Vec3& centre_rig_mm, double phase,
                       const Vec3& axis = Vec3(0.3, 1.0, 0.2)) {
    RigidTransform pose;
    pose.rotation = Quat(Eigen::AngleAxisd(0.9 * t_s + phase, axis.normalized()));
    pose.translation_mm =
        centre_rig_mm + Vec3(25.0 * std::sin(0.6 * t_s + phase), 15.0 * std::cos(0.4 * t_s),
                             10.0 * std::sin(0.3 * t_s));
    return pose;
}

/// Fully connected models of \a layouts (mm), in order.
std::vector<MarkerModel> modelsOf(const std::vector<std::vector<Vec3>>& layouts) {
    std::vector<MarkerModel> models;
    for (const std::vector<Vec3>& layout : layouts)
        models.push_back(test::fullyConnectedModel(layout));
    return models;
}

std::vector<Vec3> subset(const std::vector<Vec3>& layout, std::size_t first, std::size_t count) {
    return {layout.begin() + static_cast<std::ptrdiff_t>(first),
            layout.begin() + static_cast<std::ptrdiff_t>(first + count)};
}

// Largest distance (mm) of a model's marker from the layout's, after the best rigid fit through
// nearest markers; infinity when the sizes differ.
double layoutError_mm(const MarkerModel& model, const std::vector<Vec3>& layout) {
    if (model.markers_model_mm.size() != layout.size())
        return INFINITY;
    // Pairwise distances, sorted, compared: a rigid motion and marker order do not change them.
    auto distances = [](std::span<const Vec3> p) {
        std::vector<double> d;
        for (std::size_t i = 0; i < p.size(); ++i)
            for (std::size_t j = i + 1; j < p.size(); ++j)
                d.push_back((p[i] - p[j]).norm());
        std::sort(d.begin(), d.end());
        return d;
    };
    const std::vector<double> a = distances(model.markers_model_mm.span());
    const std::vector<double> b = distances(layout);
    double worst = 0.0;
    for (std::size_t i = 0; i < a.size(); ++i)
        worst = std::max(worst, std::abs(a[i] - b[i]));
    return worst;
}

std::vector<MarkerModel> outputModels(const CompletionConfig& config) {
    std::vector<MarkerModel> out;
    for (std::size_t i = 0; i < config.maxModels; ++i)
        out.emplace_back(config.maxMarkersPerModel);
    return out;
}

// A piece of a layout, turned, moved and listed in another order, lands on the layout with
// every one of its markers, and in no other placement with as many.
TEST(LayoutRegistration, PlacesAPieceOnItsLayoutWhateverTheOrderOfMarkers) {
    const std::vector<Vec3> whole = test::irregularLayout(14, 21, 15.0);
    RigidTransform moved;
    moved.rotation = Quat(Eigen::AngleAxisd(0.7, Vec3(0.2, 0.5, 1.0).normalized()));
    moved.translation_mm = Vec3(30.0, -12.0, 250.0);
    const std::array<std::size_t, 5> taken{11, 3, 8, 0, 6};
    std::vector<Vec3> piece;
    for (const std::size_t m : taken)
        piece.push_back(moved.apply(whole[m]));
    const completion_detail::Registration r =
        completion_detail::registerLayout(piece, whole, 2.0, 0.5);
    EXPECT_EQ(r.matched, 5U);
    EXPECT_LT(r.runnerUp, 5U);
    for (std::size_t i = 0; i < piece.size(); ++i)
        EXPECT_LT((r.T_whole_from_part.apply(piece[i]) - whole[taken[i]]).norm(), 1e-6);
}

// A piece of a regular layout (a row of squares) fits it in several places: registration says
// so, and the join step then does not take it.
TEST(LayoutRegistration, SaysWhenASelfSimilarLayoutTakesAPieceInSeveralPlaces) {
    std::vector<Vec3> grid;
    for (int row = 0; row < 2; ++row)
        for (int column = 0; column < 4; ++column)
            grid.push_back(Vec3(30.0 * column, 30.0 * row, 0.0));
    const std::vector<Vec3> square{grid[0], grid[1], grid[4], grid[5]};
    const completion_detail::Registration r =
        completion_detail::registerLayout(square, grid, 2.0, 0.5);
    EXPECT_EQ(r.matched, 4U);
    EXPECT_EQ(r.runnerUp, 4U);
}

// Two pieces that share exactly three markers: the shared triangle places one on the other,
// whatever the order of either's markers. A triangle like it within a millimetre elsewhere in the
// whole leaves it the identity (layouts are known to hundredths of a millimetre); a second copy
// of it makes the likeness no identity, and so does a marker of the piece so far from the triangle
// that the triangle cannot place it within half a millimetre.
TEST(LayoutRegistration, PlacesAPieceByTheOneTriangleItSharesUnlessAnotherIsLikeIt) {
    const std::vector<Vec3> whole = test::irregularLayout(8, 31, 15.0);
    RigidTransform moved;
    moved.rotation = Quat(Eigen::AngleAxisd(1.1, Vec3(0.6, -0.2, 1.0).normalized()));
    moved.translation_mm = Vec3(-40.0, 8.0, 300.0);
    // The piece: three markers of the whole and three of its own, away from the whole's.
    const std::array<std::size_t, 3> shared{6, 1, 4};
    std::vector<Vec3> piece{moved.apply(Vec3(0.0, 0.0, 60.0)), moved.apply(Vec3(35.0, 0.0, 70.0))};
    for (const std::size_t m : shared)
        piece.push_back(moved.apply(whole[m]));
    piece.push_back(moved.apply(Vec3(10.0, 40.0, 80.0)));
    const std::optional<RigidTransform> placed =
        completion_detail::soleSharedTriangle(piece, whole, completion_detail::kTriangleTie);
    ASSERT_TRUE(placed.has_value());
    for (std::size_t i = 0; i < shared.size(); ++i)
        EXPECT_LT((placed->apply(piece[2 + i]) - whole[shared[i]]).norm(), 1e-6);

    // The same three markers once more elsewhere in the whole, each 0.8 mm off: a near likeness
    // that a tolerance of a registration (0.5 mm, uniqueness at 2 mm) would count as a rival.
    RigidTransform elsewhere;
    elsewhere.rotation = Quat(Eigen::AngleAxisd(2.0, Vec3::UnitZ()));
    elsewhere.translation_mm = Vec3(0.0, 0.0, 400.0);
    const std::array<Vec3, 3> nudge{Vec3(0.8, 0.0, 0.0), Vec3(0.0, -0.8, 0.0), Vec3(0.0, 0.0, 0.8)};
    std::vector<Vec3> nearLikeness = whole;
    for (std::size_t i = 0; i < shared.size(); ++i)
        nearLikeness.push_back(elsewhere.apply(whole[shared[i]] + nudge[i]));
    ASSERT_TRUE(completion_detail::soleSharedTriangle(piece, nearLikeness,
                                                      completion_detail::kTriangleTie));
    EXPECT_FALSE(completion_detail::soleSharedTriangle(
        piece, nearLikeness,
        completion_detail::TriangleTieLimits{.tolerance_mm = 0.5,
                                             .uniqueness_mm = 2.0,
                                             .precision_mm = 0.05,
                                             .placement_mm = 0.5,
                                             .budget = 1000000}));

    // An exact copy: two places fit.
    std::vector<Vec3> twice = whole;
    for (const std::size_t m : shared)
        twice.push_back(elsewhere.apply(whole[m]));
    EXPECT_FALSE(
        completion_detail::soleSharedTriangle(piece, twice, completion_detail::kTriangleTie));

    // A marker of the piece 2 m from the triangle: a turn of 0.05 mm over the triangle's height
    // moves it by more than half a millimetre.
    std::vector<Vec3> reaching = piece;
    reaching.push_back(moved.apply(Vec3(0.0, 0.0, 2000.0)));
    EXPECT_FALSE(
        completion_detail::soleSharedTriangle(reaching, whole, completion_detail::kTriangleTie));
}

// The index the triangle steps look triangles up in must give what a scan of them all gives:
// every triangle whose longest side lies in the window, in order of that side (equal sides in
// the order given), and it may say "none near" only where a scan finds none within its bin width.
TEST(ViewCones, MarkersThatCanBeSeenTogetherThoughNoFrameShowedThem) {
    // A box's faces, each seen from within 50 degrees of its normal: adjacent faces (90 degrees
    // apart) can be seen together, opposite ones (180) cannot; a sphere on a post, seen from all
    // round, can be seen with anything. Cones are widened by 15 degrees.
    const double margin = 15.0 * std::numbers::pi / 180.0;
    const auto face = [](const Vec3& normal) {
        std::vector<Vec3> seen;
        const Vec3 across = normal.unitOrthogonal();
        for (int k = 0; k < 12; ++k) {
            const double turn = 2.0 * std::numbers::pi * k / 12.0;
            const Vec3 side = std::cos(turn) * across + std::sin(turn) * normal.cross(across);
            const double tilt = 50.0 * std::numbers::pi / 180.0;
            seen.push_back(std::cos(tilt) * normal + std::sin(tilt) * side);
        }
        return seen;
    };
    using completion_detail::coVisible;
    using completion_detail::viewCone;
    using completion_detail::ViewCone;
    const ViewCone top = viewCone(face(Vec3::UnitZ()), margin);
    const ViewCone side = viewCone(face(Vec3::UnitX()), margin);
    const ViewCone bottom = viewCone(face(-Vec3::UnitZ()), margin);
    EXPECT_NEAR(top.halfAngle_rad, (50.0 + 15.0) * std::numbers::pi / 180.0, 1e-9);
    EXPECT_TRUE(coVisible(top, side));
    EXPECT_FALSE(coVisible(top, bottom));
    // Seen up to 80 degrees off their normals (widened past 90), markers on opposite faces still
    // cannot be seen together: a surface hides its markers from behind.
    const auto grazing = [&](const Vec3& normal) {
        std::vector<Vec3> seen{normal};
        const Vec3 across = normal.unitOrthogonal();
        const double tilt = 80.0 * std::numbers::pi / 180.0;
        for (int k = 0; k < 8; ++k) {
            const double turn = 2.0 * std::numbers::pi * k / 8.0;
            seen.push_back(std::cos(tilt) * normal +
                           std::sin(tilt) *
                               (std::cos(turn) * across + std::sin(turn) * normal.cross(across)));
        }
        return seen;
    };
    EXPECT_FALSE(coVisible(viewCone(grazing(Vec3::UnitZ()), margin),
                           viewCone(grazing(-Vec3::UnitZ()), margin)));
    EXPECT_TRUE(coVisible(viewCone(grazing(Vec3::UnitZ()), margin),
                          viewCone(grazing(Vec3::UnitX()), margin)));
    const std::vector<Vec3> allRound{Vec3::UnitX(), -Vec3::UnitX(), Vec3::UnitY(), -Vec3::UnitY()};
    const ViewCone post = viewCone(allRound, margin);
    EXPECT_TRUE(coVisible(post, bottom));
    EXPECT_TRUE(coVisible(post, top));
    EXPECT_FALSE(coVisible(viewCone({}, margin), top)) << "never seen: seen with nothing";
}

TEST(TrianglesByLongestSide, FindsWhatAScanOfEveryTriangleFinds) {
    using completion_detail::SortedTriangle;
    std::mt19937 random(7);
    std::uniform_real_distribution<double> coordinate(-40.0, 40.0);
    std::vector<Vec3> layout;
    for (int m = 0; m < 14; ++m)
        layout.emplace_back(coordinate(random), coordinate(random), coordinate(random));
    std::vector<SortedTriangle> triangles;
    completion_detail::appendTriangles(layout, 0, triangles);
    // Equal longest sides too, to show their order is kept.
    for (std::size_t t = 0; t < 20; ++t) {
        SortedTriangle copy = triangles[t];
        copy.body = 1;
        triangles.push_back(copy);
    }
    const double width = 0.75;
    const completion_detail::TrianglesByLongestSide index(triangles, width);
    std::vector<SortedTriangle> sorted = triangles;
    std::stable_sort(sorted.begin(), sorted.end(), completion_detail::shorterLongestSide);
    ASSERT_EQ(index.all().size(), sorted.size());
    auto same = [](const SortedTriangle& a, const SortedTriangle& b) {
        return a.sides_mm == b.sides_mm && a.corners == b.corners && a.body == b.body;
    };
    EXPECT_TRUE(std::equal(sorted.begin(), sorted.end(), index.all().begin(), same));

    std::uniform_real_distribution<double> side(-5.0, 150.0);
    std::size_t nearSome = 0, nearNone = 0;
    for (int trial = 0; trial < 3000; ++trial) {
        const double a = side(random), b = a + std::abs(side(random)) * 0.05;
        std::vector<SortedTriangle> scanned;
        for (const SortedTriangle& t : sorted)
            if (t.sides_mm[2] >= a && t.sides_mm[2] <= b)
                scanned.push_back(t);
        const auto found = index.within(a, b);
        ASSERT_EQ(found.size(), scanned.size()) << a << " " << b;
        EXPECT_TRUE(std::equal(scanned.begin(), scanned.end(), found.begin(), same));

        // A triangle of random sides: "none near" only when a scan finds none within the width.
        std::array<double, 3> sides = {std::abs(side(random)), std::abs(side(random)),
                                       std::abs(side(random))};
        std::sort(sides.begin(), sides.end());
        const bool anyNear =
            std::any_of(sorted.begin(), sorted.end(), [&](const SortedTriangle& t) {
                return std::abs(t.sides_mm[2] - sides[2]) <= width &&
                       std::abs(t.sides_mm[1] - sides[1]) <= width;
            });
        const bool mayHold = index.mayHoldNear(index.binOf(sides[2]), index.binOf(sides[1]));
        if (anyNear) {
            EXPECT_TRUE(mayHold) << sides[0] << " " << sides[1] << " " << sides[2];
        }
        (mayHold ? nearSome : nearNone) += 1;
    }
    // And it does tell most of them apart, or it would save nothing.
    EXPECT_GT(nearNone, nearSome);
    EXPECT_TRUE(index.within(200.0, 100.0).empty());
    EXPECT_TRUE(completion_detail::TrianglesByLongestSide({}, width).within(0.0, 1e9).empty());
}

// The triangle step poses a body only by triangles no other of its own is like, and knows which
// other bodies have one like it; markAlike must find every such likeness that a comparison of
// every pair finds, and no other.
TEST(TrianglesByLongestSide, MarkAlikeMarksWhatEveryPairComparedMarks) {
    using completion_detail::SortedTriangle;
    std::mt19937 random(11);
    std::uniform_real_distribution<double> coordinate(-30.0, 30.0);
    std::vector<SortedTriangle> triangles;
    for (std::size_t body = 0; body < 3; ++body) {
        std::vector<Vec3> layout;
        for (int m = 0; m < 12; ++m)
            layout.emplace_back(coordinate(random), coordinate(random), coordinate(random));
        completion_detail::appendTriangles(layout, body, triangles);
    }
    std::size_t alikeOthers = 0;
    for (const double tolerance : {0.3, 3.0}) {
        std::vector<SortedTriangle> marked = triangles;
        completion_detail::markAlike(marked, tolerance);
        std::size_t alike = 0;
        for (std::size_t i = 0; i < triangles.size(); ++i) {
            bool expected = true;
            std::set<std::uint32_t> others;
            for (std::size_t j = 0; j < triangles.size(); ++j) {
                if (j == i || !completion_detail::congruent(triangles[i], triangles[j], tolerance))
                    continue;
                if (triangles[j].body == triangles[i].body)
                    expected = false;
                else
                    others.insert(static_cast<std::uint32_t>(triangles[j].body));
            }
            ASSERT_EQ(marked[i].unique, expected) << i << " at " << tolerance << " mm";
            alike += expected ? 0U : 1U;
            if (!expected)
                continue;
            const std::set<std::uint32_t> listed(marked[i].alikeBodies.begin(),
                                                 marked[i].alikeBodies.begin() +
                                                     marked[i].alikeCount);
            ASSERT_EQ(listed, others) << i << " at " << tolerance << " mm";
            ASSERT_EQ(marked[i].alikeCount, others.size());
            alikeOthers += others.empty() ? 0U : 1U;
        }
        // Both kinds occur, or the comparison shows nothing.
        EXPECT_GT(alike, 0U);
        EXPECT_LT(alike, triangles.size());
    }
    // And at the wider tolerance, triangles like another body's only.
    EXPECT_GT(alikeOthers, 0U);
}

// Two objects found at once, each moving its own way 150 mm apart, show themselves as two in
// every frame, whatever a likeness of layout would tie them by; two pieces of one body found at
// once, apart or on each other's points, never do.
TEST(FramesSeenApart, CountsFramesThatShowTwoObjectsNotTwoPiecesOfOne) {
    const completion_detail::Extent ballA{Vec3(0.0, 0.0, 0.0), 30.0};
    const completion_detail::Extent ballB{Vec3(5.0, 0.0, 0.0), 25.0};
    RigidTransform tie;
    tie.rotation = Quat(Eigen::AngleAxisd(0.7, Vec3(0.2, 1.0, 0.1).normalized()));
    tie.translation_mm = Vec3(80.0, -10.0, 5.0);
    std::vector<RigidTransform> poseA, poseB, pieceB, selfSimilarB;
    std::vector<std::size_t> frames;
    for (std::size_t f = 0; f < 200; ++f) {
        const double t_s = static_cast<double>(f) / 100.0;
        poseA.push_back(turning(t_s, Vec3(-75.0, 0.0, 600.0), 0.0));
        poseB.push_back(turning(t_s, Vec3(75.0, 0.0, 600.0), 1.3, Vec3::UnitX()));
        pieceB.push_back(poseA.back() * tie);
        // Taken for another part of the body: turned about the body's centre, on its points.
        RigidTransform turned;
        turned.rotation = Quat(Eigen::AngleAxisd(1.2, Vec3::UnitZ()));
        selfSimilarB.push_back(poseA.back() * turned);
        frames.push_back(f);
    }
    EXPECT_EQ(completion_detail::framesSeenApart(poseA, poseB, frames, ballA, ballB, tie, 2.0),
              frames.size());
    EXPECT_EQ(completion_detail::framesSeenApart(poseA, pieceB, frames, ballA, ballB, tie, 2.0),
              0U);
    EXPECT_EQ(
        completion_detail::framesSeenApart(poseA, selfSimilarB, frames, ballA, ballB, tie, 2.0),
        0U);
    // Only the frames asked about count.
    EXPECT_EQ(completion_detail::framesSeenApart(poseA, poseB, std::span(frames).first(7), ballA,
                                                 ballB, tie, 2.0),
              7U);
}

// Views that share three markers off one line fix each other; two shared markers, or three on
// one line, leave one view free to turn about that line.
TEST(RigidGroups, TiesViewsThatShareThreeMarkersOffOneLine) {
    using completion_detail::MarkerBits;
    using completion_detail::rigidGroupsOf;
    const auto bits = [](std::initializer_list<std::size_t> markers) {
        MarkerBits b{};
        for (const std::size_t k : markers)
            completion_detail::add(b, k);
        return b;
    };
    // Markers 0-2 on the x axis, 3-5 off it.
    const std::vector<Vec3> layout{Vec3(0, 0, 0),   Vec3(20, 0, 0),  Vec3(40, 0, 0),
                                   Vec3(10, 25, 0), Vec3(30, 20, 5), Vec3(15, 5, 30)};
    EXPECT_EQ(rigidGroupsOf({bits({0, 1, 3, 4}), bits({0, 1, 5})}, layout, 3.0).size(), 2U);
    EXPECT_EQ(rigidGroupsOf({bits({0, 1, 2, 3}), bits({0, 1, 2, 4})}, layout, 3.0).size(), 2U)
        << "three shared markers on one line";
    const std::vector<MarkerBits> tied =
        rigidGroupsOf({bits({0, 1, 3, 4}), bits({0, 3, 5}), bits({1, 3, 4, 5})}, layout, 3.0);
    ASSERT_EQ(tied.size(), 1U);
    EXPECT_EQ(tied[0], bits({0, 1, 3, 4, 5}));
    EXPECT_TRUE(rigidGroupsOf({bits({0, 1, 2})}, layout, 3.0).empty()) << "one line fixes nothing";
}

TEST(SessionBuffer, KeepsEachFrameInOneOrderAndRefusesWhatDoesNotFit) {
    SessionBuffer session(2, 5);
    const std::vector<Vec3> frame{Vec3(3, 0, 0), Vec3(1, 2, 0), Vec3(1, 1, 5)};
    ASSERT_TRUE(session.append(0.0, frame));
    ASSERT_EQ(session.points(0).size(), 3U);
    EXPECT_EQ(session.points(0)[0], Vec3(1, 1, 5));
    EXPECT_EQ(session.points(0)[1], Vec3(1, 2, 0));
    EXPECT_EQ(session.points(0)[2], Vec3(3, 0, 0));
    EXPECT_FALSE(session.append(0.01, frame)) << "6 points do not fit in 5";
    EXPECT_TRUE(session.append(0.01, std::span(frame).first(2)));
    EXPECT_FALSE(session.append(0.02, {})) << "a third frame does not fit in 2";
    EXPECT_EQ(session.frames(), 2U);
    EXPECT_EQ(session.framesRefused(), 2U);
    session.clear();
    EXPECT_EQ(session.frames(), 0U);
    EXPECT_EQ(session.framesRefused(), 0U);
}

// A session of bodies turning in view: every marker of every body seen in every frame, with noise.
SessionBuffer sessionOf(const std::vector<std::vector<Vec3>>& bodies, double seconds,
                        double noise_mm, unsigned seed) {
    const auto frames = static_cast<std::size_t>(seconds * 100.0);
    SessionBuffer session(frames, frames * 64);
    std::mt19937 random(seed);
    std::normal_distribution<double> noise(0.0, noise_mm);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        points.clear();
        for (std::size_t b = 0; b < bodies.size(); ++b) {
            const RigidTransform pose =
                turning(t, Vec3(-90.0 + 180.0 * static_cast<double>(b), 0.0, 600.0),
                        1.3 * static_cast<double>(b));
            for (const Vec3& m : bodies[b])
                points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        }
        session.append(t, points);
    }
    return session;
}

TEST(CalibrationCompletion, CompletesAModelFromAPieceOfIt) {
    const std::vector<Vec3> body = test::irregularLayout(12, 7, 15.0);
    const SessionBuffer session = sessionOf({body}, 10.0, 0.05, 1);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    ASSERT_TRUE(completion.isValid());
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 5)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
    EXPECT_EQ(completion.counters().markersAdded, 7U);
}

// The markers first learnt of a long bar may all lie at one end of it: its other two, 95 and 110
// mm from them (too few to be found as a body of their own and joined), are learnt too, as an
// object's unknown markers are looked for well beyond its known ones.
TEST(CalibrationCompletion, LearnsTheFarEndOfALongBarFromAPieceAtOneEnd) {
    const std::vector<Vec3> body{
        Vec3(0.0, 0.0, 0.0),  Vec3(15.0, 3.0, 2.0),  Vec3(4.0, 16.0, -3.0), Vec3(12.0, 10.0, 12.0),
        Vec3(-8.0, 6.0, 9.0), Vec3(100.0, 5.0, 0.0), Vec3(112.0, -6.0, 8.0)};
    const SessionBuffer session = sessionOf({body}, 10.0, 0.05, 3);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({subset(body, 0, 5)}), out), 1U);
    EXPECT_EQ(completion.counters().markersAdded, 2U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
}

TEST(CalibrationCompletion, JoinsTwoPiecesOfOneBody) {
    const std::vector<Vec3> body = test::irregularLayout(12, 8, 15.0);
    const SessionBuffer session = sessionOf({body}, 10.0, 0.05, 2);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 6), subset(body, 6, 6)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U) << "the two pieces move as one body";
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
}

// A session of bodies turning in view, each marker seen only while \a inView(marker, t) says so.
template <typename InView>
SessionBuffer sessionWhere(const std::vector<std::vector<Vec3>>& bodies, double seconds,
                           double noise_mm, unsigned seed, InView inView) {
    const auto frames = static_cast<std::size_t>(seconds * 100.0);
    SessionBuffer session(frames, frames * 64);
    std::mt19937 random(seed);
    std::normal_distribution<double> noise(0.0, noise_mm);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        points.clear();
        for (std::size_t b = 0; b < bodies.size(); ++b) {
            const RigidTransform pose =
                turning(t, Vec3(-60.0 + 120.0 * static_cast<double>(b), 0.0, 600.0),
                        1.3 * static_cast<double>(b), b == 0 ? Vec3(0.3, 1.0, 0.2) : Vec3::UnitX());
            for (std::size_t m = 0; m < bodies[b].size(); ++m)
                if (inView(b, m, t))
                    points.push_back(pose.apply(bodies[b][m]) +
                                     Vec3(noise(random), noise(random), noise(random)));
        }
        session.append(t, points);
    }
    return session;
}

// The precision completion reports is what the learnt layout shows against the truth: the point
// noise as simulated, and the markers as far from their true places as predicted (within the
// scatter of an RMS over twelve markers), for a quiet and a noisy session.
TEST(CalibrationCompletion, SaysHowCloselyItsFramesFixTheLayout) {
    const std::vector<Vec3> body = test::irregularLayout(12, 7, 15.0);
    for (const double noise_mm : {0.1, 0.3}) {
        // Seven markers in view, a different seven every second.
        const SessionBuffer session =
            sessionWhere({body}, 10.0, noise_mm, 21, [](std::size_t, std::size_t m, double t) {
                return (m + static_cast<std::size_t>(t)) % 12 < 7;
            });
        const CompletionConfig config;
        CalibrationCompletion completion(config);
        std::vector<MarkerModel> out = outputModels(config);
        ASSERT_EQ(completion.run(session, modelsOf({subset(body, 0, 5)}), out), 1U);
        ASSERT_EQ(completion.precision().size(), 1U);
        const LayoutPrecision& precision = completion.precision()[0];
        EXPECT_NEAR(precision.pointSigma_mm / noise_mm, 1.0, 0.1);
        EXPECT_EQ(precision.looseModes, 0U);
        const test::ModelAlignment aligned = test::alignModel(out[0], body, 1.0);
        ASSERT_EQ(aligned.matched, 12U);
        EXPECT_GT(aligned.rms_mm, 0.6 * precision.markerRms_mm) << "noise " << noise_mm;
        EXPECT_LT(aligned.rms_mm, 1.6 * precision.markerRms_mm) << "noise " << noise_mm;
        EXPECT_GE(precision.worstMarker_mm, precision.markerRms_mm);
    }
}

// Two pieces of one body in view at once for only 0.15 s, as when one side of an object turns
// away just as the other turns into view: a pose from three or four markers of each piece turns
// by a degree or so, so relative poses frame by frame scatter by millimetres, but the two layouts
// fitted as one fit every one of those frames.
TEST(CalibrationCompletion, JoinsTwoPiecesOfOneBodySeenTogetherOnlyBriefly) {
    const std::vector<Vec3> body = test::irregularLayout(8, 15, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.1, 6, [](std::size_t, std::size_t m, double t) {
            return m < 4 ? t < 5.0 : t >= 4.85;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 4), subset(body, 4, 4)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByMotion, 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// A body whose markers come into view two at a time as two others leave, every quarter second,
// as a turning object shows one side after another: no frame holds three markers of the model and
// three new ones, so the tracker loses the model as soon as its side turns away, and no four
// markers are in view together long enough to be found as a body of their own. Followed frame to
// frame (the turn about the two markers still in view carried on for a few frames), every side is
// learnt.
TEST(CalibrationCompletion, FollowsABodyWhoseMarkersComeAndGoTwoAtATime) {
    const std::vector<Vec3> body = test::irregularLayout(10, 18, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 8, [](std::size_t, std::size_t m, double t) {
            const auto first = 2 * static_cast<std::size_t>(t / 0.25);
            return (m + 10 - first % 10) % 10 < 4;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({subset(body, 0, 4)}), out), 1U);
    EXPECT_GT(completion.counters().framesFollowed, 0U);
    // The largest error of the 45 distances: the sides form a chain, which four alternations of
    // pose fits and marker means straightened only to 0.16 mm; the joint step of all poses and
    // markers gets it under 0.05 mm.
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
}

// Two pieces of one body that share four markers but are never in view together, and whose
// shared markers are never all in view at once: no frame poses both, so only their layouts tie
// them. The shared four are not the first markers of the second piece, so whichever markers a
// search tries first, it must find them; and four of nine is less than half the piece.
TEST(CalibrationCompletion, JoinsTwoPiecesNeverSeenTogetherThatShareFourMarkers) {
    const std::vector<Vec3> body = test::irregularLayout(14, 20, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 10, [](std::size_t, std::size_t m, double t) {
            return t < 4.0 ? m <= 8 : t >= 6.0 && m >= 5;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<Vec3> second = subset(body, 9, 5);
    second.insert(second.begin() + 2, body.begin() + 5, body.begin() + 9);
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 9), second});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByLayout, 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// Two pieces of one body, markers 0-6 and 5-8, that share markers 5 and 6: the first seen for
// four seconds, the second two seconds later, and between them a tenth of a second in which the
// first piece's markers 0-4 are seen with markers 7 to \a lastGlimpsed of the second.
SessionBuffer twoPiecesWithAGlimpse(const std::vector<Vec3>& body, std::size_t lastGlimpsed) {
    return sessionWhere({body}, 10.0, 0.05, 13, [=](std::size_t, std::size_t m, double t) {
        if (t < 4.0)
            return m <= 6;
        if (t < 4.1)
            return m <= 4 || (m >= 7 && m <= lastGlimpsed);
        return t >= 6.0 && m >= 5;
    });
}

// The glimpse shows both of the second piece's own markers. Too brief to make them the first
// piece's markers, those glimpses are where the second piece's layout lands on the first, four
// markers in one place: the pieces are one body.
TEST(CalibrationCompletion, JoinsAPieceWhoseMarkersTheOtherGlimpsedBriefly) {
    const std::vector<Vec3> body = test::irregularLayout(9, 27, 15.0);
    const SessionBuffer session = twoPiecesWithAGlimpse(body, 8);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 7), subset(body, 5, 4)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByLayout, 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// The glimpse shows only one of them: the triangle of the two shared markers and the glimpse,
// like no other of either piece, is the tie.
TEST(CalibrationCompletion, JoinsAPieceTiedByTwoSharedMarkersAndAGlimpse) {
    const std::vector<Vec3> body = test::irregularLayout(9, 28, 15.0);
    const SessionBuffer session = twoPiecesWithAGlimpse(body, 7);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    // The condition of the scene: the triangle of markers 5, 6 and 7 is like no other.
    ASSERT_TRUE(completion_detail::soleSharedTriangle(subset(body, 5, 4), subset(body, 0, 8),
                                                      completion_detail::kTriangleTie));
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 7), subset(body, 5, 4)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByLayout, 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), body.size());
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// Two pieces of one body, markers 0-6 and 6-10, that share only marker 6 (a car's roof and its
// side, meeting at a corner): between them a tenth of a second in which the first piece's markers
// 0-5 are seen with markers 7-9 of the second. The second piece lands on the first's marker and
// three of its glimpses, four markers in one place: one shared marker anchors a tie the glimpses
// make.
TEST(CalibrationCompletion, JoinsAPieceTiedByOneSharedMarkerAndThreeGlimpses) {
    const std::vector<Vec3> body = test::irregularLayout(11, 29, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 15, [](std::size_t, std::size_t m, double t) {
            if (t < 4.0)
                return m <= 6;
            if (t < 4.1)
                return m <= 5 || (m >= 7 && m <= 9);
            return t >= 6.0 && m >= 6;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 7), subset(body, 6, 5)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByLayout, 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), body.size());
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// Two pieces of one body, markers 0-6 and 5-9, that share markers 5 and 6: the first seen for
// four seconds, then for half a second only the two shared markers, then the second piece. No
// frame shows three markers of the one with a marker of the other, so nothing fixes how the
// second turns about the line through 5 and 6 against the first: they stay two models. But the
// shared markers were followed from point to point all along, from the one's poses into the
// other's, and completion says the two are pieces of one object, which only showing it again can
// mend. Two objects (the second scene) are not.
TEST(CalibrationCompletion, SaysWhichModelsArePiecesOfOneObjectThatNothingTied) {
    const std::vector<Vec3> body = test::irregularLayout(10, 31, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 16, [](std::size_t, std::size_t m, double t) {
            if (t < 4.0)
                return m <= 6;
            return t < 4.5 ? m == 5 || m == 6 : m >= 5;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 7), subset(body, 5, 5)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 2U);
    EXPECT_LT(layoutError_mm(out[0], subset(body, 0, 7)), 0.1);
    EXPECT_LT(layoutError_mm(out[1], subset(body, 5, 5)), 0.1);
    ASSERT_EQ(completion.untiedPieces().size(), 1U);
    EXPECT_EQ(completion.untiedPieces()[0].first, 0U);
    EXPECT_EQ(completion.untiedPieces()[0].second, 1U);
    EXPECT_EQ(completion.untiedPieces()[0].sharedMarkers, 2U);
    EXPECT_EQ(completion.counters().untiedPieces, 1U);

    const std::vector<Vec3> other = test::irregularLayout(8, 32, 15.0);
    const SessionBuffer two = sessionWhere({body, other}, 10.0, 0.05, 17,
                                           [](std::size_t, std::size_t, double) { return true; });
    std::vector<MarkerModel> outOfTwo = outputModels(config);
    ASSERT_EQ(completion.run(two, modelsOf({body, other}), outOfTwo), 2U);
    EXPECT_TRUE(completion.untiedPieces().empty());
    EXPECT_EQ(completion.counters().untiedPieces, 0U);
}

// Two pieces of one body that share exactly three markers, seen twenty seconds apart with
// nothing in view between: no frame poses both and no chain of frames leads from one to the
// other. The triangle they share, like no other of either, is the only tie, and it holds.
TEST(CalibrationCompletion, JoinsTwoPiecesThatShareOnlyATriangleSeenFarApartInTime) {
    const std::vector<Vec3> body = test::irregularLayout(10, 26, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 12, [](std::size_t, std::size_t m, double t) {
            return t < 4.0 ? m <= 6 : t >= 6.0 && m >= 4;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    // The condition of the scene: the shared triangle (markers 4, 5, 6) is the pieces' only tie.
    ASSERT_TRUE(completion_detail::soleSharedTriangle(subset(body, 4, 6), subset(body, 0, 7),
                                                      completion_detail::kTriangleTie));
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 7), subset(body, 4, 6)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByLayout, 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// Two pieces of one body sharing three markers, never posed in the same frame: the first is
// lost when a hand hides everything for eight frames (longer than the tracker predicts a body it
// lost), after which only the three shared markers are in view until the second piece's other
// markers come in half a second later. Each piece holds a copy of the shared triangle elsewhere,
// so three markers find neither piece and the triangle is no identity. The three points are
// followed frame to frame across the gap and into the second piece's poses: they are the same
// points in both pieces' frames, which ties them.
TEST(CalibrationCompletion, JoinsTwoPiecesWhoseSharedMarkersAreFollowedFromOneToTheOther) {
    std::vector<Vec3> body = test::irregularLayout(10, 27, 15.0);
    for (const auto& [first, angle, offset] :
         {std::tuple{std::size_t{0}, 1.1, Vec3(70.0, 10.0, -20.0)},
          std::tuple{std::size_t{7}, -0.9, Vec3(-15.0, 75.0, 25.0)}}) {
        RigidTransform copy;
        copy.rotation = Quat(Eigen::AngleAxisd(angle, Vec3(0.2, 0.4, 1.0).normalized()));
        copy.translation_mm = offset;
        for (std::size_t k = 0; k < 3; ++k)
            body[first + k] = copy.apply(body[4 + k]);
    }
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 14, [](std::size_t, std::size_t m, double t) {
            if (t < 4.0)
                return m <= 6;
            if (t < 4.08)
                return false;
            return t < 4.5 ? m >= 4 && m <= 6 : m >= 4;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    // The condition of the scene: the shared triangle ties nothing by its shape.
    ASSERT_FALSE(completion_detail::soleSharedTriangle(subset(body, 4, 6), subset(body, 0, 7),
                                                       completion_detail::kTriangleTie));
    const std::vector<MarkerModel> seeds = modelsOf({subset(body, 0, 7), subset(body, 4, 6)});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(completion.counters().joinedByTracks, 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// Two objects with a triangle of markers alike, one coming into view 50 ms after the other left,
// 120 mm away: as one body they would jump faster than either was ever seen to move, so the
// likeness does not join them.
TEST(CalibrationCompletion, KeepsTwoObjectsWithALikeTriangleApart) {
    const std::vector<Vec3> a = test::irregularLayout(7, 24, 15.0);
    // b's own markers lie farther from each other and from its copy of a's triangle than any two
    // markers of a (within +-40 mm), so that no other triangle of b is like one of a's, whatever
    // layout the platform's random numbers give a.
    std::vector<Vec3> b{Vec3(0.0, 0.0, 200.0), Vec3(190.0, 25.0, 210.0), Vec3(60.0, 205.0, 245.0)};
    RigidTransform apart;
    apart.rotation = Quat(Eigen::AngleAxisd(0.8, Vec3(1.0, 0.3, 0.0).normalized()));
    apart.translation_mm = Vec3(20.0, -70.0, 30.0);
    for (std::size_t m = 0; m < 3; ++m)
        b.push_back(apart.apply(a[m]));
    const SessionBuffer session =
        sessionWhere({a, b}, 10.0, 0.05, 13, [](std::size_t body, std::size_t, double t) {
            return body == 0 ? t < 5.0 : t >= 5.05;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    // The condition of the scene: without the motion, the likeness would tie them.
    ASSERT_TRUE(completion_detail::soleSharedTriangle(b, a, completion_detail::kTriangleTie));
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({a, b}), out), 2U);
    EXPECT_EQ(completion.counters().joinedByLayout, 0U);
    EXPECT_LT(layoutError_mm(out[0], a), 0.1);
    EXPECT_LT(layoutError_mm(out[1], b), 0.1);
}

// Markers 0-5 of a body until 4 s; from 5 s markers 0-2, and marker 6 every other fifth of a
// second.
bool threeAndANewOne(std::size_t m, double t) {
    if (t < 4.0)
        return m < 6;
    const bool newOneShows = static_cast<int>(t / 0.2) % 2 == 0;
    return t >= 5.0 && (m < 3 || (m == 6 && newOneShows));
}

// A piece of a body that is later seen only by three of its markers, and beside them, every
// other fifth of a second, a marker it has never been seen with: the tracker needs four of a
// model's markers to find it, and never more than four points are in view, too few to be found as
// a body of their own. Only the three points whose distances match one triangle of the piece, and
// no other, pose it; the new marker is then learnt from those poses.
TEST(CalibrationCompletion, PosesAPieceFromThreeOfItsMarkersAndLearnsAMarkerSeenWithThem) {
    const std::vector<Vec3> body = test::irregularLayout(7, 13, 15.0);
    const CompletionConfig config;
    // The condition of the scene: the three markers' triangle is like no other of the layout.
    using completion_detail::congruent;
    using completion_detail::sortedTriangle;
    const auto shown = sortedTriangle(body[0], body[1], body[2], 0, 1, 2);
    ASSERT_TRUE(completion_detail::wellShaped(shown, config.triangleTolerance_mm));
    for (std::uint32_t i = 0; i < body.size(); ++i)
        for (std::uint32_t j = i + 1; j < body.size(); ++j)
            for (std::uint32_t k = std::max(j + 1, 3U); k < body.size(); ++k) {
                ASSERT_FALSE(congruent(shown, sortedTriangle(body[i], body[j], body[k], i, j, k),
                                       config.triangleUniqueness * config.triangleTolerance_mm));
            }
    const SessionBuffer session =
        sessionWhere({body}, 10.0, 0.05, 12,
                     [](std::size_t, std::size_t m, double t) { return threeAndANewOne(m, t); });
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({subset(body, 0, 6)}), out), 1U);
    EXPECT_GT(completion.counters().framesFromTriangles, 0U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// The same piece beside another object, in view all the time and moving its own way, that has a
// triangle like the piece's three: three points like it are the other object's only where that
// object is, and it is found elsewhere in every frame, so they pose the piece.
TEST(CalibrationCompletion, PosesAPieceByATriangleLikeOneOfAnObjectFoundElsewhere) {
    const std::vector<Vec3> body = test::irregularLayout(7, 13, 15.0);
    // The other object's own markers lie far from each other and from its copy of the triangle
    // (as in KeepsTwoObjectsWithALikeTriangleApart).
    std::vector<Vec3> other{Vec3(0.0, 0.0, 200.0), Vec3(190.0, 25.0, 210.0),
                            Vec3(60.0, 205.0, 245.0), Vec3(-120.0, 140.0, 260.0)};
    RigidTransform copied;
    copied.rotation = Quat(Eigen::AngleAxisd(0.8, Vec3(1.0, 0.3, 0.0).normalized()));
    copied.translation_mm = Vec3(20.0, -70.0, 30.0);
    for (std::size_t m = 0; m < 3; ++m)
        other.push_back(copied.apply(body[m]));
    const CompletionConfig config;
    // The condition of the scene: the other object has the piece's triangle.
    using completion_detail::sortedTriangle;
    ASSERT_TRUE(completion_detail::congruent(sortedTriangle(body[0], body[1], body[2], 0, 1, 2),
                                             sortedTriangle(other[4], other[5], other[6], 4, 5, 6),
                                             config.triangleTolerance_mm));
    const SessionBuffer session =
        sessionWhere({body, other}, 10.0, 0.05, 12, [](std::size_t b, std::size_t m, double t) {
            return b == 1 || threeAndANewOne(m, t);
        });
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({subset(body, 0, 6), other}), out), 2U);
    EXPECT_GT(completion.counters().framesFromTriangles, 0U);
    // Both have seven markers; which model is which does not matter.
    const bool pieceFirst = layoutError_mm(out[0], body) < layoutError_mm(out[1], body);
    EXPECT_LT(layoutError_mm(out[pieceFirst ? 0 : 1], body), 0.1);
    EXPECT_LT(layoutError_mm(out[pieceFirst ? 1 : 0], other), 0.1);
}

// A body the online stage made no model of (no seed at all) is found in the session's points as a
// set that keeps its distances while it moves; four reflections of the room that stand still keep
// theirs too, but are no body.
TEST(CalibrationCompletion, FindsABodyNoSeedExplainsButNotReflectionsThatStandStill) {
    const std::vector<Vec3> body = test::irregularLayout(6, 19, 15.0);
    const std::vector<Vec3> reflections{Vec3(-150, 40, 700), Vec3(-120, 60, 720),
                                        Vec3(-170, 90, 690), Vec3(-140, 20, 760)};
    const std::size_t frames = 1000;
    SessionBuffer session(frames, frames * 16);
    std::mt19937 random(9);
    std::normal_distribution<double> noise(0.0, 0.1);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        const RigidTransform pose = turning(t, Vec3(40.0, 0.0, 600.0), 0.0);
        points.clear();
        for (const Vec3& m : body)
            points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        for (const Vec3& r : reflections)
            points.push_back(r + Vec3(noise(random), noise(random), noise(random)));
        session.append(t, points);
    }
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, {}, out), 1U);
    EXPECT_GE(completion.counters().discovered, 1U);
    EXPECT_LT(layoutError_mm(out[0], body), 0.1);
}

// Two bodies turning on their own, in view at once for 0.15 s: found together, but no one layout
// of both fits those frames, so they stay two.
TEST(CalibrationCompletion, KeepsTwoBodiesSeenTogetherOnlyBrieflyApart) {
    const std::vector<Vec3> a = test::irregularLayout(5, 16, 15.0);
    const std::vector<Vec3> b = test::irregularLayout(5, 17, 15.0);
    const SessionBuffer session =
        sessionWhere({a, b}, 10.0, 0.1, 7, [](std::size_t body, std::size_t, double t) {
            return body == 0 ? t < 5.0 : t >= 4.85;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({a, b}), out), 2U);
    EXPECT_EQ(completion.counters().joinedByMotion, 0U);
}

// A body shown for less than a second (a piece of an object seen in passing, which nothing ties
// to the rest of it) is no model: it would be tracked as an object of its own. Shown for longer,
// it is one.
TEST(CalibrationCompletion, LeavesOutABodyShownForLessThanASecond) {
    const std::vector<Vec3> a = test::irregularLayout(6, 19, 15.0);
    const std::vector<Vec3> b = test::irregularLayout(5, 20, 15.0);
    const CompletionConfig config;
    for (const auto& [shown_s, expected] : {std::pair{0.6, 1U}, std::pair{1.4, 2U}}) {
        const SessionBuffer session =
            sessionWhere({a, b}, 10.0, 0.1, 9, [&](std::size_t body, std::size_t, double t) {
                return body == 0 || (t >= 4.0 && t < 4.0 + shown_s);
            });
        CalibrationCompletion completion(config);
        std::vector<MarkerModel> out = outputModels(config);
        ASSERT_EQ(completion.run(session, modelsOf({a, b}), out), expected) << shown_s << " s";
        EXPECT_LT(layoutError_mm(out[0], a), 0.08);
        EXPECT_EQ(completion.counters().droppedSeenBriefly, 2U - expected);
    }
}

TEST(CalibrationCompletion, KeepsTwoBodiesApartAndDropsWhatNothingShows) {
    const std::vector<Vec3> a = test::irregularLayout(10, 9, 15.0);
    const std::vector<Vec3> b = test::irregularLayout(8, 10, 15.0);
    const SessionBuffer session = sessionOf({a, b}, 10.0, 0.1, 3);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    // A seed no frame shows: markers far from anything seen.
    std::vector<Vec3> ghost = test::irregularLayout(5, 11, 15.0);
    for (Vec3& p : ghost)
        p *= 3.0;
    const std::vector<MarkerModel> seeds = modelsOf({subset(a, 0, 7), subset(b, 0, 6), ghost});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 2U);
    EXPECT_LT(layoutError_mm(out[0], a), 0.08);
    EXPECT_LT(layoutError_mm(out[1], b), 0.08);
    EXPECT_EQ(completion.counters().dropped, 1U);
}

// \a frames frames of \a body turning in front of the cameras with \a noise_mm of point noise,
// each frame's points then changed by \a edit(frame, pose, points).
template <typename Edit>
SessionBuffer sessionOfOneBody(const std::vector<Vec3>& body, std::size_t frames, double noise_mm,
                               unsigned seed, Edit edit) {
    SessionBuffer session(frames, frames * 16);
    std::mt19937 random(seed);
    std::normal_distribution<double> noise(0.0, noise_mm);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        const RigidTransform pose = turning(t, Vec3(0.0, 0.0, 600.0), 0.0);
        points.clear();
        for (const Vec3& m : body)
            points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        edit(f, pose, points);
        session.append(t, points);
    }
    return session;
}

// A ring of five markers, nearly evenly spaced, never seen more than four at a time (each in turn
// hidden for a fifth of the session), whose online model holds four of them. Any four of a ring
// look alike, so S_min of the five is five; asked for five, completion would never find the
// ring again once it had learnt the fifth marker, and would drop it. It asks for no more markers
// than were ever seen together.
TEST(CalibrationCompletion, FindsARingSeenFourAtATimeByFourOfItsMarkers) {
    std::vector<Vec3> ring;
    for (const double degrees : {0.0, 73.0, 143.0, 217.0, 289.0})
        ring.emplace_back(30.0 * std::cos(degrees * std::numbers::pi / 180.0),
                          30.0 * std::sin(degrees * std::numbers::pi / 180.0), 0.0);
    const std::size_t frames = 2000;
    const SessionBuffer session = sessionOfOneBody(
        ring, frames, 0.05, 6,
        [&](std::size_t f, const RigidTransform&, std::vector<Vec3>& points) {
            points.erase(points.begin() + static_cast<std::ptrdiff_t>(f * 5 / frames));
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    const std::vector<Vec3> four(ring.begin(), ring.begin() + 4);
    ASSERT_EQ(completion.run(session, modelsOf({four}), out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), ring.size());
    EXPECT_LT(layoutError_mm(out[0], ring), 0.02);
}

// A point that rides along with the body for a while (a marker of something held against it)
// sits at one place in the body's frame for 0.6 s; the two times the body is later seen from the
// same directions, it is not there. It is no marker of the body, although a third of the frames
// that look at that place from where it was seen do show it.
TEST(CalibrationCompletion, LeavesOutAPointThatRodeAlongForAWhile) {
    const std::vector<Vec3> body = test::irregularLayout(10, 12, 15.0);
    const Vec3 rider_body_mm(55.0, 10.0, -5.0);
    const SessionBuffer session =
        sessionOfOneBody(body, 2000, 0.05, 4,
                         [&](std::size_t f, const RigidTransform& pose, std::vector<Vec3>& points) {
                             if (f >= 100 && f < 160)
                                 points.push_back(pose.apply(rider_body_mm));
                         });
    const CompletionConfig config;
    ASSERT_LT(config.minSeen_s, 0.6) << "the rider is seen long enough to be a marker by time";
    CalibrationCompletion completion(config);
    const std::vector<MarkerModel> seeds = modelsOf({body});
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, seeds, out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), body.size());
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
}

// A session of a rigid body (0.1 mm of point noise) and of \a wobbly markers (body frame, mm)
// carried by a second pose but each wobbling by \a wobble_mm about its place, as markers on skin
// or on a flexible strap do; the first \a onRigid of them ride on the rigid body instead.
SessionBuffer sessionWithWobble(const std::vector<Vec3>& rigid, const std::vector<Vec3>& wobbly,
                                std::size_t onRigid, double wobble_mm) {
    const std::size_t frames = 2000;
    SessionBuffer session(frames, frames * 32);
    std::mt19937 random(7);
    std::normal_distribution<double> noise(0.0, 0.1);
    std::normal_distribution<double> wobble(0.0, wobble_mm);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        const RigidTransform pose = turning(t, Vec3(-60.0, 0.0, 600.0), 0.0);
        const RigidTransform other = turning(t, Vec3(60.0, 0.0, 600.0), 1.3, Vec3::UnitX());
        points.clear();
        for (const Vec3& m : rigid)
            points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        for (std::size_t k = 0; k < wobbly.size(); ++k)
            points.push_back((k < onRigid ? pose : other).apply(wobbly[k]) +
                             Vec3(wobble(random), wobble(random), wobble(random)));
        session.append(t, points);
    }
    return session;
}

// A marker on a flexible tab of the object wobbles by 0.6 mm about its place: close enough to
// be learnt as a place of the body, but its points lie off the body's poses about six times
// farther than the other markers' (a rider, or a marker of another object held against it, does
// so too). It is left out, and the rest of the layout is not pulled by it.
TEST(CalibrationCompletion, LeavesOutAMarkerThatDoesNotMoveWithTheBody) {
    const std::vector<Vec3> body = test::irregularLayout(10, 12, 15.0);
    const SessionBuffer session = sessionWithWobble(body, {Vec3(55.0, 10.0, -5.0)}, 1, 0.6);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({body}), out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), body.size());
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
    EXPECT_EQ(completion.counters().markersNotRigid, 1U);
}

// Markers on skin keep their distances only within a millimetre or two, and a group of them is
// learnt as a body when the edge tolerance allows it; beside a rigid object in the same session,
// their points lie off any pose of theirs several times farther than the object's do: no rigid
// object, no model (the person carrying the Vicon box: 6 such bodies dropped, the box kept).
TEST(CalibrationCompletion, DropsABodyOfMarkersOnSkinBesideARigidOne) {
    const std::vector<Vec3> box = test::irregularLayout(8, 3, 15.0);
    const std::vector<Vec3> skin = test::irregularLayout(6, 5, 20.0);
    const SessionBuffer session = sessionWithWobble(box, skin, 0, 0.5);
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({box, skin}), out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), box.size());
    EXPECT_EQ(completion.counters().droppedNotRigid, 1U);
}

// For two seconds of a twenty-second session one marker's point lies 1 mm off its place (a
// finger over half of it shifts its centre so): the tracker drops it from those poses as an
// outlier, but the layout's least squares matches every marker within reach, and a tenth of one
// marker's frames 1 mm off would pull it by a tenth of a millimetre. Those frames fit far worse
// than the rig measures, and are left out of the layout.
TEST(CalibrationCompletion, LeavesFramesThatFitFarWorseThanTheRigOutOfTheLayout) {
    const std::vector<Vec3> body = test::irregularLayout(10, 12, 15.0);
    const SessionBuffer session = sessionOfOneBody(
        body, 2000, 0.05, 5, [](std::size_t f, const RigidTransform&, std::vector<Vec3>& points) {
            if (f >= 800 && f < 1000)
                points[0] += Vec3(1.0, 0.0, 0.0);
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({body}), out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), body.size());
    EXPECT_LT(layoutError_mm(out[0], body), 0.02);
}

// A marker seen only ever with the same two markers of the body, in frames of those three, and
// never just after or before a frame of the rest: each such frame fixes its distances from the
// two, but not its turn about their line, which the frame's pose takes up, and no handover
// carries the turn over from the rest; whatever place the session's poses gave it, no frame says
// it is right. It is dropped, and the layout keeps the markers that frames fix to each other.
TEST(CalibrationCompletion, DropsAMarkerThatNoFrameFixesToTheRest) {
    const std::vector<Vec3> body = test::irregularLayout(7, 12, 15.0);
    const SessionBuffer session =
        sessionWhere({body}, 12.0, 0.05, 11, [](std::size_t, std::size_t m, double t) {
            const double phase = std::fmod(t, 3.0);
            if ((phase >= 2.0 && phase < 2.05) || phase >= 2.95)
                return m <= 1;
            return phase >= 2.05 ? m <= 1 || m == 6 : m <= 5;
        });
    const CompletionConfig config;
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({body}), out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), 6U);
    EXPECT_EQ(completion.counters().markersNotFixed, 1U);
    EXPECT_EQ(completion.precision()[0].looseModes, 0U);
    EXPECT_LT(layoutError_mm(out[0], subset(body, 0, 6)), 0.05);
}

// A stereo rig measures a point at 1 m four times as coarsely as one at 0.5 m (its error along
// the line of sight grows with the square of the distance). Two rigid objects, one near and one
// far, each fit their poses as well as the rig allows where they are: both are rigid, and both
// are learnt whole; judged by the near one's residuals alone, the far one would be dropped.
TEST(CalibrationCompletion, JudgesAFarObjectByTheRigsNoiseWhereItIs) {
    const std::vector<Vec3> nearBody = test::irregularLayout(8, 3, 15.0);
    const std::vector<Vec3> farBody = test::irregularLayout(8, 5, 15.0);
    const std::size_t frames = 2000;
    SessionBuffer session(frames, frames * 32);
    std::mt19937 random(9);
    std::normal_distribution<double> unit(0.0, 1.0);
    std::vector<Vec3> points;
    const auto observe = [&](const RigidTransform& pose, const std::vector<Vec3>& layout) {
        for (const Vec3& m : layout) {
            const Vec3 p = pose.apply(m);
            const double sigma_mm = 0.05 * p.squaredNorm() / (500.0 * 500.0);
            points.push_back(p + sigma_mm * Vec3(unit(random), unit(random), unit(random)));
        }
    };
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        points.clear();
        observe(turning(t, Vec3(-60.0, 0.0, 500.0), 0.0), nearBody);
        observe(turning(t, Vec3(60.0, 0.0, 1000.0), 1.3, Vec3::UnitX()), farBody);
        session.append(t, points);
    }
    CompletionConfig config;
    ASSERT_TRUE(config.noiseGrowsWithDistance);
    ASSERT_EQ(config.viewpoint_rig_mm, Vec3::Zero());
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({nearBody, farBody}), out), 2U);
    EXPECT_EQ(completion.counters().markersNotRigid, 0U);
    EXPECT_EQ(out[0].markers_model_mm.size(), 8U);
    EXPECT_EQ(out[1].markers_model_mm.size(), 8U);
}

// A glint that stands still in the rig (a screw head, a watch) sits at one place of the body's
// frame for the 0.6 s the body is held still, and the body is never seen from there again in the
// session: by time and by the share of frames that look at it, it would be a marker. It is none:
// the body never carried it anywhere, while every marker travels with the body.
TEST(CalibrationCompletion, LeavesOutAGlintThatStoodStillWhileTheBodyDid) {
    const std::vector<Vec3> body = test::irregularLayout(10, 12, 15.0);
    const std::size_t frames = 400;
    SessionBuffer session(frames, frames * 16);
    std::mt19937 random(6);
    std::normal_distribution<double> noise(0.0, 0.05);
    // Held still from 1.0 s to 1.6 s: the pose of 1.0 s, then on as if no time had passed.
    auto poseAt = [](double t) {
        return turning(t < 1.0 ? t : std::max(1.0, t - 0.6), Vec3(0.0, 0.0, 600.0), 0.0);
    };
    const Vec3 glint_rig_mm = poseAt(1.0).apply(Vec3(55.0, 10.0, -5.0));
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        const RigidTransform pose = poseAt(t);
        points.clear();
        for (const Vec3& m : body)
            points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        points.push_back(glint_rig_mm + Vec3(noise(random), noise(random), noise(random)));
        session.append(t, points);
    }
    const CompletionConfig config;
    ASSERT_LT(config.minSeen_s, 0.6) << "the glint is seen long enough to be a marker by time";
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({body}), out), 1U);
    EXPECT_EQ(out[0].markers_model_mm.size(), body.size());
    EXPECT_LT(layoutError_mm(out[0], body), 0.05);
}

// A marker at the edge of its view, or often behind a passing hand: whenever the turning body
// shows it to the cameras it is there in only every fourth frame, a quarter of the frames that
// look at it as it was seen. It is there in every pass, so it is a marker, unlike a point that
// rode along in one pass only.
TEST(CalibrationCompletion, KeepsAMarkerSeenInEveryPassThoughInFewOfItsFrames) {
    const std::vector<Vec3> body = test::irregularLayout(10, 12, 15.0);
    const Vec3 flicker_body_mm(55.0, 10.0, -5.0);
    const Vec3 normal_body = flicker_body_mm.normalized();
    const std::size_t frames = 3000;
    SessionBuffer session(frames, frames * 16);
    std::mt19937 random(5);
    std::normal_distribution<double> noise(0.0, 0.05);
    std::vector<Vec3> points;
    std::size_t passes = 0, lastFacing = 0;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        const RigidTransform pose = turning(t, Vec3(0.0, 0.0, 600.0), 0.0);
        points.clear();
        for (const Vec3& m : body)
            points.push_back(pose.apply(m) + Vec3(noise(random), noise(random), noise(random)));
        const Vec3 toCameras_body =
            (pose.inverse().apply(Vec3::Zero()) - flicker_body_mm).normalized();
        if (toCameras_body.dot(normal_body) > std::cos(50.0 * std::numbers::pi / 180.0)) {
            if (passes == 0 || f > lastFacing + 10)
                ++passes;
            lastFacing = f;
            if (f % 4 == 0)
                points.push_back(pose.apply(flicker_body_mm) +
                                 Vec3(noise(random), noise(random), noise(random)));
        }
        session.append(t, points);
    }
    ASSERT_GE(passes, 3U) << "the body shows the marker again and again";
    const CompletionConfig config;
    ASSERT_GT(config.minSeenShare, 0.25) << "a quarter of its frames is too few by share alone";
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({body}), out), 1U);
    std::vector<Vec3> withFlicker = body;
    withFlicker.push_back(flicker_body_mm);
    EXPECT_LT(layoutError_mm(out[0], withFlicker), 0.1);
}

// Two objects side by side, each turning on its own, except for 0.6 s in which the second keeps
// still against the first: its markers then sit at places of the first's frame, in a look at
// that side of the first that the session never repeats, so no later frame tells them from the
// first's markers. But the second's own pose puts its markers on those points, and the two are
// found together at wandering relative poses the rest of the time: they are the second's.
TEST(CalibrationCompletion, LeavesOutMarkersOfAnotherObjectThatKeptStillAgainstIt) {
    const std::vector<Vec3> a = test::irregularLayout(8, 41, 15.0);
    const std::vector<Vec3> b = test::irregularLayout(6, 42, 15.0);
    const std::size_t frames = 500;
    SessionBuffer session(frames, frames * 16);
    std::mt19937 random(6);
    std::normal_distribution<double> noise(0.0, 0.05);
    auto poseA = [](double t) { return turning(t, Vec3(-60.0, 0.0, 600.0), 0.0); };
    auto poseB = [](double t) { return turning(t, Vec3(60.0, 0.0, 600.0), 1.3, Vec3::UnitX()); };
    // b against a while it keeps still: as it was when it stopped moving on its own.
    const RigidTransform T_a_from_b = poseA(1.0).inverse() * poseB(1.0);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        const bool still = t >= 1.0 && t < 1.6;
        const RigidTransform rig_from_a = poseA(t);
        const RigidTransform rig_from_b = still ? rig_from_a * T_a_from_b : poseB(t);
        points.clear();
        for (const Vec3& m : a)
            points.push_back(rig_from_a.apply(m) +
                             Vec3(noise(random), noise(random), noise(random)));
        for (const Vec3& m : b)
            points.push_back(rig_from_b.apply(m) +
                             Vec3(noise(random), noise(random), noise(random)));
        session.append(t, points);
    }
    const CompletionConfig config;
    ASSERT_LT(config.minSeen_s, 0.6) << "b's markers sit still against a long enough to count";
    CalibrationCompletion completion(config);
    std::vector<MarkerModel> out = outputModels(config);
    ASSERT_EQ(completion.run(session, modelsOf({a, b}), out), 2U);
    EXPECT_LT(layoutError_mm(out[0], a), 0.1);
    EXPECT_LT(layoutError_mm(out[1], b), 0.1);
}

// The same frames with each frame's points in four other orders give the same models, bit for bit
// the online stage and completion both put every frame in one order first.
TEST(CalibrationCompletion, SameModelsWhateverTheOrderOfPointsInAFrame) {
    const std::vector<std::vector<Vec3>> bodies{test::irregularLayout(9, 13, 15.0),
                                                test::irregularLayout(7, 14, 15.0)};
    const std::size_t frames = 1500;
    std::vector<std::vector<Vec3>> recording(frames);
    std::mt19937 random(5);
    std::normal_distribution<double> noise(0.0, 0.1);
    for (std::size_t f = 0; f < frames; ++f) {
        const double t = static_cast<double>(f) / 100.0;
        for (std::size_t b = 0; b < bodies.size(); ++b) {
            // The bodies move apart after the first second, so the online stage splits them.
            const double apart = std::min(1.0, t) * 90.0;
            const RigidTransform pose =
                turning(t, Vec3((b == 0 ? -1.0 : 1.0) * apart, 0.0, 600.0),
                        0.7 * static_cast<double>(b), b == 0 ? Vec3::UnitY() : Vec3::UnitX());
            for (const Vec3& m : bodies[b])
                recording[f].push_back(pose.apply(m) +
                                       Vec3(noise(random), noise(random), noise(random)));
        }
    }
    auto learn = [&](unsigned shuffleSeed) {
        std::mt19937 shuffler(shuffleSeed);
        CalibrationSession session(CalibrationConfig{}, CompletionConfig{}, frames, frames * 32);
        for (std::size_t f = 0; f < frames; ++f) {
            std::vector<Vec3> points = recording[f];
            if (shuffleSeed != 0)
                std::shuffle(points.begin(), points.end(), shuffler);
            session.update(static_cast<double>(f) / 100.0, points);
        }
        std::vector<MarkerModel> out = session.complete();
        return out;
    };
    const std::vector<MarkerModel> reference = learn(0);
    ASSERT_GE(reference.size(), 1U);
    for (unsigned order = 1; order <= 4; ++order) {
        const std::vector<MarkerModel> models = learn(order);
        ASSERT_EQ(models.size(), reference.size()) << "order " << order;
        for (std::size_t m = 0; m < models.size(); ++m) {
            ASSERT_EQ(models[m].markers_model_mm.size(), reference[m].markers_model_mm.size());
            for (std::size_t k = 0; k < models[m].markers_model_mm.size(); ++k)
                EXPECT_EQ(models[m].markers_model_mm[k], reference[m].markers_model_mm[k])
                    << "order " << order << ", model " << m << ", marker " << k;
            EXPECT_EQ(models[m].edges.size(), reference[m].edges.size());
            EXPECT_EQ(models[m].sMin, reference[m].sMin);
        }
    }
}

} // namespace
} // namespace edgetrack
