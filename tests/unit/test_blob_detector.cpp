// Tests of the blob detector against truth and against a plain flood-fill reference.
#include <algorithm>
#include <limits>
#include <queue>
#include <random>

#include <gtest/gtest.h>

#include "core/blob_detector.hpp"
#include "hal/sim/world.hpp"
#include "tests/support/alloc_guard.hpp"

using namespace edgetrack;

namespace {

struct Image {
    int width;
    int height;
    int stride;
    std::vector<std::uint8_t> pixels;

    Image(int w, int h, int s = 0)
        : width(w)
        , height(h)
        , stride(s > 0 ? s : w)
        , pixels(static_cast<std::size_t>(stride * h), 10) {}
    std::uint8_t& at(int x, int y) { return pixels[static_cast<std::size_t>(y * stride + x)]; }
};

// Draws spots with the simulator's renderer profile (blurred saturating discs).
void drawSpots(Image& image, const std::vector<sim::Glint>& spots) {
    const sim::FrameRenderer renderer(image.width, image.height, 10.0, 0.0, 1);
    sim::Observation obs;
    obs.glints[0] = spots;
    // The renderer writes rows of `width` at `stride`; padding bytes keep their value.
    renderer.render(image.pixels, image.stride, 0, obs, 1.0, 0);
}

sim::Glint disc(double x, double y, double radius, double peak = 900.0) {
    sim::Glint g;
    g.centre_px = {x, y};
    g.radiusMajor_px = g.radiusMinor_px = radius;
    g.peak_dn = peak;
    return g;
}

// The blob of \a blobs whose centre lies nearest \a at_px; nullptr when there is none.
template <typename Blobs>
const Blob* nearestBlob(const Blobs& blobs, const Vec2& at_px) {
    const Blob* nearest = nullptr;
    for (const Blob& b : blobs)
        if (nearest == nullptr ||
            (b.centre_px - at_px).norm() < (nearest->centre_px - at_px).norm())
            nearest = &b;
    return nearest;
}

// How far (px) the nearest blob's centre lies from \a at_px; infinity when there is no blob.
template <typename Blobs>
double distanceToNearestBlob(const Blobs& blobs, const Vec2& at_px) {
    const Blob* nearest = nearestBlob(blobs, at_px);
    return nearest == nullptr ? std::numeric_limits<double>::infinity()
                              : (nearest->centre_px - at_px).norm();
}

// Reference: breadth-first 8-connected labelling and the same moments, pixel by pixel.
struct ReferenceBlob {
    Vec2 centre;
    int area;
};
std::vector<ReferenceBlob> referenceComponents(Image& image, std::uint8_t threshold) {
    std::vector<int> label(static_cast<std::size_t>(image.width * image.height), -1);
    std::vector<ReferenceBlob> out;
    for (int y = 0; y < image.height; ++y)
        for (int x = 0; x < image.width; ++x) {
            if (image.at(x, y) < threshold ||
                label[static_cast<std::size_t>(y * image.width + x)] >= 0)
                continue;
            double sumI = 0, sumIx = 0, sumIy = 0;
            int area = 0;
            std::queue<std::pair<int, int>> queue;
            queue.push({x, y});
            label[static_cast<std::size_t>(y * image.width + x)] = 1;
            while (!queue.empty()) {
                const auto [px, py] = queue.front();
                queue.pop();
                const double intensity = image.at(px, py);
                sumI += intensity;
                sumIx += intensity * px;
                sumIy += intensity * py;
                ++area;
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const int nx = px + dx, ny = py + dy;
                        if (nx < 0 || ny < 0 || nx >= image.width || ny >= image.height)
                            continue;
                        auto& l = label[static_cast<std::size_t>(ny * image.width + nx)];
                        if (l < 0 && image.at(nx, ny) >= threshold) {
                            l = 1;
                            queue.push({nx, ny});
                        }
                    }
            }
            out.push_back({Vec2(sumIx / sumI, sumIy / sumI), area});
        }
    return out;
}

BlobDetectorConfig permissive() {
    // Accepts every component, so the comparison with the reference covers all of them.
    BlobDetectorConfig c;
    c.minArea_px = 1;
    c.maxArea_px = 1 << 30;
    c.maxElongation = 1e9;
    c.minFill = 0.0;
    c.maxBlobs = 4096;
    c.maxLabels = 1 << 16;
    c.splitMerged = false;
    return c;
}

} // namespace

