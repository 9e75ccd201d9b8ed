// Object calibration on a real Vicon recording: a rigid box among a person's skin markers.
#include <filesystem>
#include <optional>
#include <vector>

#include <gtest/gtest.h>

#include "core/object_calibrator.hpp"
#include "core/rigid_fit.hpp"
#include "firmware_app/recording/c3d.hpp"
#include "tests/support/model_alignment.hpp"

namespace edgetrack {
namespace {

const std::filesystem::path kVicon =
    std::filesystem::path(EDGETRACK_REALDATA_DIR) / "ezc3d-testFiles" / "Vicon.c3d";

// The box's labelled layout: every frame with all eight markers fitted onto the first such frame,
// and averaged (mm, in that frame's coordinates).
std::vector<Vec3> labelledBox(const recording::C3dPoints& c3d,
                              const std::vector<std::size_t>& box) {
    std::vector<Vec3> reference, sum(box.size(), Vec3::Zero());
    int frames = 0;
    for (std::size_t f = 0; f < c3d.frameCount; ++f) {
        std::vector<Vec3> now;
        for (std::size_t p : box)
            if (c3d.isValid(f, p))
                now.push_back(c3d.position(f, p));
        if (now.size() != box.size())
            continue;
        if (reference.empty())
            reference = now;
        const std::optional<RigidFit> fit = fitRigid(now, reference);
        if (!fit)
            continue;
        for (std::size_t i = 0; i < now.size(); ++i)
            sum[i] += fit->transform.apply(now[i]);
        ++frames;
    }
    for (Vec3& p : sum)
        p /= static_cast<double>(frames);
    return sum;
}

TEST(CalibrationRealData, ViconBoxIsOneObjectOfItsEightMarkers) {
    if (!std::filesystem::exists(kVicon))
        GTEST_SKIP() << kVicon << " is absent (the shared real-data folder is not here)";
    const Result<recording::C3dPoints> c3d = recording::readC3d(kVicon);
    ASSERT_TRUE(c3d) << c3d.error().message;
    std::vector<std::size_t> box;
    for (std::size_t p = 0; p < c3d->pointCount; ++p)
        if (c3d->labels[p].rfind("boite:", 0) == 0)
            box.push_back(p);
    ASSERT_EQ(box.size(), 8u);
    const std::vector<Vec3> layout = labelledBox(*c3d, box);

    CalibrationConfig config;
    ObjectCalibrator calibrator(config);
    std::vector<Vec3> points;
    for (std::size_t f = 0; f < c3d->frameCount; ++f) {
        points.clear();
        for (std::size_t p = 0; p < c3d->pointCount; ++p)
            if (c3d->isValid(f, p))
                points.push_back(c3d->position(f, p));
        calibrator.update(static_cast<double>(f) / c3d->frameRate_hz, points);
    }
    std::vector<MarkerModel> models;
    for (std::size_t i = 0; i < config.maxObjects; ++i)
        models.emplace_back(config.maxMarkersPerObject);
    const std::size_t count = calibrator.exportModels(models);

    // Exactly one model holds box markers; it holds all eight and nothing else, within 1 mm.
    int boxModels = 0;
    for (std::size_t i = 0; i < count; ++i) {
        const test::ModelAlignment a = test::alignModel(models[i], layout, 1.0);
        if (a.matched < 3)
            continue;
        ++boxModels;
        EXPECT_EQ(a.matched, 8u);
        EXPECT_EQ(models[i].markers_model_mm.size(), 8u) << "skin markers merged into the box";
        EXPECT_LT(a.rms_mm, 1.0);
        for (std::size_t m = 0; m < models[i].markers_model_mm.size(); ++m)
            if (a.layoutMarkerOf[m] >= 0) {
                EXPECT_LT((a.layoutFromModel.apply(models[i].markers_model_mm[m]) -
                           layout[static_cast<std::size_t>(a.layoutMarkerOf[m])])
                              .norm(),
                          1.0);
            }
        RecordProperty("box_rms_mm", std::to_string(a.rms_mm));
    }
    EXPECT_EQ(boxModels, 1);
}

} // namespace
} // namespace edgetrack
