// Blob-level and point-level views of an observation, as a perfect detector would report them.
#include "hal/sim/levels.hpp"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <Eigen/SVD>

namespace edgetrack::sim {

namespace {

struct Spot {
    Vec2 centre_px;
    double radius_px;
    int group;
    /// Index into markers followed by spuriousPoints; -1 for a round glint, -2 for a streak.
    int source;
    /// How far from the centre the spot stays above the detection level (px).
    double reach_px;
};

// Distance from a spot's centre at which its blurred edge falls to the detection level, from the
// renderer's profile peak * erfc((rho - R) / (sqrt(2) sigma)) / 2.
double reachAtDetectionLevel(double radius_px, double peak_dn,
                             double blur_px = FrameRenderer::kEdgeBlur_px) {
    const double target = 2.0 * kDetectionLevel_dn / peak_dn;
    if (target >= 2.0)
        return 0.0;                // never reaches the level: no blob at all
    double low = -6.0, high = 6.0; // erfc is decreasing: bisect for erfc(z) = target
    for (int i = 0; i < 50; ++i) {
        const double mid = 0.5 * (low + high);
        (std::erfc(mid) > target ? low : high) = mid;
    }
    return std::max(0.0, radius_px + std::numbers::sqrt2 * blur_px * low);
}

// Spots whose discs touch (with the edge blur) form one blob; returns spots with group labels.
void groupSpots(const Observation& observation, int camera, std::vector<Spot>& spots) {
    const auto c = static_cast<std::size_t>(camera);
    spots.clear();
    int source = 0;
    // An elliptic image reaches as far as its longer semi-axis (toward its neighbour or not).
    const auto addView = [&](const MarkerView& m) {
        if (m.visible[c]) {
            const double major_px =
                Eigen::JacobiSVD<Eigen::Matrix2d>(m.shape_px[c]).singularValues()(0);
            spots.push_back({m.pixel[c], m.radius_px[c], -1, source,
                             reachAtDetectionLevel(major_px, m.peak_dn[c], m.blur_px[c])});
        }
        ++source;
    };
    for (const MarkerView& m : observation.markers)
        addView(m);
    for (const MarkerView& m : observation.spuriousPoints)
        addView(m);
    // Every glint takes part in merging (a streak across a marker spoils it too), but only round
    // ones are reported as blobs.
    for (const Glint& g : observation.glints[c]) {
        const double radius = g.isRound() ? g.radiusMinor_px : g.radiusMajor_px;
        spots.push_back({g.centre_px, radius, -1, g.isRound() ? -1 : -2,
                         reachAtDetectionLevel(radius, g.peak_dn)});
    }
    // Spots too faint to reach the detection level make no blob.
    std::erase_if(spots, [](const Spot& s) { return s.reach_px <= 0.0; });

    for (std::size_t i = 0; i < spots.size(); ++i) {
        if (spots[i].group < 0)
            spots[i].group = static_cast<int>(i);
        for (std::size_t j = i + 1; j < spots.size(); ++j) {
            // Pixels of 8-connected blobs touch up to one pixel diagonal beyond their reaches.
            const double reach = spots[i].reach_px + spots[j].reach_px + std::numbers::sqrt2;
            if ((spots[i].centre_px - spots[j].centre_px).norm() >= reach)
                continue;
            // Union: relabel j's whole group to i's.
            const int from = spots[j].group, to = spots[i].group;
            if (from < 0) {
                spots[j].group = to;
            } else if (from != to) {
                for (Spot& s : spots)
                    if (s.group == from)
                        s.group = to;
            }
        }
    }
}

} // namespace

void blobsFromObservation(const Observation& observation, int camera, const LevelNoise& noise,
                          Random& random, std::vector<SimBlob>& out) {
    thread_local std::vector<Spot> spots;
    groupSpots(observation, camera, spots);
    out.clear();
    for (std::size_t g = 0; g < spots.size(); ++g) {
        if (spots[g].group != static_cast<int>(g))
            continue;
        bool rejected = false;
        for (const Spot& s : spots)
            rejected = rejected || (s.group == static_cast<int>(g) && s.source == -2);
        if (rejected)
            continue; // not round: the detector drops it
        Vec2 weighted = Vec2::Zero();
        double area = 0.0;
        for (const Spot& s : spots)
            if (s.group == static_cast<int>(g)) {
                const double a = std::numbers::pi * s.radius_px * s.radius_px;
                weighted += a * s.centre_px;
                area += a;
            }
        SimBlob blob;
        const double noiseY = random.normal(noise.blobCentreSigma_px);
        const double noiseX = random.normal(noise.blobCentreSigma_px);
        blob.centre_px = weighted / area + Vec2(noiseX, noiseY);
        blob.area_px = area;
        out.push_back(blob);
    }
}

void separatelyVisible(const Observation& observation, std::vector<int>& out) {
    thread_local std::array<std::vector<Spot>, 2> spots;
    thread_local std::array<std::vector<int>, 2> groupSize;
    thread_local std::array<std::vector<int>, 2> groupOfSource;
    const std::size_t sources = observation.markers.size() + observation.spuriousPoints.size();
    for (int camera = 0; camera < 2; ++camera) {
        const auto c = static_cast<std::size_t>(camera);
        groupSpots(observation, camera, spots[c]);
        groupSize[c].assign(spots[c].size(), 0);
        groupOfSource[c].assign(sources, -1);
        for (const Spot& s : spots[c]) {
            ++groupSize[c][static_cast<std::size_t>(s.group)];
            if (s.source >= 0)
                groupOfSource[c][static_cast<std::size_t>(s.source)] = s.group;
        }
    }
    out.clear();
    for (std::size_t i = 0; i < sources; ++i) {
        bool alone = true;
        for (std::size_t c = 0; c < 2; ++c) {
            const int group = groupOfSource[c][i];
            alone = alone && group >= 0 && groupSize[c][static_cast<std::size_t>(group)] == 1;
        }
        if (alone)
            out.push_back(static_cast<int>(i));
    }
}

void pointsFromObservation(const Observation& observation, const LevelNoise& noise, Random& random,
                           std::vector<Vec3>& out) {
    thread_local std::vector<int> visible;
    separatelyVisible(observation, visible);
    out.clear();
    const std::size_t markerCount = observation.markers.size();
    for (const int source : visible) {
        const auto s = static_cast<std::size_t>(source);
        const Vec3& p = s < markerCount
                            ? observation.markers[s].position_rig_mm
                            : observation.spuriousPoints[s - markerCount].position_rig_mm;
        const double noiseZ = random.normal(noise.pointSigma_mm);
        const double noiseY = random.normal(noise.pointSigma_mm);
        const double noiseX = random.normal(noise.pointSigma_mm);
        out.push_back(p + Vec3(noiseX, noiseY, noiseZ));
    }
    // INTERFACES §1: points come in any order; shuffling keeps consumers honest.
    for (std::size_t i = out.size(); i > 1; --i)
        std::swap(out[i - 1], out[random.below(i)]);
}

} // namespace edgetrack::sim