TEST(BlobDetector, CentresOfIsolatedDiscsAreSubPixel) {
    Image image(1280, 800);
    std::vector<sim::Glint> spots;
    std::mt19937 random(2);
    std::uniform_real_distribution<double> x(20, 1260), y(20, 780), r(2.5, 7.0);
    std::vector<Vec2> centres;
    while (spots.size() < 40) {
        const sim::Glint g = disc(x(random), y(random), r(random));
        bool apart = true;
        for (const sim::Glint& o : spots)
            apart = apart && (o.centre_px - g.centre_px).norm() > 30.0;
        if (apart)
            spots.push_back(g);
    }
    drawSpots(image, spots);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    ASSERT_TRUE(detector.isValid());
    FixedVector<Blob, 64> blobs;
    detector.detect(image.pixels.data(), image.stride, blobs);
    ASSERT_EQ(blobs.size(), spots.size());
    double sum = 0.0;
    for (const sim::Glint& g : spots) {
        const double nearest = distanceToNearestBlob(blobs, g.centre_px);
        // Cutting the blurred edge at the threshold biases small discs by a few hundredths.
        EXPECT_LT(nearest, 0.06);
        sum += nearest;
    }
    EXPECT_LT(sum / static_cast<double>(spots.size()), 0.03);
    for (const Blob& b : blobs) {
        EXPECT_LT(b.elongation, 1.1f);
        EXPECT_EQ(b.peak, 255);
    }
}

TEST(BlobDetector, AgreesWithFloodFillOnEveryLayout) {
    // Odd widths, a stride with padding, blobs across 64-byte boundaries and at every edge.
    for (const auto& [w, h, stride] : {std::tuple{1280, 800, 1280}, std::tuple{1000, 301, 1024},
                                       std::tuple{77, 50, 80}, std::tuple{64, 64, 64}}) {
        Image image(w, h, stride);
        std::vector<sim::Glint> spots;
        std::mt19937 random(static_cast<unsigned>(w));
        std::uniform_real_distribution<double> x(-3, w + 3), y(-3, h + 3), r(0.7, 9.0);
        for (int i = 0; i < 60; ++i)
            spots.push_back(disc(x(random), y(random), r(random), 400.0));
        spots.push_back(disc(63.5, 10.0, 3.0));   // across the first 64-byte boundary
        spots.push_back(disc(w - 1.0, 5.0, 3.0)); // on the right edge
        drawSpots(image, spots);
        // A patch of speckle: several runs start and end inside one 16-byte piece.
        std::bernoulli_distribution speck(0.4);
        for (int yy = h / 4; yy < std::min(h, h / 4 + 12); ++yy)
            for (int xx = w / 3; xx < std::min(w, w / 3 + 90); ++xx)
                if (speck(random))
                    image.at(xx, yy) = 180;
        // Isolated specks and a full-width line too.
        image.at(0, h - 1) = 255;
        image.at(w - 1, h - 1) = 255;
        for (int xx = 0; xx < w; ++xx)
            image.at(xx, h / 2) = 200;

        const BlobDetectorConfig config = permissive();
        BlobDetector detector(config, w, h);
        BoundedVector<Blob> blobs(config.maxBlobs);
        detector.detect(image.pixels.data(), stride, blobs);
        const std::vector<ReferenceBlob> reference = referenceComponents(image, config.threshold);
        ASSERT_EQ(blobs.size(), reference.size()) << w << "x" << h;
        for (const ReferenceBlob& expected : reference) {
            bool matched = false;
            for (const Blob& b : blobs)
                matched = matched || ((b.centre_px - expected.centre).norm() < 1e-9 &&
                                      static_cast<int>(b.area_px) == expected.area);
            EXPECT_TRUE(matched) << w << "x" << h << " blob at " << expected.centre.transpose();
        }
    }
}

