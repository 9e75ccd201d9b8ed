// The marker-tracking front end on simulated images, as the firmware runs it, for evaluations.
#pragma once

#include <cstdint>
#include <vector>

#include "core/blob_detector.hpp"
#include "core/stereo_matcher.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"

namespace edgetrack::test {

/**
 * \brief Renders both cameras' images of an observation, detects blobs and matches them in
 * stereo, with the default blob configuration and the given stereo configuration.
 */
class SimImagePipeline {
public:
    SimImagePipeline(const sim::World& world, std::uint64_t seed, const StereoConfig& stereoConfig)
        : rig_(world.scene().rig)
        , renderer_(rig_.width_px, rig_.height_px, world.scene().background_dn,
                    world.scene().noiseSigma_dn, seed)
        , detectors_{BlobDetector(blobConfig_, rig_.width_px, rig_.height_px),
                     BlobDetector(blobConfig_, rig_.width_px, rig_.height_px)}
        , stereo_(world.rig(), stereoConfig, blobConfig_.maxBlobs)
        , images_{std::vector<std::uint8_t>(pixels()), std::vector<std::uint8_t>(pixels())}
        , blobs_{BoundedVector<Blob>(blobConfig_.maxBlobs),
                 BoundedVector<Blob>(blobConfig_.maxBlobs)}
        , markers_(stereoConfig.maxMarkers) {}

    /// \brief Frame \a frame of \a observation into \a points (rig frame, mm): the SVD matcher, or
    /// the epipolar-only baseline.
    void run(const sim::Observation& observation, std::uint64_t frame, bool epipolarOnly,
             std::vector<Vec3>& points) {
        for (int c = 0; c < 2; ++c) {
            const auto camera = static_cast<std::size_t>(c);
            renderer_.render(images_[camera], rig_.width_px, c, observation, 1.0, frame);
            detectors_[camera].detect(images_[camera].data(), rig_.width_px, blobs_[camera]);
        }
        if (epipolarOnly)
            stereo_.matchEpipolarOnly(blobs_[0].span(), blobs_[1].span(), markers_);
        else
            stereo_.match(blobs_[0].span(), blobs_[1].span(), markers_);
        points.clear();
        for (const StereoMarker& m : markers_)
            points.push_back(m.position_rig_mm);
    }

    const BoundedVector<Blob>& blobs(int camera) const {
        return blobs_[static_cast<std::size_t>(camera)];
    }
    const BlobDetector& detector(int camera) const {
        return detectors_[static_cast<std::size_t>(camera)];
    }
    const StereoMatcher& stereo() const { return stereo_; }

private:
    std::size_t pixels() const { return static_cast<std::size_t>(rig_.width_px * rig_.height_px); }

    sim::RigSpec rig_;
    BlobDetectorConfig blobConfig_{};
    sim::FrameRenderer renderer_;
    BlobDetector detectors_[2];
    StereoMatcher stereo_;
    std::vector<std::uint8_t> images_[2];
    BoundedVector<Blob> blobs_[2];
    BoundedVector<StereoMarker> markers_;
};

/**
 * \brief Each frame of a simulated world as the pipeline's 3D points: at images level through
 * SimImagePipeline (SVD stereo), at points level the simulator's points with their noise.
 */
class SimFrames {
public:
    SimFrames(const sim::World& world, std::uint64_t seed, bool images)
        : world_(world)
        , images_(images)
        , pipeline_(world, seed, StereoConfig{})
        , random_(seed ^ 0x5eedU) {
        noise_.pointSigma_mm = world.scene().pointNoise_mm;
    }

    /// \brief Observe frame \a frame into \a observation and its points (rig frame, mm).
    void next(std::uint64_t frame, sim::Observation& observation, std::vector<Vec3>& points) {
        world_.observe(frame, observation);
        if (images_)
            pipeline_.run(observation, frame, false, points);
        else
            sim::pointsFromObservation(observation, noise_, random_, points);
    }

private:
    const sim::World& world_;
    bool images_;
    SimImagePipeline pipeline_;
    sim::Random random_;
    sim::LevelNoise noise_;
};

} // namespace edgetrack::test
