// The marker front end: both cameras' blob detection and stereo correspondence, images to 3D
// points.
#include "core/marker_pipeline.hpp"

#include <optional>

namespace edgetrack {

MarkerPipeline::MarkerPipeline(const StereoRig& rig, const MarkerPipelineConfig& config)
    : config_(config)
    , width_px_(rig.camera(0).intrinsics().width_px)
    , height_px_(rig.camera(0).intrinsics().height_px)
    , detectors_{BlobDetector(config.blobs, width_px_, height_px_),
                 BlobDetector(config.blobs, width_px_, height_px_)}
    , blobs_{BoundedVector<Blob>(config.blobs.maxBlobs), BoundedVector<Blob>(config.blobs.maxBlobs)}
    , expected_px_{BoundedVector<Vec2>(config.blobs.maxBlobs),
                   BoundedVector<Vec2>(config.blobs.maxBlobs)}
    , stereo_(rig, config.stereo, config.blobs.maxBlobs)
    , markers_(config.stereo.maxMarkers)
    , points_rig_mm_(config.stereo.maxMarkers) {
    if (rig.camera(1).intrinsics().width_px != width_px_ ||
        rig.camera(1).intrinsics().height_px != height_px_)
        error_ = "the rig's two cameras must have the same image size";
    else if (!detectors_[0].isValid())
        error_ = "[blobs] settings are unusable for the rig's image size";
    else if (!stereo_.isValid())
        error_ = "[stereo] settings are unusable for the rig";
}

void MarkerPipeline::detectBlobs(int camera, const std::uint8_t* pixels, int stride_bytes) {
    detectors_[index(camera)].detect(pixels, stride_bytes, blobs_[index(camera)],
                                     expected_px_[index(camera)].span());
}

void MarkerPipeline::clearExpected() {
    for (BoundedVector<Vec2>& expected : expected_px_)
        expected.clear();
}

void MarkerPipeline::expect(const Vec3& marker_rig_mm) {
    for (std::size_t camera = 0; camera < 2; ++camera)
        if (const std::optional<Vec2> pixel =
                stereo_.rig().camera(static_cast<int>(camera)).project(marker_rig_mm))
            expected_px_[camera].push_back(*pixel);
}

void MarkerPipeline::matchStereo(StereoMethod method) {
    if (method == StereoMethod::EpipolarOnly)
        stereo_.matchEpipolarOnly(blobs_[0].span(), blobs_[1].span(), markers_);
    else
        stereo_.match(blobs_[0].span(), blobs_[1].span(), markers_);
    points_rig_mm_.clear();
    for (const StereoMarker& marker : markers_)
        points_rig_mm_.push_back(marker.position_rig_mm);
}

std::span<const Vec3> MarkerPipeline::process(const std::uint8_t* pixels0, int stride0_bytes,
                                              const std::uint8_t* pixels1, int stride1_bytes) {
    detectBlobs(0, pixels0, stride0_bytes);
    detectBlobs(1, pixels1, stride1_bytes);
    matchStereo();
    return points_rig_mm();
}

MarkerPipelineCounters MarkerPipeline::counters() const {
    MarkerPipelineCounters c;
    for (std::size_t camera = 0; camera < 2; ++camera) {
        c.rejectedNotRound += detectors_[camera].counters().rejectedNotRound;
        c.splitBlobs += detectors_[camera].counters().splitBlobs;
        c.splitRefused += detectors_[camera].counters().splitRefused;
        c.cutDiscs += detectors_[camera].counters().cutDiscs;
        c.labelOverflow += detectors_[camera].counters().labelOverflow;
        // The detector chooses which blobs fit and counts the rest; the blob vectors count blobs
        // given from outside (blobs level) that did not fit.
        c.blobOverflow +=
            detectors_[camera].counters().blobOverflow + blobs_[camera].overflowCount();
    }
    c.markerOverflow = stereo_.counters().markerOverflow;
    return c;
}

} // namespace edgetrack