TEST(BlobDetector, WithoutSplittingRejectsMergedElongatedSmallAndLargeBlobs) {
    Image image(640, 480);
    sim::Glint streak = disc(400, 100, 2.0);
    streak.radiusMajor_px = 12.0;
    streak.radiusMinor_px = 1.5;
    streak.angle_rad = 0.4;
    drawSpots(image, {disc(100, 100, 5.0), disc(100 + 9.0, 100, 5.0), // two touching markers
                      disc(300, 300, 5.0),                            // a good one
                      streak, disc(500, 400, 0.8, 200.0),             // a streak, a speck
                      disc(200, 380, 40.0)});                         // a lamp
    BlobDetectorConfig config;
    config.splitMerged = false;
    BlobDetector detector(config, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    ASSERT_EQ(blobs.size(), 1u);
    EXPECT_NEAR(blobs[0].centre_px.x(), 300.0, 0.02);
    const BlobCounters& c = detector.counters();
    EXPECT_EQ(c.rejectedNotRound, 2u);
    EXPECT_EQ(c.splitBlobs, 0u);
    EXPECT_EQ(c.rejectedSmall, 1u);
    EXPECT_EQ(c.rejectedLarge, 1u);
}

TEST(BlobDetector, SplitsTouchingDiscsIntoTheirCentres) {
    // Two and three discs of the simulator's profile touching or overlapping, at sub-pixel
    // centres (0.6 to 0.95 diameters apart), a streak that is one elongated spot, and a round
    // disc. Every disc is found within 0.15 px; the streak stays refused. (Three discs in a
    // triangle make a blob round enough to pass as one disc: not split yet.)
    Image image(640, 480);
    const std::vector<sim::Glint> discs = {
        disc(100.3, 100.6, 5.0),  disc(109.8, 100.9, 5.0), // 0.95 diameters apart
        disc(200.45, 150.2, 4.0), disc(205.1, 155.0, 4.0), // 0.84 diameters, diagonal
        disc(300.7, 300.1, 5.0),  disc(306.9, 300.4, 4.0), // 0.7 of the larger, unequal
        disc(450.2, 200.3, 4.5),  disc(458.0, 200.1, 4.5), disc(466.1, 199.2, 4.5), // in a row
        disc(550.0, 400.0, 5.0)};                                                   // alone
    std::vector<sim::Glint> spots = discs;
    sim::Glint streak = disc(400, 400, 2.0);
    streak.radiusMajor_px = 12.0;
    streak.radiusMinor_px = 1.5;
    streak.angle_rad = 0.4;
    spots.push_back(streak);
    drawSpots(image, spots);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(blobs.size(), discs.size());
    double sum2 = 0.0;
    for (const sim::Glint& d : discs) {
        const Blob* nearest = nearestBlob(blobs, d.centre_px);
        ASSERT_NE(nearest, nullptr);
        const double error = (nearest->centre_px - d.centre_px).norm();
        EXPECT_LT(error, 0.15) << "disc at " << d.centre_px.transpose();
        sum2 += error * error;
    }
    EXPECT_LT(std::sqrt(sum2 / static_cast<double>(discs.size())), 0.08);
    const BlobCounters& c = detector.counters();
    EXPECT_EQ(c.splitBlobs, 4u);
    EXPECT_EQ(c.splitParts, 9u);
    EXPECT_EQ(c.splitRefused, 1u) << "the streak";
}

TEST(BlobDetector, KeepsOneMarkerSeenFarOffTheAxisOrAtASlantWhole) {
    // One marker's image is an ellipse: a sphere far off the axis of a wide lens, a flat marker
    // at a slant. Elongations 1.1 to 1.9 at any angle are one blob each, at its centre; a streak
    // (a lit edge) longer than a marker can look stays refused.
    Image image(640, 480);
    std::vector<sim::Glint> ellipses;
    for (int k = 0; k < 8; ++k) {
        sim::Glint g = disc(60.0 + 75.0 * k + 0.3 * k, 120.0 + 0.17 * k, 5.0);
        g.radiusMajor_px = 5.0 * (1.1 + 0.115 * k);
        g.angle_rad = 0.4 * k;
        ellipses.push_back(g);
    }
    std::vector<sim::Glint> spots = ellipses;
    sim::Glint streak = disc(320.0, 360.0, 1.5);
    streak.radiusMajor_px = 14.0;
    streak.angle_rad = 0.7;
    spots.push_back(streak);
    drawSpots(image, spots);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.stride, blobs);
    ASSERT_EQ(blobs.size(), ellipses.size());
    for (const sim::Glint& g : ellipses) {
        const Blob* nearest = nearestBlob(blobs, g.centre_px);
        ASSERT_NE(nearest, nullptr);
        EXPECT_LT((nearest->centre_px - g.centre_px).norm(), 0.1) << g.radiusMajor_px;
        EXPECT_FALSE(nearest->split) << g.radiusMajor_px;
    }
    EXPECT_EQ(detector.counters().splitBlobs, 0u);
}

