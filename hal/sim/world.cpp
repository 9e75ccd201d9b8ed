// What the simulated cameras see: marker visibility, occlusion, spurious reflections, images.
#include "hal/sim/world.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <numbers>

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>

#include "hal/sim/random.hpp"

namespace edgetrack::sim {

namespace {

// Brightness of a marker squarely facing the ring at the rig's convergence distance (DN).
constexpr double kPeakAtReference_dn = 1100.0;
constexpr double kReferenceDistance_mm = 550.0;
constexpr double kSpuriousPointDiameter_mm = 3.0;
constexpr double kSpuriousPointLitProbability = 0.8;

std::uint64_t mix(std::uint64_t a, std::uint64_t b) {
    std::uint64_t z = a * 0x9E3779B97F4A7C15ull ^ (b + 0x632BE59BD9B4E019ull);
    z = (z ^ (z >> 31)) * 0xBF58476D1CE4E5B9ull;
    return z ^ (z >> 29);
}

// Does the segment from a to b pass through the axis-aligned box (centre, half extent)?
bool segmentHitsBox(const Vec3& a, const Vec3& b, const Vec3& centre, const Vec3& half) {
    double enter = 0.0, leave = 1.0;
    const Vec3 d = b - a;
    for (int axis = 0; axis < 3; ++axis) {
        const double low = centre[axis] - half[axis] - a[axis];
        const double high = centre[axis] + half[axis] - a[axis];
        if (std::abs(d[axis]) < 1e-12) {
            if (low > 0.0 || high < 0.0)
                return false;
            continue;
        }
        double t0 = low / d[axis], t1 = high / d[axis];
        if (t0 > t1)
            std::swap(t0, t1);
        enter = std::max(enter, t0);
        leave = std::min(leave, t1);
        if (enter > leave)
            return false;
    }
    return true;
}

bool segmentHitsSphere(const Vec3& a, const Vec3& b, const Vec3& centre, double radius) {
    const Vec3 d = b - a;
    const double t = std::clamp((centre - a).dot(d) / d.squaredNorm(), 0.0, 1.0);
    return (a + t * d - centre).squaredNorm() < radius * radius;
}

} // namespace

World::World(Scene scene, std::uint64_t seed)
    : scene_(std::move(scene))
    , rig_(makeRig(scene_.rig))
    , T_rig_from_scene_(rigFromScene(scene_.rig))
    , seed_(seed) {
    Random random(mix(seed, 0x5EED));
    const double w = scene_.rig.width_px, h = scene_.rig.height_px;
    for (int camera = 0; camera < 2; ++camera) {
        for (int i = 0; i < scene_.spurious.staticPerCamera; ++i) {
            Glint g;
            g.centre_px = {random.uniform(10.0, w - 10.0), random.uniform(10.0, h - 10.0)};
            if (i % 3 == 2) { // a streak: a lit edge of a table or a cable
                g.radiusMajor_px = random.uniform(6.0, 15.0);
                g.radiusMinor_px = random.uniform(1.2, 2.0);
                g.angle_rad = random.uniform(0.0, std::numbers::pi);
            } else {
                g.radiusMajor_px = g.radiusMinor_px = random.uniform(1.5, 4.0);
            }
            g.peak_dn = random.uniform(300.0, 800.0);
            staticGlints_[static_cast<std::size_t>(camera)].push_back(g);
        }
        for (int i = 0; i < scene_.spurious.flickeringPerCamera; ++i) {
            Glint g;
            g.centre_px = {random.uniform(10.0, w - 10.0), random.uniform(10.0, h - 10.0)};
            g.radiusMajor_px = g.radiusMinor_px = random.uniform(1.5, 3.5);
            g.peak_dn = random.uniform(250.0, 700.0);
            flickerGlints_[static_cast<std::size_t>(camera)].push_back(g);
        }
    }
    // Scene coordinates: about the middle of the project's rig, which randomRig()s also face.
    const double midline =
        scene_.rig.convergence_deg >= 0.0 ? kSceneCentre_mm.x() : 0.5 * scene_.rig.baseline_mm;
    for (int i = 0; i < scene_.spurious.points3d; ++i) {
        const double z = random.uniform(420.0, 760.0);
        const double y = random.uniform(-160.0, 160.0);
        const double x = random.uniform(midline - 220.0, midline + 220.0);
        spuriousPoints_rig_mm_.push_back(T_rig_from_scene_.apply(Vec3(x, y, z)));
    }
    occluderScratch_.reserve(scene_.occluders.size());
}

bool World::markerVisible(const Vec3& position_rig_mm, const Vec3& normal_rig, int camera,
                          int ownObject, const std::vector<RigidTransform>& poses,
                          const std::vector<Vec3>& occluderCentres) const {
    const Vec3 eye = rig_.camera(camera).centre_rig_mm();
    const Vec3 toEye = eye - position_rig_mm;
    const bool hasNormal = normal_rig.squaredNorm() > 0.5;
    // Flat markers stop reflecting toward the camera well before grazing incidence.
    const double minFacingCosine =
        ownObject >= 0 ? scene_.objects[static_cast<std::size_t>(ownObject)].object.minFacingCosine
                       : 0.2;
    if (hasNormal && normal_rig.dot(toEye) < minFacingCosine * toEye.norm())
        return false;

    for (std::size_t o = 0; o < scene_.objects.size(); ++o) {
        const MarkerObject& object = scene_.objects[o].object;
        const RigidTransform toObject = poses[o].inverse();
        // A marker sits on its own body's surface: start just outside it along the normal.
        Vec3 start = position_rig_mm;
        if (static_cast<int>(o) == ownObject) {
            if (!hasNormal)
                continue;
            start += 0.6 * normal_rig;
        }
        const Vec3 a = toObject.apply(start);
        const Vec3 b = toObject.apply(eye);
        for (const BodyBox& box : object.bodyBoxes)
            if (segmentHitsBox(a, b, box.centre_object_mm, box.halfExtent_mm))
                return false;
        if (object.bodyRadius_mm > 0.0 &&
            segmentHitsSphere(a, b, Vec3::Zero(), object.bodyRadius_mm))
            return false;
    }
    for (std::size_t i = 0; i < occluderCentres.size(); ++i)
        if (segmentHitsSphere(position_rig_mm, eye, occluderCentres[i],
                              scene_.occluders[i].radius_mm))
            return false;
    return true;
}

namespace {

// The image of a sphere of radius_mm centred at centre_cam_mm (camera frame) in normalized
// coordinates: the cone of rays tangent to it is X^T M X = 0 with M = C C^T - (|C|^2 - R^2) I.
// On the plane z = 1 (X = (p, 1)) that is the ellipse (p - p0)^T (Q / s) (p - p0) = 1 with
// Q = -M's upper 2x2 block. Returns false when the sphere reaches behind the camera's plane.
bool sphereImage(const Vec3& centre_cam_mm, double radius_mm, Vec2& centre,
                 Eigen::Matrix2d& shape) {
    const double offAxis2 = centre_cam_mm.squaredNorm() - radius_mm * radius_mm;
    if (!(centre_cam_mm.z() > radius_mm) || offAxis2 <= 0.0)
        return false;
    const Mat3 m = centre_cam_mm * centre_cam_mm.transpose() - offAxis2 * Mat3::Identity();
    const Eigen::Matrix2d q = -m.topLeftCorner<2, 2>();
    const Vec2 b = m.topRightCorner<2, 1>();
    const Eigen::Matrix2d qInverse = q.inverse();
    centre = qInverse * b;
    const double scale = m(2, 2) + b.dot(qInverse * b);
    if (!(scale > 0.0))
        return false;
    // shape shape^T = scale Q^-1: the symmetric square root.
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(scale * qInverse);
    shape = eigen.eigenvectors() * eigen.eigenvalues().cwiseMax(0.0).cwiseSqrt().asDiagonal() *
            eigen.eigenvectors().transpose();
    return true;
}

// The image of a flat disc of radius_mm at centre_cam_mm facing normal_cam, in normalized
// coordinates, to first order in its size: the projection's Jacobian applied to two radii.
void discImage(const Vec3& centre_cam_mm, const Vec3& normal_cam, double radius_mm, Vec2& centre,
               Eigen::Matrix2d& shape) {
    const double z = centre_cam_mm.z();
    centre = {centre_cam_mm.x() / z, centre_cam_mm.y() / z};
    Eigen::Matrix<double, 2, 3> projection;
    projection << 1.0 / z, 0.0, -centre.x() / z, 0.0, 1.0 / z, -centre.y() / z;
    const Vec3 axis0 = normal_cam.unitOrthogonal();
    const Vec3 axis1 = normal_cam.cross(axis0);
    shape.col(0) = radius_mm * (projection * axis0);
    shape.col(1) = radius_mm * (projection * axis1);
}

} // namespace

void World::fillView(MarkerView& view, const Vec3& normal_rig, double diameter_mm, bool flat,
                     int ownObject, const std::vector<RigidTransform>& poses,
                     const std::vector<Vec3>& occluderCentres) const {
    const RigSpec& optics = scene_.rig;
    const double focus_mm =
        optics.focusDistance_mm > 0.0 ? optics.focusDistance_mm : optics.convergenceDistance_mm;
    const bool hasNormal = normal_rig.squaredNorm() > 0.5;
    for (int camera = 0; camera < 2; ++camera) {
        const auto c = static_cast<std::size_t>(camera);
        view.visible[c] = false;
        const CameraModel& model = rig_.camera(camera);
        const std::optional<Vec2> pixel = model.project(view.position_rig_mm);
        if (!pixel)
            continue;
        const CameraIntrinsics& in = model.intrinsics();
        if (pixel->x() < 0.0 || pixel->y() < 0.0 || pixel->x() > in.width_px - 1.0 ||
            pixel->y() > in.height_px - 1.0)
            continue;
        if (!markerVisible(view.position_rig_mm, normal_rig, camera, ownObject, poses,
                           occluderCentres))
            continue;
        const Vec3 inCamera = model.toCamera(view.position_rig_mm);
        const double radius_mm = 0.5 * diameter_mm;
        Vec2 centre;
        Eigen::Matrix2d shape;
        if (flat && hasNormal) {
            discImage(inCamera, model.extrinsics().rotation_cam_from_rig * normal_rig, radius_mm,
                      centre, shape);
        } else if (!sphereImage(inCamera, radius_mm, centre, shape)) {
            continue;
        }
        // Small enough for the distortion to be affine across it: its Jacobian at the centre.
        const Eigen::Matrix2d toPixels =
            Eigen::Vector2d(in.fx_px, in.fy_px).asDiagonal() * model.distortionJacobian(centre);
        const double distance_mm = inCamera.norm();
        double facing = 1.0;
        if (hasNormal) {
            const Vec3 toEye = (model.centre_rig_mm() - view.position_rig_mm).normalized();
            facing = 0.35 + 0.65 * normal_rig.dot(toEye);
        }
        const double falloff = (kReferenceDistance_mm / distance_mm);
        const double cosOffAxis = inCamera.z() / distance_mm;
        const double vignetting = optics.vignetting ? std::pow(cosOffAxis, 4) : 1.0;
        // Thin lens: a point at depth z spreads to a disc of aperture * f * |1/focus - 1/z| px,
        // whose spread along one axis is a quarter of its diameter.
        const double defocus_px =
            optics.aperture_mm * in.fx_px * std::abs(1.0 / focus_mm - 1.0 / inCamera.z());
        view.visible[c] = true;
        view.pixel[c] = *pixel;
        view.spotCentre_px[c] = model.pixelFromNormalized(model.distortNormalized(centre));
        view.shape_px[c] = toPixels * shape;
        view.radius_px[c] = std::sqrt(std::abs(view.shape_px[c].determinant()));
        view.blur_px[c] = std::hypot(FrameRenderer::kEdgeBlur_px, 0.25 * defocus_px);
        view.depth_mm[c] = inCamera.z();
        view.peak_dn[c] = kPeakAtReference_dn * falloff * falloff * facing * vignetting;
    }
}

void World::observe(std::uint64_t frameIndex, Observation& out) const {
    const double t = frameTime_s(frameIndex);
    out.time_s = t;
    // Room for the largest frame at once, so observing allocates only the first time.
    std::size_t markerCount = 0;
    for (const SceneObject& object : scene_.objects)
        markerCount += object.object.markers.size();
    out.objectPoses.reserve(scene_.objects.size());
    out.markers.reserve(markerCount);
    out.spuriousPoints.reserve(spuriousPoints_rig_mm_.size());
    for (std::size_t camera = 0; camera < 2; ++camera) {
        out.glints[camera].reserve(staticGlints_[camera].size() + flickerGlints_[camera].size());
        out.occluders[camera].reserve(scene_.occluders.size());
    }
    out.objectPoses.clear();
    for (const SceneObject& object : scene_.objects)
        out.objectPoses.push_back(T_rig_from_scene_ * object.motion.poseAt(t));
    occluderScratch_.clear();
    for (const Occluder& occluder : scene_.occluders)
        occluderScratch_.push_back(
            T_rig_from_scene_.apply(occluder.motion.poseAt(t).translation_mm));

    out.markers.clear();
    for (std::size_t o = 0; o < scene_.objects.size(); ++o) {
        const MarkerObject& object = scene_.objects[o].object;
        const RigidTransform& pose = out.objectPoses[o];
        for (std::size_t m = 0; m < object.markers.size(); ++m) {
            MarkerView view;
            view.object = static_cast<int>(o);
            view.marker = static_cast<int>(m);
            view.position_rig_mm = pose.apply(object.markers[m].position_object_mm);
            const Vec3 normal_rig = pose.rotation * object.markers[m].normal_object;
            fillView(view, normal_rig, object.markerDiameter_mm, object.flatMarkers,
                     static_cast<int>(o), out.objectPoses, occluderScratch_);
            out.markers.push_back(view);
        }
    }

    Random flicker(mix(seed_, frameIndex + 1));
    out.spuriousPoints.clear();
    for (std::size_t i = 0; i < spuriousPoints_rig_mm_.size(); ++i) {
        if (!flicker.chance(kSpuriousPointLitProbability))
            continue;
        MarkerView view;
        view.object = -1;
        view.marker = static_cast<int>(i);
        view.position_rig_mm = spuriousPoints_rig_mm_[i];
        fillView(view, Vec3::Zero(), kSpuriousPointDiameter_mm, false, -1, out.objectPoses,
                 occluderScratch_);
        for (double& peak : view.peak_dn)
            peak *= 0.6;
        out.spuriousPoints.push_back(view);
    }
    for (std::size_t camera = 0; camera < 2; ++camera) {
        out.occluders[camera].clear();
        const CameraModel& model = rig_.camera(static_cast<int>(camera));
        for (std::size_t i = 0; i < occluderScratch_.size(); ++i) {
            const Vec3 inCamera = model.toCamera(occluderScratch_[i]);
            const double radius_mm = scene_.occluders[i].radius_mm;
            const std::optional<Vec2> centre = model.project(occluderScratch_[i]);
            if (!centre || inCamera.z() <= radius_mm)
                continue;
            out.occluders[camera].push_back({*centre,
                                             model.intrinsics().fx_px * radius_mm / inCamera.z(),
                                             inCamera.z() - radius_mm});
        }
    }
    for (std::size_t camera = 0; camera < 2; ++camera) {
        out.glints[camera].clear();
        for (const Glint& g : staticGlints_[camera])
            out.glints[camera].push_back(g);
        for (const Glint& g : flickerGlints_[camera])
            if (flicker.chance(scene_.spurious.flickerProbability))
                out.glints[camera].push_back(g);
    }
}

Eigen::Matrix2d Glint::shape_px() const {
    return Eigen::Rotation2Dd(angle_rad).toRotationMatrix() *
           Eigen::Vector2d(radiusMajor_px, radiusMinor_px).asDiagonal();
}

// ---------------------------------------------------------------------------------------------

FrameRenderer::FrameRenderer(int width_px, int height_px, double background_dn,
                             double noiseSigma_dn, std::uint64_t seed)
    : width_px_(width_px)
    , height_px_(height_px)
    , seed_(seed) {
    constexpr std::size_t kTableExtra = 1u << 16;
    noiseTable_.resize(static_cast<std::size_t>(width_px) + kTableExtra);
    Random random(mix(seed, 0x401CE));
    for (std::uint8_t& value : noiseTable_)
        value = static_cast<std::uint8_t>(
            std::clamp(std::lround(background_dn + random.normal(noiseSigma_dn)), 0l, 255l));
}

void FrameRenderer::drawSpot(std::span<std::uint8_t> image, int stride_bytes, const Vec2& centre_px,
                             const Eigen::Matrix2d& shape_px, double blur_px, double peak_dn,
                             double depth_mm, std::span<const OccluderView> occluders) const {
    const double determinant = shape_px.determinant();
    if (peak_dn <= 0.5 || !(std::abs(determinant) > 1e-12))
        return;
    // u = inverse * offset is the offset in units of the ellipse (|u| = 1 on its edge).
    const Eigen::Matrix2d inverse = shape_px.inverse();
    const Eigen::Matrix2d metric = inverse.transpose() * inverse;
    const Eigen::JacobiSVD<Eigen::Matrix2d> axes(shape_px);
    const double major_px = axes.singularValues()(0), minor_px = axes.singularValues()(1);
    const double edgeScale = 1.0 / (std::numbers::sqrt2 * blur_px);
    // Beyond this distance from the edge the spot adds under 0.45 dn, which the rounding below
    // turns into nothing (erfc(x) <= exp(-x^2) for x >= 0), so those pixels skip the costly erfc.
    const double noEffect_px = std::sqrt(std::max(0.0, std::log(peak_dn / 0.9))) / edgeScale;
    const double reach = major_px + noEffect_px + 1.0;
    const int x0 = std::max(0, static_cast<int>(std::floor(centre_px.x() - reach)));
    const int x1 = std::min(width_px_ - 1, static_cast<int>(std::ceil(centre_px.x() + reach)));
    const int y0 = std::max(0, static_cast<int>(std::floor(centre_px.y() - reach)));
    const int y1 = std::min(height_px_ - 1, static_cast<int>(std::ceil(centre_px.y() + reach)));
    for (int y = y0; y <= y1; ++y) {
        std::uint8_t* row = image.data() + static_cast<std::ptrdiff_t>(y) * stride_bytes;
        for (int x = x0; x <= x1; ++x) {
            const Vec2 offset(x - centre_px.x(), y - centre_px.y());
            const Vec2 pulled = metric * offset;
            const double q = std::sqrt(offset.dot(pulled));
            // Signed distance to the edge (px), to first order: (q - 1) / |grad q|.
            const double gradient = q > 1e-9 ? pulled.norm() / q : 0.0;
            const double edge_px = gradient > 0.0 ? (q - 1.0) / gradient : -minor_px;
            if (edge_px > noEffect_px)
                continue;
            double value = peak_dn * 0.5 * std::erfc(edge_px * edgeScale);
            // Behind the edge of a nearer occluder, as blurred as any edge.
            for (const OccluderView& o : occluders)
                if (o.depth_mm < depth_mm)
                    value *=
                        1.0 - 0.5 * std::erfc(((Vec2(x, y) - o.centre_px).norm() - o.radius_px) *
                                              edgeScale);
            const double sum = row[x] + value + 0.5;
            row[x] = static_cast<std::uint8_t>(sum >= 255.0 ? 255.0 : sum);
        }
    }
}

void FrameRenderer::render(std::span<std::uint8_t> image, int stride_bytes, int camera,
                           const Observation& observation, double ledLitFraction,
                           std::uint64_t frameIndex) const {
    Random random(mix(seed_, frameIndex * 2 + static_cast<std::uint64_t>(camera) + 7));
    const std::size_t width = static_cast<std::size_t>(width_px_);
    const std::uint64_t offsets = noiseTable_.size() - width;
    for (int y = 0; y < height_px_; ++y)
        std::memcpy(image.data() + static_cast<std::ptrdiff_t>(y) * stride_bytes,
                    noiseTable_.data() + random.below(offsets), width);

    const auto c = static_cast<std::size_t>(camera);
    const double lit = std::clamp(ledLitFraction, 0.0, 1.0);
    for (const MarkerView& m : observation.markers)
        if (m.visible[c])
            drawSpot(image, stride_bytes, m.spotCentre_px[c], m.shape_px[c], m.blur_px[c],
                     m.peak_dn[c] * lit, m.depth_mm[c], observation.occluders[c]);
    for (const MarkerView& m : observation.spuriousPoints)
        if (m.visible[c])
            drawSpot(image, stride_bytes, m.spotCentre_px[c], m.shape_px[c], m.blur_px[c],
                     m.peak_dn[c]);
    for (const Glint& g : observation.glints[c])
        drawSpot(image, stride_bytes, g.centre_px, g.shape_px(), kEdgeBlur_px, g.peak_dn);
}

} // namespace edgetrack::sim
