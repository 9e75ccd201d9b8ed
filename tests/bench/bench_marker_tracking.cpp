// Benchmarks of marker tracking on one core: blob detection of a 1280x800 frame pair beside the
// memory floor and OpenCV, stereo plus frame-to-frame correspondence for about 60 markers, and
// the front end on touching markers.
#include <array>
#include <cstdint>
#include <vector>

#include <benchmark/benchmark.h>

#include "core/blob_detector.hpp"
#include "core/marker_pipeline.hpp"
#include "core/marker_tracker.hpp"
#include "core/simd/neon.hpp"
#include "core/stereo_matcher.hpp"
#include "hal/sim/world.hpp"

#if EDGETRACK_HAVE_OPENCV
#include <opencv2/imgproc.hpp>
#endif

namespace {

using namespace edgetrack;

// One frame pair of a simulated scene, rendered once.
struct FramePair {
    sim::World world;
    std::vector<std::uint8_t> image[2];
    sim::Observation observation;

    FramePair(const char* scene, std::uint64_t frame)
        : world(*sim::makeScene(scene, 1), 1) {
        const sim::RigSpec& rig = world.scene().rig;
        const sim::FrameRenderer renderer(rig.width_px, rig.height_px, world.scene().background_dn,
                                          world.scene().noiseSigma_dn, 1);
        world.observe(frame, observation);
        for (int c = 0; c < 2; ++c) {
            image[c].resize(static_cast<std::size_t>(rig.width_px * rig.height_px));
            renderer.render(image[c], rig.width_px, c, observation, 1.0, frame);
        }
    }
    int width() const { return world.scene().rig.width_px; }
    int height() const { return world.scene().rig.height_px; }
    std::int64_t bytes() const { return static_cast<std::int64_t>(2 * image[0].size()); }
};

const FramePair& twoCubes() {
    static const FramePair pair("two_cubes", 120);
    return pair;
}

// The frames as the detector meets them. Hot: one pair, read again and again, so it stays in this
// machine's 32 MB L3. Cold: the pair copied 32 times (64 MB) and the copies taken in turn, so each
// comes from DRAM, as a frame does on the board, where the cameras write it by DMA just before.
struct FrameSource {
    static constexpr std::size_t kColdCopies = 32;
    std::vector<std::vector<std::uint8_t>> copies;