TEST(BlobDetector, SplitsDiscsFarOverEachOtherThatPassAsRound) {
    // Two discs 0.3 to 0.4 diameters apart make a blob round enough to pass the roundness
    // tests (elongation under 1.35, fill over 0.75): its outline is still two arcs, and two
    // circles fit it. A single disc, a little oval from its pixels, stays one blob at its centre.
    Image image(640, 480);
    const std::vector<sim::Glint> discs = {
        disc(100.3, 100.6, 6.0),  disc(104.1, 101.4, 6.0), // 0.32 diameters apart
        disc(250.45, 200.2, 5.0), disc(252.9, 202.6, 5.0), // 0.34, diagonal
        disc(400.2, 300.7, 6.0),  disc(404.9, 300.3, 5.0), // 0.39 of the larger, unequal
        disc(550.0, 400.0, 5.0)};                          // alone
    drawSpots(image, discs);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(detector.counters().rejectedNotRound, 0u) << "every blob passes as round";
    ASSERT_EQ(blobs.size(), discs.size());
    // Far over each other, a disc keeps less of its own outline: within 0.25 px each, 0.15 RMS.
    double sum2 = 0.0;
    for (const sim::Glint& d : discs) {
        const Blob* nearest = nearestBlob(blobs, d.centre_px);
        ASSERT_NE(nearest, nullptr);
        const double error = (nearest->centre_px - d.centre_px).norm();
        EXPECT_LT(error, 0.25) << "disc at " << d.centre_px.transpose();
        sum2 += error * error;
    }
    EXPECT_LT(std::sqrt(sum2 / static_cast<double>(discs.size())), 0.15);
    EXPECT_EQ(detector.counters().splitBlobs, 3u);
    EXPECT_EQ(detector.counters().splitParts, 6u);
}

TEST(BlobDetector, SplitsChainsOfMoreThanThreeDiscs) {
    // Markers near each other in space make chains in the image: four large discs in a row (a
    // blob 70 px long) and five small ones along a bend, each disc touching the next. Every disc
    // is found within 0.15 px.
    Image image(640, 480);
    const std::vector<sim::Glint> discs = {
        disc(100.3, 100.6, 9.0), disc(115.6, 101.4, 9.0), disc(131.2, 101.9, 9.0),
        disc(146.5, 103.1, 9.0), // four in a row, 0.85 diameters apart
        disc(300.2, 300.4, 5.0), disc(308.7, 301.1, 5.0), disc(316.3, 305.2, 5.0),
        disc(321.4, 312.6, 5.0), disc(322.9, 321.2, 5.0)}; // five along a bend
    drawSpots(image, discs);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(blobs.size(), discs.size());
    for (const sim::Glint& d : discs) {
        const double nearest = distanceToNearestBlob(blobs, d.centre_px);
        EXPECT_LT(nearest, 0.15) << "disc at " << d.centre_px.transpose();
    }
    EXPECT_EQ(detector.counters().splitBlobs, 2u);
    EXPECT_EQ(detector.counters().splitParts, 9u);
}

TEST(BlobDetector, SplitsAClusterThatPassesAsRound) {
    // Four discs in a cluster make a blob round enough to pass the roundness tests, and as one
    // blob its centre would lie between the markers. It is split: the three outer discs are found
    // within 0.2 px. The one in the middle keeps three short arcs of its outline between its
    // neighbours; it is left out rather than placed where no disc is.
    Image image(640, 480);
    const std::vector<sim::Glint> discs = {disc(209.9, 199.6, 6.0), disc(195.6, 208.7, 6.0),
                                           disc(195.1, 191.8, 6.0)};
    std::vector<sim::Glint> spots = discs;
    spots.push_back(disc(200.4, 200.3, 6.0)); // in the middle
    drawSpots(image, spots);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(detector.counters().rejectedNotRound, 0u) << "the cluster passes as round";
    EXPECT_EQ(blobs.size(), discs.size());
    for (const sim::Glint& d : discs) {
        const double nearest = distanceToNearestBlob(blobs, d.centre_px);
        EXPECT_LT(nearest, 0.2) << "disc at " << d.centre_px.transpose();
    }
    for (const Blob& b : blobs) {
        double nearest = 1e9;
        for (const sim::Glint& d : spots)
            nearest = std::min(nearest, (b.centre_px - d.centre_px).norm());
        EXPECT_LT(nearest, 0.2) << "a blob where no disc is: " << b.centre_px.transpose();
    }
}

TEST(BlobDetector, PlacesADiscThatKeepsAThirdOfItsOutline) {
    // A disc resting on two others, one below to each side (0.75 to 0.83 diameters from each),
    // keeps only its upper arc, about a third of its circle: that arc fits its circle closely
    // and places it within 0.25 px (0.15 px RMS over all the discs).
    Image image(640, 480);
    std::vector<sim::Glint> discs;
    const double spacings_px[] = {9.0, 9.5, 10.0};
    for (int i = 0; i < 3; ++i) {
        const double x = 160.3 + 150.0 * i, y = 200.4 + 0.1 * i;
        const double s = spacings_px[i];
        discs.push_back(disc(x, y, 6.0));
        discs.push_back(disc(x - 0.8 * s, y + 0.6 * s, 6.0));
        discs.push_back(disc(x + 0.8 * s, y + 0.6 * s, 6.0));
    }
    drawSpots(image, discs);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(blobs.size(), discs.size());
    double sum2 = 0.0;
    for (const sim::Glint& d : discs) {
        const double nearest = distanceToNearestBlob(blobs, d.centre_px);
        EXPECT_LT(nearest, 0.25) << "disc at " << d.centre_px.transpose();
        sum2 += nearest * nearest;
    }
    EXPECT_LT(std::sqrt(sum2 / static_cast<double>(discs.size())), 0.15);
}

