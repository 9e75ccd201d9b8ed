// What the simulated cameras see: marker visibility, occlusion, spurious reflections, images.
#pragma once

#include <array>
#include <cstdint>
#include <span>
#include <vector>

#include "core/stereo_rig.hpp"
#include "hal/sim/scene.hpp"

namespace edgetrack::sim {

/// \brief One marker of one object as both cameras see it at one instant (ground truth).
struct MarkerView {
    int object = 0;
    int marker = 0;
    Vec3 position_rig_mm = Vec3::Zero();
    /// In the image, facing the camera and not hidden by any body or hand.
    std::array<bool, 2> visible{};
    /// The projection of the marker's centre (raw px): where a perfect detector puts it.
    std::array<Vec2, 2> pixel{Vec2::Zero(), Vec2::Zero()};
    /// Radius of the disc of the same area as the marker's image (px).
    std::array<double, 2> radius_px{};
    /// The marker's image as the lens forms it, an ellipse: the pixels spotCentre_px + shape_px u
    /// for u in the unit disc (raw px). For a sphere it is the tangent cone's conic, which is
    /// longer along the radius from the image centre by 1 / cos of the angle off the axis; for a
    /// flat marker it is the disc seen at its slant; both are then warped by the lens distortion.
    std::array<Eigen::Matrix2d, 2> shape_px{Eigen::Matrix2d::Identity(),
                                            Eigen::Matrix2d::Identity()};
    /// Centre of that ellipse (raw px): for a sphere off the axis it lies outward of pixel by a
    /// few thousandths of a pixel (the cone's conic is not centred on the centre's image).
    std::array<Vec2, 2> spotCentre_px{Vec2::Zero(), Vec2::Zero()};
    /// Blur of the image's edge (Gaussian sigma, px): the lens's own (FrameRenderer::kEdgeBlur_px)
    /// and the defocus at the marker's depth.
    std::array<double, 2> blur_px{0.6, 0.6};

    /// \brief Make camera \a camera's image a disc of \a radius_px at \a centre_px (for tests
    /// that place images by hand).
    void setDisc(int camera, const Vec2& centre_px, double discRadius_px) {
        const auto c = static_cast<std::size_t>(camera);
        pixel[c] = spotCentre_px[c] = centre_px;
        radius_px[c] = discRadius_px;
        shape_px[c] = discRadius_px * Eigen::Matrix2d::Identity();
    }
    /// Peak brightness with the LED ring lit for the whole exposure (DN; above 255 saturates).
    std::array<double, 2> peak_dn{};
    /// Depth in each camera's frame (mm, along its optical axis): what lies nearer hides it.
    std::array<double, 2> depth_mm{};
};

/// \brief A hand or arm (an occluder sphere) as one camera sees it: a dark disc in front of what
/// lies deeper, which cuts the discs of markers at its edge.
struct OccluderView {
    Vec2 centre_px = Vec2::Zero();
    double radius_px = 0.0;
    /// Depth of its nearest point in the camera's frame (mm).
    double depth_mm = 0.0;
};

/// \brief An image-space reflection of ambient IR in one camera; not lit by the LED ring.
struct Glint {
    Vec2 centre_px = Vec2::Zero();
    double radiusMajor_px = 2.0;
    double radiusMinor_px = 2.0;
    double angle_rad = 0.0;
    double peak_dn = 400.0;