    FrameSource(const FramePair& pair, bool cold) {
        const std::size_t count = cold ? kColdCopies : 1;
        for (std::size_t k = 0; k < count; ++k)
            for (int c = 0; c < 2; ++c)
                copies.push_back(pair.image[c]);
    }
    const std::uint8_t* image(std::size_t iteration, int camera) const {
        return copies[2 * (iteration % (copies.size() / 2)) + static_cast<std::size_t>(camera)]
            .data();
    }
};

void BM_BlobDetectionPair(benchmark::State& state) {
    const FramePair& pair = twoCubes();
    const FrameSource source(pair, state.range(0) != 0);
    BlobDetector detector(BlobDetectorConfig{}, pair.width(), pair.height());
    BoundedVector<Blob> blobs(256);
    std::size_t iteration = 0;
    for (auto _ : state) {
        for (int c = 0; c < 2; ++c) {
            detector.detect(source.image(iteration, c), pair.width(), blobs);
            benchmark::DoNotOptimize(blobs.data());
        }
        ++iteration;
    }
    state.SetBytesProcessed(state.iterations() * pair.bytes());
    state.counters["blobs"] = static_cast<double>(blobs.size());
    state.SetLabel(simd::neonBackendName());
}
BENCHMARK(BM_BlobDetectionPair)->ArgName("cold")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

// The memory floor: every byte loaded once and reduced with the cheapest NEON operation.
void BM_PlainReadPair(benchmark::State& state) {
    const FramePair& pair = twoCubes();
    const FrameSource source(pair, state.range(0) != 0);
    const std::size_t size = pair.image[0].size();
    std::size_t iteration = 0;
    for (auto _ : state) {
        for (int c = 0; c < 2; ++c) {
            const std::uint8_t* p = source.image(iteration, c);
            uint8x16_t m0 = vdupq_n_u8(0), m1 = m0, m2 = m0, m3 = m0;
            for (std::size_t i = 0; i + 64 <= size; i += 64) {
                m0 = vmaxq_u8(m0, vld1q_u8(p + i));
                m1 = vmaxq_u8(m1, vld1q_u8(p + i + 16));
                m2 = vmaxq_u8(m2, vld1q_u8(p + i + 32));
                m3 = vmaxq_u8(m3, vld1q_u8(p + i + 48));
            }
            benchmark::DoNotOptimize(vmaxvq_u8(vmaxq_u8(vmaxq_u8(m0, m1), vmaxq_u8(m2, m3))));
        }
        ++iteration;
    }
    state.SetBytesProcessed(state.iterations() * pair.bytes());
}
BENCHMARK(BM_PlainReadPair)->ArgName("cold")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

#if EDGETRACK_HAVE_OPENCV
// The usual way: threshold, then connected components with statistics.
void BM_OpenCvPair(benchmark::State& state) {
    const FramePair& pair = twoCubes();
    cv::setNumThreads(0); // one core, like ours
    cv::Mat binary, labels, stats, centroids;
    for (auto _ : state) {
        for (int c = 0; c < 2; ++c) {
            const cv::Mat image(pair.height(), pair.width(), CV_8UC1,
                                const_cast<std::uint8_t*>(pair.image[c].data()));
            cv::threshold(image, binary, 59, 255, cv::THRESH_BINARY);
            const int n =
                cv::connectedComponentsWithStats(binary, labels, stats, centroids, 8, CV_32S);
            benchmark::DoNotOptimize(n);
        }
    }
    state.SetBytesProcessed(state.iterations() * pair.bytes());
}
BENCHMARK(BM_OpenCvPair)->Unit(benchmark::kMicrosecond);
#endif

// A run of consecutive frame pairs of a simulated scene, rendered once: images 2f and 2f + 1
// are frame f's two cameras.
struct FrameRun {
    sim::World world;
    std::vector<std::vector<std::uint8_t>> images;