TEST(BlobDetector, SplitsTwoDiscsFarOverEachOtherWithinALargerBlob) {
    // Two discs 0.3 and 0.35 diameters apart make one peak of the distance and one circle that
    // fits their outline poorly; with a third disc touching them the blob is not round, and the
    // poor circle is split in two across its longest spread. Every disc within 0.25 px.
    Image image(640, 480);
    std::vector<sim::Glint> discs;
    const double apart[] = {0.3, 0.35};
    for (int i = 0; i < 2; ++i) {
        const double x = 160.3 + 150.0 * i, y = 200.4 + 0.1 * i;
        discs.push_back(disc(x, y, 6.0));
        discs.push_back(disc(x + 12.0 * apart[i], y + 0.3, 6.0));
        discs.push_back(disc(x + 6.0 * apart[i] + 1.0, y + 10.5, 6.0)); // below, touching both
    }
    drawSpots(image, discs);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(blobs.size(), discs.size());
    double sum2 = 0.0;
    for (const sim::Glint& d : discs) {
        const double nearest = distanceToNearestBlob(blobs, d.centre_px);
        EXPECT_LT(nearest, 0.25) << "disc at " << d.centre_px.transpose();
        sum2 += nearest * nearest;
    }
    EXPECT_LT(std::sqrt(sum2 / static_cast<double>(discs.size())), 0.15);
}

TEST(BlobDetector, CentresADiscCutByAnEdgeFromItsVisibleArc) {
    // Markers partly hidden behind an edge in front of them: the straight edge of the object's
    // body (a fifth, a third and half of the disc hidden) and the round edge of a hand (a disc of
    // 40 px). The pixels of what is left pull the centre towards it by up to 2.5 px; the circle
    // through the visible arc puts it within 0.15 px of the true centre.
    Image image(640, 480);
    const std::vector<sim::Glint> discs = {disc(100.3, 100.6, 6.0), disc(250.7, 100.2, 6.0),
                                           disc(400.45, 100.9, 6.0), disc(300.2, 300.4, 6.0)};
    drawSpots(image, discs);
    // Hidden: x beyond the centre + 0.6, 0.33 and 0 radii; inside a hand of radius 40 px whose
    // edge passes 2.5 px from the last disc's centre.
    const double straightCuts_px[] = {0.6 * 6.0, 0.33 * 6.0, 0.0};
    for (std::size_t i = 0; i < 3; ++i)
        for (int y = 80; y < 120; ++y)
            for (int x = static_cast<int>(std::ceil(discs[i].centre_px.x() + straightCuts_px[i]));
                 x < static_cast<int>(discs[i].centre_px.x()) + 20; ++x)
                image.at(x, y) = 10;
    const Vec2 hand(300.2 + 42.5, 300.4);
    for (int y = 250; y < 350; ++y)
        for (int x = 280; x < 400; ++x)
            if ((Vec2(x, y) - hand).norm() < 40.0)
                image.at(x, y) = 10;
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    ASSERT_EQ(blobs.size(), discs.size());
    for (const sim::Glint& d : discs) {
        const Blob* nearest = nearestBlob(blobs, d.centre_px);
        ASSERT_NE(nearest, nullptr);
        EXPECT_LT((nearest->centre_px - d.centre_px).norm(), 0.15)
            << "disc at " << d.centre_px.transpose();
        EXPECT_TRUE(nearest->cut) << "disc at " << d.centre_px.transpose();
    }
    EXPECT_EQ(detector.counters().cutDiscs, discs.size());
}

// A line through \a centre_px along \a direction, given by a point \a before_px back along it.
PixelLine lineThrough(const Vec2& centre_px, const Vec2& direction, double before_px) {
    return {centre_px - before_px * direction.normalized(), direction.normalized()};
}

/// Split \a blob into the two \a discs and measure the parts against \a pair's true centres:
/// each within 0.25 px, a split part. \return the sum of their squared errors (px^2); infinity
/// when not both were placed.
double splitPairSquaredError(BlobDetector& detector, const Image& image, const Blob& blob,
                             std::span<const DiscOnLine> discs,
                             const std::vector<sim::Glint>& pair) {
    std::array<Blob, 2> parts{};
    std::array<bool, 2> placed{};
    if (detector.splitOnLines(image.pixels.data(), image.width, blob, discs, parts, placed) != 2) {
        ADD_FAILURE() << "pair at " << pair[0].centre_px.transpose() << " not split in two";
        return std::numeric_limits<double>::infinity();
    }
    double sum2 = 0.0;
    for (std::size_t k = 0; k < 2; ++k) {
        const double error = (parts[k].centre_px - pair[k].centre_px).norm();
        EXPECT_LT(error, 0.25) << "disc at " << pair[k].centre_px.transpose();
        EXPECT_TRUE(parts[k].split);
        sum2 += error * error;
    }
    return sum2;
}

