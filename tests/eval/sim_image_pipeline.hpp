// Simulated images through the firmware's MarkerPipeline, for evaluations.
#pragma once

#include <cstdint>
#include <vector>

#include "core/marker_pipeline.hpp"
#include "hal/sim/levels.hpp"
#include "hal/sim/world.hpp"

namespace edgetrack::test {

/**
 * \brief Renders both cameras' images of an observation and runs them through the firmware's
 * MarkerPipeline with the given settings (default: edgetrack.toml's).
 */
class SimImagePipeline {
public:
    SimImagePipeline(const sim::World& world, std::uint64_t seed,
                     const MarkerPipelineConfig& config = {})
        : rig_(world.scene().rig)
        , renderer_(rig_.width_px, rig_.height_px, world.scene().background_dn,
                    world.scene().noiseSigma_dn, seed)
        , pipeline_(world.rig(), config)
        , images_{std::vector<std::uint8_t>(pixels()), std::vector<std::uint8_t>(pixels())} {}

    /// \brief Frame \a frame of \a observation into \a points (rig frame, mm).
    void run(const sim::Observation& observation, std::uint64_t frame, StereoMethod method,
             std::vector<Vec3>& points) {
        for (int c = 0; c < 2; ++c) {
            const auto camera = static_cast<std::size_t>(c);
            renderer_.render(images_[camera], rig_.width_px, c, observation, 1.0, frame);
            pipeline_.detectBlobs(c, images_[camera].data(), rig_.width_px);
        }
        pipeline_.matchStereo(
            method, {{{images_[0].data(), rig_.width_px}, {images_[1].data(), rig_.width_px}}});
        points.assign(pipeline_.points_rig_mm().begin(), pipeline_.points_rig_mm().end());
    }

    const MarkerPipeline& pipeline() const { return pipeline_; }

private:
    std::size_t pixels() const { return static_cast<std::size_t>(rig_.width_px * rig_.height_px); }

    sim::RigSpec rig_;
    sim::FrameRenderer renderer_;
    MarkerPipeline pipeline_;
    std::vector<std::uint8_t> images_[2];
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
        , pipeline_(world, seed)
        , random_(seed ^ 0x5eedU) {
        noise_.pointSigma_mm = world.scene().pointNoise_mm;
    }

    /// \brief Observe frame \a frame into \a observation and its points (rig frame, mm).
    void next(std::uint64_t frame, sim::Observation& observation, std::vector<Vec3>& points) {
        world_.observe(frame, observation);
        if (images_)
            pipeline_.run(observation, frame, StereoMethod::Svd, points);
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