    bool isRound() const { return radiusMajor_px <= 1.3 * radiusMinor_px; }
    /// Its ellipse as MarkerView::shape_px (px).
    Eigen::Matrix2d shape_px() const;
};

/// \brief The world at one instant, from the cameras' point of view.
struct Observation {
    double time_s = 0.0;
    /// T_rig_from_object for each scene object, in scene order.
    std::vector<RigidTransform> objectPoses;
    std::vector<MarkerView> markers;
    /// Reflective points in the volume that are lit this frame (ambient, both cameras).
    std::vector<MarkerView> spuriousPoints;
    std::array<std::vector<Glint>, 2> glints;
    /// Per camera, the occluders in front of it: a marker whose centre they leave in view but
    /// whose disc reaches under one is rendered cut by its edge.
    std::array<std::vector<OccluderView>, 2> occluders;
};

/**
 * \brief The simulated world: a scene, its rig, and everything random drawn from one seed.
 *
 * observe() is a pure function of (seed, frame index), so frames can be produced in any order and
 * twice give the same result. Vectors in the Observation are reused, so after the first frames
 * observing allocates nothing.
 */
class World {
public:
    World(Scene scene, std::uint64_t seed);

    const Scene& scene() const { return scene_; }
    const StereoRig& rig() const { return rig_; }
    std::uint64_t seed() const { return seed_; }

    /// \return time (s) of frame \a frameIndex's mid-exposure.
    double frameTime_s(std::uint64_t frameIndex) const {
        return static_cast<double>(frameIndex) / scene_.frameRate_hz;
    }

    /// \brief Fill \a out with the world as seen at frame \a frameIndex.
    void observe(std::uint64_t frameIndex, Observation& out) const;

    /// \brief Marker visibility from camera \a camera (facing it and not hidden); exposed for
    /// tests.
    bool markerVisible(const Vec3& position_rig_mm, const Vec3& normal_rig, int camera,
                       int ownObject, const std::vector<RigidTransform>& poses,
                       const std::vector<Vec3>& occluderCentres) const;

private:
    void fillView(MarkerView& view, const Vec3& normal_rig, double diameter_mm, bool flat,
                  int ownObject, const std::vector<RigidTransform>& poses,
                  const std::vector<Vec3>& occluderCentres) const;

    Scene scene_;
    StereoRig rig_;
    /// Where the scene's motions and points lie in the rig frame (rigFromScene()).
    RigidTransform T_rig_from_scene_;
    std::uint64_t seed_;
    std::array<std::vector<Glint>, 2> staticGlints_;
    std::array<std::vector<Glint>, 2> flickerGlints_;
    std::vector<Vec3> spuriousPoints_rig_mm_;
    mutable std::vector<Vec3> occluderScratch_;
};

/**
 * \brief Renders 8-bit IR frames: background, sensor noise, blurred saturating marker discs.
 *
 * Noise comes from a table made once, copied per row from a random offset, so a frame costs
 * little more than a memory fill. Overlapping discs add up and merge into one blob.
 */
class FrameRenderer {
public:
    FrameRenderer(int width_px, int height_px, double background_dn, double noiseSigma_dn,
                  std::uint64_t seed);

    /**
     * \brief Render camera \a camera's image of \a observation into \a image (row stride
     * \a stride_bytes).
     * \param ledLitFraction share of the exposure during which the LED ring was on (0 to 1);
     * markers reflect the ring, glints do not.
     */
    void render(std::span<std::uint8_t> image, int stride_bytes, int camera,
                const Observation& observation, double ledLitFraction,
                std::uint64_t frameIndex) const;

    /// \brief Blur of every edge in focus (px, Gaussian sigma): the lens and the pixels.
    static constexpr double kEdgeBlur_px = 0.6;

private:
    /// An elliptic spot (centre_px + shape_px u, u in the unit disc) with an edge blurred by
    /// \a blur_px at depth \a depth_mm, cut by the edges of the \a occluders nearer than that.
    void drawSpot(std::span<std::uint8_t> image, int stride_bytes, const Vec2& centre_px,
                  const Eigen::Matrix2d& shape_px, double blur_px, double peak_dn,
                  double depth_mm = 0.0, std::span<const OccluderView> occluders = {}) const;

    int width_px_;
    int height_px_;
    std::uint64_t seed_;
    std::vector<std::uint8_t> noiseTable_;
};

} // namespace edgetrack::sim