TEST(BlobDetector, SplitsDiscsFarOverEachOtherOnTheirLines) {
    // Two discs 0.22 to 0.24 diameters apart make one round blob with hardly a neck: detection
    // alone keeps some as one blob between them. With a line for each centre (in a rig, the
    // epipolar lines of the discs' own blobs in the other camera) both are found within 0.15 px:
    // the one whose blob was paired starting from the blob's centre, the other searched along its
    // line.
    Image image(640, 480);
    const std::vector<sim::Glint> pairs[] = {{disc(100.3, 100.6, 6.0), disc(102.9, 101.5, 6.0)},
                                             {disc(300.45, 200.2, 5.0), disc(298.2, 201.0, 5.5)},
                                             {disc(450.2, 300.7, 8.0), disc(453.8, 299.6, 8.0)}};
    // The size of each disc is known from the other camera, where it is a blob of its own: here
    // a twin of each, alone, 60 px (first disc) or 100 px (second) below.
    const std::array<Vec2, 2> twinOffset{Vec2(0.0, 60.0), Vec2(0.0, 100.0)};
    std::vector<sim::Glint> all;
    for (const auto& pair : pairs)
        for (std::size_t k = 0; k < 2; ++k) {
            const Vec2 twin = pair[k].centre_px + twinOffset[k];
            all.push_back(pair[k]);
            all.push_back(disc(twin.x(), twin.y(), pair[k].radiusMajor_px));
        }
    drawSpots(image, all);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_LT(blobs.size(), 12u) << "detection alone keeps a pair or more as one blob";
    const auto radiusOfTwin = [&](const sim::Glint& d, std::size_t k) {
        const Blob* twin = nearestBlob(blobs, d.centre_px + twinOffset[k]);
        return twin->discRadius_px();
    };
    double sum2 = 0.0;
    for (const auto& pair : pairs) {
        const Blob* blob = nearestBlob(blobs, 0.5 * (pair[0].centre_px + pair[1].centre_px));
        ASSERT_NE(blob, nullptr);
        // Rows of a rectified rig are nearly along x; the lines slope a little, as epipolar
        // lines of a toed-in rig do.
        std::array<DiscOnLine, 2> discs{};
        discs[0].line = lineThrough(pair[0].centre_px, {1.0, 0.02}, 7.0);
        discs[0].start_px = blob->centre_px;
        discs[0].radius_px = radiusOfTwin(pair[0], 0);
        discs[1].line = lineThrough(pair[1].centre_px, {1.0, -0.03}, -5.0);
        discs[1].radius_px = radiusOfTwin(pair[1], 1);
        discs[1].known = false;
        sum2 += splitPairSquaredError(detector, image, *blob, discs, pair);
    }
    EXPECT_LT(std::sqrt(sum2 / 6.0), 0.15);
    EXPECT_EQ(detector.counters().splitOnLines, 3u);
}

TEST(BlobDetector, PlacesNoDiscWithoutAnArcOfItsOwn) {
    // A single disc has no second disc on a line through it, nor on a line that misses it: its
    // own circle explains its whole outline, and it is left as it is. Two touching discs have
    // none on a line through the top of their blob.
    Image image(640, 480);
    drawSpots(image, {disc(100.3, 100.6, 6.0), disc(300.2, 200.4, 6.0), disc(306.9, 201.1, 6.0)});
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    const Blob* single = nearestBlob(blobs, {100.3, 100.6});
    ASSERT_NE(single, nullptr);
    std::array<DiscOnLine, 2> discs{};
    discs[0].line = lineThrough({100.3, 100.6}, {1.0, 0.0}, 3.0);
    discs[0].start_px = single->centre_px;
    discs[0].radius_px = single->discRadius_px();
    discs[1].line = lineThrough({100.0, 103.5}, {1.0, 0.0}, 3.0);
    discs[1].radius_px = discs[0].radius_px;
    discs[1].known = false;
    std::array<Blob, 2> parts{};
    std::array<bool, 2> placed{};
    const auto split = [&](const Blob& blob) {
        return detector.splitOnLines(image.pixels.data(), image.width, blob, discs, parts, placed);
    };
    EXPECT_EQ(split(*single), 0u) << "one disc";
    EXPECT_FALSE(placed[0] || placed[1]);
    discs[1].line = lineThrough({100.0, 140.0}, {1.0, 0.0}, 3.0);
    EXPECT_EQ(split(*single), 0u) << "a line beside the blob";

    // The two touching discs at 300 are split by detection; a line for one of them and another
    // through the blob's top rows, where no disc lies.
    const Blob* left = nearestBlob(blobs, {300.2, 200.4});
    ASSERT_NE(left, nullptr);
    ASSERT_TRUE(left->split);
    discs[0].line = lineThrough({300.2, 200.4}, {1.0, 0.0}, 3.0);
    discs[0].start_px = left->centre_px;
    discs[1].line = lineThrough({303.0, 195.0}, {1.0, 0.0}, 3.0);
    split(*left);
    EXPECT_FALSE(placed[1]) << "a line through no disc";
}

