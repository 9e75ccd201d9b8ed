// Simulated world: marker objects, their motions, occluders, spurious reflections, named scenes.
#pragma once

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/rigid_transform.hpp"
#include "core/stereo_rig.hpp"

namespace edgetrack::sim {

/// \brief One retroreflective marker on an object, in the object's frame.
struct SimMarker {
    Vec3 position_object_mm = Vec3::Zero();
    /// Outward surface normal (unit). Zero for a spherical marker on a post, seen from anywhere.
    Vec3 normal_object = Vec3::Zero();
};

/// \brief An axis-aligned box of the object's body, in the object's frame; it hides markers.
struct BodyBox {
    Vec3 centre_object_mm = Vec3::Zero();
    Vec3 halfExtent_mm = Vec3::Zero();
};

/// \brief A rigid object carrying markers: the paper's cubes, sphere and toy car, or a wand.
struct MarkerObject {
    std::string name;
    std::vector<SimMarker> markers;
    double markerDiameter_mm = 6.0;
    std::vector<BodyBox> bodyBoxes;
    /// A spherical body (radius > 0), centred on the object's origin.
    double bodyRadius_mm = 0.0;
    /// A flat marker is seen while the cosine of the angle between its normal and the line to
    /// the camera is at least this: 0.2 is a 157 degree cone; retroreflective foil on a curved
    /// object may give only 60 degrees (0.87).
    double minFacingCosine = 0.2;
    /// Flat markers (retroreflective foil discs of markerDiameter_mm on the surface, each with
    /// its normal): their images are ellipses narrowed by the slant at which each camera sees
    /// them. false: spheres, whose images depend only on where they lie.
    bool flatMarkers = false;
};

/// The paper's 7x7x7 cm cube with 30 markers, five per face, irregular so no face repeats.
MarkerObject makeCube70();
/// The paper's 5x5x5 cm cube, four markers per face.
MarkerObject makeCube50();
/// The paper's sphere of 7 cm diameter with 24 markers.
MarkerObject makeSphere70();
/// The paper's toy car with 38 markers on body and cabin.
MarkerObject makeToyCar();
/// Six clusters of two or three 10 mm spheres 1 to 1.6 diameters apart: images that touch.
MarkerObject makeClusters();
/// A wand with three spherical markers on a line, 55 and 102 mm apart.
MarkerObject makeWand();

/**
 * \brief How an object (or hand) moves: smooth wander, turning, erratic shake, leaving the view.
 *
 * Every term is a sum of sines with phases drawn from the seed, so a pose is a pure function of
 * time: any frame can be rendered alone, in any order, and twice gives the same answer.
 */
struct MotionSpec {
    Vec3 centre_rig_mm{60.0, 0.0, 550.0};
    /// Slow wander around the centre, per axis.
    Vec3 wanderAmplitude_mm{60.0, 40.0, 50.0};
    double wanderFrequency_hz = 0.08;
    /// Steady turning about two axes, so that over time every side faces the cameras.
    double spinRate_radps = 0.5;
    double tumbleRate_radps = 0.23;
    /// Erratic hand motion: fast shake of position and orientation.
    double shakeAmplitude_mm = 0.0;
    double shakeAmplitude_rad = 0.0;
    double shakeFrequency_hz = 2.0;
    /// Share of time in erratic mode, in alternating blocks (0: never, 1: always).
    double erraticShare = 1.0;
    double erraticPeriod_s = 8.0;
    /// Leave the view at leaveAt_s, be back by returnAt_s (negative: never leave).
    double leaveAt_s = -1.0;
    double returnAt_s = -1.0;
    Vec3 leaveOffset_mm{700.0, 0.0, 0.0};
};

class Motion {
public:
    Motion() = default;
    Motion(const MotionSpec& spec, std::uint64_t seed);

    /// \return T_rig_from_object at time \a t_s.
    RigidTransform poseAt(double t_s) const;
    const MotionSpec& spec() const { return spec_; }

private:
    struct Wave {
        double amplitude = 0.0;
        double frequency_hz = 0.0;
        double phase = 0.0;
    };
    static double sum(const std::vector<Wave>& waves, double t_s);