    FrameRun(const char* sceneName, std::uint64_t firstFrame, std::size_t frames)
        : world(*sim::makeScene(sceneName, 1), 1) {
        const sim::RigSpec& rig = world.scene().rig;
        const sim::FrameRenderer renderer(rig.width_px, rig.height_px, world.scene().background_dn,
                                          world.scene().noiseSigma_dn, 1);
        sim::Observation observation;
        for (std::size_t f = 0; f < frames; ++f) {
            world.observe(firstFrame + f, observation);
            for (int c = 0; c < 2; ++c) {
                images.emplace_back(static_cast<std::size_t>(rig.width_px * rig.height_px));
                renderer.render(images.back(), rig.width_px, c, observation, 1.0, firstFrame + f);
            }
        }
    }
    int width_px() const { return world.scene().rig.width_px; }
};

// Stereo and frame-to-frame correspondence of the crowd scene (six objects, 60-70 markers) over
// consecutive frames, so that the frame-to-frame prediction sees the motion it is made for; the
// sequence repeats with the tracker reset, as after a pause.
void BM_StereoAndFrameToFrame(benchmark::State& state) {
    constexpr std::uint64_t kFirstFrame = 650;
    constexpr std::size_t kFrames = 32;
    const FrameRun run("crowd", kFirstFrame, kFrames);
    const sim::World& world = run.world;
    const sim::RigSpec& rig = world.scene().rig;
    BlobDetector detector(BlobDetectorConfig{}, rig.width_px, rig.height_px);
    std::vector<BoundedVector<Blob>> blobs;
    for (const std::vector<std::uint8_t>& image : run.images) {
        blobs.emplace_back(256);
        detector.detect(image.data(), rig.width_px, blobs.back());
    }
    StereoMatcher stereo(world.rig(), StereoConfig{}, 256);
    MarkerTracker tracker{FrameToFrameConfig{}};
    BoundedVector<StereoMarker> markers(256);
    BoundedVector<Vec3> points(256);
    std::size_t frame = 0, markerCount = 0;
    for (auto _ : state) {
        const std::size_t f = frame % kFrames;
        if (f == 0)
            tracker.reset();
        stereo.match(blobs[2 * f].span(), blobs[2 * f + 1].span(), markers);
        points.clear();
        for (const StereoMarker& m : markers)
            points.push_back(m.position_rig_mm);
        benchmark::DoNotOptimize(
            tracker.update(world.frameTime_s(kFirstFrame + f), points.span()).data());
        markerCount += markers.size();
        ++frame;
    }
    state.counters["markers"] =
        static_cast<double>(markerCount) / static_cast<double>(std::max<std::size_t>(frame, 1));
}
BENCHMARK(BM_StereoAndFrameToFrame)->Unit(benchmark::kMicrosecond);

/// Runs \a pipeline's whole front end (both images' blobs, stereo) over \a run's frames in turn,
/// giving stereo the images when \a lines (the split on epipolar lines goes back to them).
void runFrontEnd(benchmark::State& state, const FrameRun& run, MarkerPipeline& pipeline,
                 bool lines) {
    const std::size_t frames = run.images.size() / 2;
    const int width_px = run.width_px();
    std::size_t frame = 0, markerCount = 0;
    for (auto _ : state) {
        const std::size_t f = frame % frames;
        const std::array<ImageView, 2> views{
            {{run.images[2 * f].data(), width_px}, {run.images[2 * f + 1].data(), width_px}}};
        for (int c = 0; c < 2; ++c)
            pipeline.detectBlobs(c, views[static_cast<std::size_t>(c)].pixels, width_px);
        pipeline.matchStereo(StereoMethod::Svd, lines ? views : std::array<ImageView, 2>{});
        benchmark::DoNotOptimize(pipeline.points_rig_mm().data());
        markerCount += pipeline.markers().size();
        ++frame;
    }
    state.counters["markers"] =
        static_cast<double>(markerCount) / static_cast<double>(std::max<std::size_t>(frame, 1));
}

// The whole front end on the touching scene, where a third of the markers touch another in one
// image, over 32 consecutive frames. With "lines" set, stereo goes back to the images and splits
// blobs on the other camera's epipolar lines; with "carry" set, markers hidden in one image are
// carried on (StereoConfig::maxCarriedFrames); with "seek" set, markers of the frame before are
// sought where they are expected (StereoConfig::seekExpectedMarkers): the differences are what
// those steps cost.
void BM_FrontEndTouching(benchmark::State& state) {
    const FrameRun run("touching", 300, 32);
    MarkerPipelineConfig config;
    config.stereo.maxCarriedFrames = state.range(1) != 0 ? StereoConfig{}.maxCarriedFrames : 0;
    config.stereo.seekExpectedMarkers = state.range(2) != 0;
    MarkerPipeline pipeline(run.world.rig(), config);
    runFrontEnd(state, run, pipeline, state.range(0) != 0);
}
BENCHMARK(BM_FrontEndTouching)
    ->ArgNames({"lines", "carry", "seek"})
    ->Args({0, 0, 0})
    ->Args({1, 0, 0})
    ->Args({1, 1, 0})
    ->Args({1, 1, 1})
    ->Unit(benchmark::kMicrosecond);

// The whole front end on the crowd (60-70 markers a frame), with and without the step that keeps
// pairs whose points continue the last frame's (StereoConfig::continuity_mm): the difference is
// what that step costs where it has the most points to compare.
void BM_FrontEndCrowd(benchmark::State& state) {
    const FrameRun run("crowd", 650, 32);
    MarkerPipelineConfig config;
    config.stereo.continuity_mm = state.range(0) != 0 ? StereoConfig{}.continuity_mm : 0.0;
    MarkerPipeline pipeline(run.world.rig(), config);
    runFrontEnd(state, run, pipeline, true);
}
BENCHMARK(BM_FrontEndCrowd)->ArgName("continuity")->Arg(0)->Arg(1)->Unit(benchmark::kMicrosecond);

} // namespace

BENCHMARK_MAIN();