TEST(BlobDetector, FindsDiscsFarOverEachOtherFromWhereTheyWereExpected) {
    // Two discs 0.15 to 0.3 diameters apart, as a marker hidden behind another or both in a
    // cluster are, with no line from the other camera to hold either: each is started a pixel
    // from its centre (where it was expected) with the size it had, and found within 0.15 px.
    // The blob's own centre lies between them.
    Image image(640, 480);
    const std::vector<sim::Glint> pairs[] = {{disc(100.3, 100.6, 8.0), disc(103.9, 101.5, 8.0)},
                                             {disc(300.45, 200.2, 8.5), disc(298.2, 203.9, 8.0)},
                                             {disc(450.2, 300.7, 9.0), disc(452.1, 299.6, 9.0)}};
    std::vector<sim::Glint> all;
    for (const auto& pair : pairs)
        all.insert(all.end(), pair.begin(), pair.end());
    // A twin of each pair's first disc alone, for the outline radius of such a disc.
    all.push_back(disc(100.0, 400.0, 8.0));
    drawSpots(image, all);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    const double outlineGrowth_px = nearestBlob(blobs, {100.0, 400.0})->discRadius_px() - 8.0;
    double sum2 = 0.0;
    for (const auto& pair : pairs) {
        const Blob* blob = nearestBlob(blobs, 0.5 * (pair[0].centre_px + pair[1].centre_px));
        ASSERT_NE(blob, nullptr);
        EXPECT_GT((blob->centre_px - pair[0].centre_px).norm(), 0.5)
            << "detection alone does not find the first disc";
        std::array<DiscOnLine, 2> discs{};
        for (std::size_t k = 0; k < 2; ++k) {
            discs[k].free = true;
            discs[k].start_px = pair[k].centre_px + Vec2(k == 0 ? 0.8 : -0.6, 0.6);
            discs[k].radius_px = pair[k].radiusMajor_px + outlineGrowth_px;
        }
        sum2 += splitPairSquaredError(detector, image, *blob, discs, pair);
    }
    EXPECT_LT(std::sqrt(sum2 / 6.0), 0.15);
}

TEST(BlobDetector, PlacesNoFreeDiscWhereNoneIsHidden) {
    // A single disc, with a second disc expected 3 px from its centre: the disc's own circle
    // explains the whole outline, and the second has no arc of its own. Nor does a lone free
    // disc started beside the blob move onto it.
    Image image(640, 480);
    drawSpots(image, {disc(100.3, 100.6, 8.0)});
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    ASSERT_EQ(blobs.size(), 1u);
    std::array<DiscOnLine, 2> discs{};
    discs[0].free = true;
    discs[0].start_px = blobs[0].centre_px;
    discs[0].radius_px = blobs[0].discRadius_px();
    discs[1] = discs[0];
    discs[1].start_px += Vec2(2.4, 1.8);
    std::array<Blob, 2> parts{};
    std::array<bool, 2> placed{};
    detector.splitOnLines(image.pixels.data(), image.width, blobs[0], discs, parts, placed);
    EXPECT_TRUE(placed[0]);
    EXPECT_FALSE(placed[1]) << "a disc expected where none is hidden";
    discs[0].start_px = blobs[0].centre_px + Vec2(6.0, 0.0);
    EXPECT_EQ(detector.splitOnLines(image.pixels.data(), image.width, blobs[0],
                                    std::span(discs.data(), 1), std::span(parts.data(), 1),
                                    std::span(placed.data(), 1)),
              0u)
        << "a free disc does not stray to the blob";
}