    MotionSpec spec_{};
    Quat initial_ = Quat::Identity();
    Vec3 spinAxis_ = Vec3::UnitY();
    Vec3 tumbleAxis_ = Vec3::UnitX();
    std::vector<Wave> wander_[3];
    std::vector<Wave> shake_[3];
    std::vector<Wave> twist_[3];
};

/// \brief A hand or arm: a sphere that hides markers behind it.
struct Occluder {
    Motion motion;
    double radius_mm = 40.0;
};

/// \brief Ambient IR reflections, independent of the LED ring.
struct SpuriousSpec {
    /// Per camera: fixed glints, some of them elongated streaks.
    int staticPerCamera = 0;
    /// Per camera: glints that come and go from frame to frame.
    int flickeringPerCamera = 0;
    double flickerProbability = 0.3;
    /// Reflective points in the volume, seen by both cameras (a watch, a screw head).
    int points3d = 0;
};

/// \brief The simulated rig's optics, like the paper's near-field desktop setup.
struct RigSpec {
    int width_px = 1280;
    int height_px = 800;
    double focal_px = 910.0;
    double baseline_mm = 120.0;
    /// Camera 1 is turned toward camera 0's axis so both look at this distance.
    double convergenceDistance_mm = 550.0;
    double k1 = -0.08;
    double k2 = 0.02;
    /// Entrance pupil diameter (mm): with focusDistance_mm it sets the defocus blur, a disc of
    /// aperture * focal_px * |1 / focus - 1 / depth| px (thin lens) at each depth.
    double aperture_mm = 1.2;
    /// Distance the lenses are focused at (mm); 0: the convergence distance.
    double focusDistance_mm = 0.0;
    /// Natural vignetting: brightness falls as cos^4 of the angle off the optical axis. false
    /// turns it off.
    bool vignetting = true;

    // A rig of any build (randomRig()): used where convergence_deg >= 0, in place of the
    // project's rig above (camera 0 straight ahead, camera 1 turned toward its axis).
    /// Angle between the optical axes (degrees): each camera turned inward by half of it.
    double convergence_deg = -1.0;
    /// Distance from the middle of the baseline to kSceneCentre_mm (mm), which both cameras
    /// face, each turned by half the convergence.
    double viewingDistance_mm = 550.0;
    /// The whole rig rolled about its viewing direction, and each camera about its own axis
    /// (degrees): rigs are mounted sideways, and sensors sit a little turned in their lenses.
    double rigRoll_deg = 0.0;
    std::array<double, 2> cameraRoll_deg{0.0, 0.0};
    /// Camera 1's focal length over camera 0's.
    double focalRatio1 = 1.004;
    double k3 = 0.0;
};

/// \brief Where the project's scenes move their objects about, in scene coordinates (mm): the
/// frame of the project's rig's camera 0.
inline const Vec3 kSceneCentre_mm{60.0, 0.0, 550.0};

/// \brief A hand passing in front of the objects: it wanders sideways about \a centre_rig_mm
/// at \a frequency_hz, without turning.
MotionSpec passingHand(const Vec3& centre_rig_mm, double frequency_hz);

/// \brief Build the stereo rig of \a spec (camera 0 at the origin, camera 1 to its right).
StereoRig makeRig(const RigSpec& spec);

/**
 * \brief T_rig_from_scene: where the scene's coordinates (kSceneCentre_mm, the objects' motions)
 * lie in the frame of \a spec's camera 0. The identity for the project's rig.
 */
RigidTransform rigFromScene(const RigSpec& spec);

/// \brief \a rig with camera 1 moved by \a offset_mm and turned by \a turn_deg about a tilted
/// axis: the cameras after a knock, or a rig measured long ago. The board believes such a rig
/// while the simulated cameras render with the true one.
StereoRig knockedRig(const StereoRig& rig, double offset_mm, double turn_deg);

struct SceneObject {
    MarkerObject object;
    Motion motion;
};

/// \brief A complete simulated scene.
struct Scene {
    std::string name;
    std::string description;
    RigSpec rig;
    double frameRate_hz = 100.0;
    double exposure_s = 0.001;
    std::vector<SceneObject> objects;
    std::vector<Occluder> occluders;
    SpuriousSpec spurious;
    /// Sensor noise, digital numbers (standard deviation).
    double noiseSigma_dn = 2.0;
    /// Background level, digital numbers.
    double background_dn = 10.0;
    /// Noise of each coordinate of a point at points level (mm, standard deviation).
    double pointNoise_mm = 0.05;
};

/**
 * \brief Another session with \a scene's objects: the same objects and rig, each moving as
 * before in kind but with its own phases and turning axes drawn from \a sessionSeed (so the
 * cameras see each object from other directions), a hand passing in front of them, and at least
 * six glints per camera that come and go. A user calibrates once and tracks in sessions like it.
 */
Scene anotherSession(const Scene& scene, std::uint64_t sessionSeed);

struct SceneInfo {
    const char* name;
    const char* description;
};

/// \return the named scenes, in the order `edgetrack sim --list` prints them.
std::span<const SceneInfo> sceneCatalogue();

/// \brief Build scene \a name with motions drawn from \a seed. \return nothing for an unknown name.
std::optional<Scene> makeScene(std::string_view name, std::uint64_t seed);

} // namespace edgetrack::sim
