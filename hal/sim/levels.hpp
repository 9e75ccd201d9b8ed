// Blob-level and point-level views of an observation, as a perfect detector would report them.
#pragma once

#include <array>
#include <vector>

#include "hal/sim/random.hpp"
#include "hal/sim/world.hpp"

namespace edgetrack::sim {

/// \brief A blob centre in raw pixels of one camera, with its area.
struct SimBlob {
    Vec2 centre_px = Vec2::Zero();
    double area_px = 0.0;
};

/// \brief Level (DN) at which the blob and point levels consider a spot detected; it matches the
/// default threshold of core's BlobDetector, so "merged" means what the detector will see merged.
inline constexpr double kDetectionLevel_dn = 60.0;

/// \brief Noise of the blob and point levels.
struct LevelNoise {
    double blobCentreSigma_px = 0.05;
    double pointSigma_mm = 0.05;
};

/**
 * \brief The blobs camera \a camera would detect: visible markers, lit spurious points and round
 * glints. Spots that overlap in the image merge into one blob at their area-weighted centre, as
 * they do in a real image; elongated glints are left out, as the detector rejects them.
 */
void blobsFromObservation(const Observation& observation, int camera, const LevelNoise& noise,
                          Random& random, std::vector<SimBlob>& out);

/**
 * \brief Indices (markers first, then spuriousPoints after them) of the points that both cameras
 * see as blobs of their own, merged with no other spot in either image: what stereo can find.
 */
void separatelyVisible(const Observation& observation, std::vector<int>& out);

/**
 * \brief The 3D points a perfect stereo stage would reconstruct: markers and spurious points seen
 * by both cameras and merged with nothing in either image, with noise, in shuffled order.
 */
void pointsFromObservation(const Observation& observation, const LevelNoise& noise, Random& random,
                           std::vector<Vec3>& out);

} // namespace edgetrack::sim