TEST(BlobDetector, OverflowIsCountedNotWritten) {
    Image image(640, 480);
    std::vector<sim::Glint> spots;
    for (int row = 0; row < 10; ++row)
        for (int col = 0; col < 20; ++col)
            spots.push_back(disc(15.0 + col * 30.0, 15.0 + row * 30.0, 3.0));
    drawSpots(image, spots);
    BlobDetectorConfig config;
    config.maxBlobs = 150;
    BlobDetector detector(config, image.width, image.height);
    BoundedVector<Blob> blobs(config.maxBlobs);
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(blobs.size(), 150u);
    EXPECT_EQ(detector.counters().blobOverflow, 50u);
}

TEST(BlobDetector, WithMoreBlobsThanRoomKeepsTheExpectedThenTheRoundest) {
    // 40 slightly oval discs at the top, 200 round ones below them and three discs where markers
    // are expected, low in the image, with room for 100 blobs: the first 100 from the top would
    // be the ovals and the first round rows.
    Image image(640, 480);
    std::vector<sim::Glint> spots;
    for (int row = 0; row < 2; ++row)
        for (int col = 0; col < 20; ++col) {
            sim::Glint oval = disc(15.0 + col * 30.0, 15.0 + row * 30.0, 3.6);
            oval.radiusMinor_px = 3.0;
            spots.push_back(oval);
        }
    for (int row = 0; row < 10; ++row)
        for (int col = 0; col < 20; ++col)
            spots.push_back(disc(15.0 + col * 30.0, 75.0 + row * 30.0, 3.0));
    const std::vector<Vec2> expected = {{100.0, 420.0}, {200.0, 440.0}, {300.0, 420.0}};
    for (const Vec2& e : expected)
        spots.push_back(disc(e.x() + 1.5, e.y() - 2.0, 3.0)); // moved a little since
    drawSpots(image, spots);
    BlobDetectorConfig config;
    config.maxBlobs = 100;
    BlobDetector detector(config, image.width, image.height);
    BoundedVector<Blob> blobs(config.maxBlobs);
    detector.detect(image.pixels.data(), image.width, blobs, expected);
    ASSERT_EQ(blobs.size(), 100u);
    EXPECT_EQ(detector.counters().blobOverflow, 143u);
    for (const Vec2& e : expected) {
        const bool kept = std::any_of(blobs.begin(), blobs.end(), [&](const Blob& b) {
            return (b.centre_px - e).norm() < 4.0;
        });
        EXPECT_TRUE(kept) << "the blob expected near " << e.transpose();
    }
    // The rest are the round discs, none of the ovals, in the order of their top rows.
    for (const Blob& b : blobs)
        EXPECT_LT(b.elongation, 1.1F) << b.centre_px.transpose();
    for (std::size_t i = 1; i < blobs.size(); ++i)
        EXPECT_LE(blobs[i - 1].top, blobs[i].top);

    // Without expectations, the expected ones are just round discs among the others.
    BlobDetector plain(config, image.width, image.height);
    plain.detect(image.pixels.data(), image.width, blobs);
    EXPECT_EQ(blobs.size(), 100u);
    EXPECT_EQ(plain.counters().blobOverflow, 143u);
}

TEST(BlobDetector, FloodOfSpecksExhaustsLabelsSafely) {
    Image image(512, 512);
    for (int y = 0; y < 512; y += 2)
        for (int x = 0; x < 512; x += 2)
            image.at(x, y) = 255; // 65536 isolated pixels
    BlobDetectorConfig config;
    config.maxLabels = 1000;
    BlobDetector detector(config, image.width, image.height);
    FixedVector<Blob, 16> blobs;
    detector.detect(image.pixels.data(), image.width, blobs);
    EXPECT_TRUE(blobs.empty());
    EXPECT_EQ(detector.counters().labelOverflow, 1u);
    EXPECT_EQ(detector.counters().rejectedSmall, 1000u);
}

TEST(BlobDetector, RejectsBadConfiguration) {
    BlobDetectorConfig config;
    config.maxArea_px = 1;
    EXPECT_FALSE(BlobDetector(config, 640, 480).isValid());
    EXPECT_FALSE(BlobDetector(BlobDetectorConfig{}, 0, 480).isValid());
}

TEST(BlobDetector, DetectingDoesNotAllocate) {
    Image image(1280, 800);
    std::vector<sim::Glint> spots;
    for (int i = 0; i < 60; ++i)
        spots.push_back(disc(30.0 + (i % 10) * 120.0, 40.0 + (i / 10) * 120.0, 4.0));
    drawSpots(image, spots);
    BlobDetector detector(BlobDetectorConfig{}, image.width, image.height);
    BoundedVector<Blob> blobs(256);
    const auto count = test::countAllocations([&] {
        for (int i = 0; i < 50; ++i)
            detector.detect(image.pixels.data(), image.width, blobs);
    });
    EXPECT_EQ(count, 0u);
    EXPECT_EQ(blobs.size(), 60u);
}
