// Simulated world: marker objects, their motions, occluders, spurious reflections, named scenes.
#include "hal/sim/scene.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>

#include "hal/sim/random.hpp"
#include "hal/sim/random_objects.hpp"

namespace edgetrack::sim {

namespace {

constexpr double kPi = std::numbers::pi;

// A rectangle on an object's surface where markers may be stuck.
struct Patch {
    Vec3 centre_mm;
    Vec3 uAxis;
    Vec3 vAxis;
    double uHalf_mm;
    double vHalf_mm;
    int count;
};

// Scatters markers over patches by rejection sampling with a minimum spacing, from a fixed seed:
// the object is a physical thing, the same in every scene and for every scene seed.
std::vector<SimMarker> scatter(const std::vector<Patch>& patches, double margin_mm,
                               double minSpacing_mm, std::uint64_t layoutSeed) {
    Random random(layoutSeed);
    std::vector<SimMarker> markers;
    for (const Patch& patch : patches) {
        const Vec3 normal = patch.uAxis.cross(patch.vAxis).normalized();
        int placed = 0;
        for (int attempt = 0; placed < patch.count && attempt < 100000; ++attempt) {
            const double u =
                random.uniform(-patch.uHalf_mm + margin_mm, patch.uHalf_mm - margin_mm);
            const double v =
                random.uniform(-patch.vHalf_mm + margin_mm, patch.vHalf_mm - margin_mm);
            const Vec3 p = patch.centre_mm + u * patch.uAxis + v * patch.vAxis;
            const bool apart = std::all_of(markers.begin(), markers.end(), [&](const SimMarker& m) {
                return (m.position_object_mm - p).norm() >= minSpacing_mm;
            });
            if (apart) {
                markers.push_back({p, normal});
                ++placed;
            }
        }
    }
    return markers;
}

std::vector<Patch> cubeFaces(double half_mm, int perFace) {
    const Vec3 x = Vec3::UnitX(), y = Vec3::UnitY(), z = Vec3::UnitZ();
    // u x v points outward on every face.
    return {{half_mm * x, y, z, half_mm, half_mm, perFace},
            {-half_mm * x, z, y, half_mm, half_mm, perFace},
            {half_mm * y, z, x, half_mm, half_mm, perFace},
            {-half_mm * y, x, z, half_mm, half_mm, perFace},
            {half_mm * z, x, y, half_mm, half_mm, perFace},
            {-half_mm * z, y, x, half_mm, half_mm, perFace}};
}

double smoothstep(double edge0, double edge1, double x) {
    const double t = std::clamp((x - edge0) / (edge1 - edge0), 0.0, 1.0);
    return t * t * (3.0 - 2.0 * t);
}

Quat randomRotation(Random& random) {
    // Shoemake's uniform quaternion.
    const double u1 = random.uniform(), u2 = random.uniform(), u3 = random.uniform();
    const double a = std::sqrt(1.0 - u1), b = std::sqrt(u1);
    return Quat(a * std::sin(2.0 * kPi * u2), a * std::cos(2.0 * kPi * u2),
                b * std::sin(2.0 * kPi * u3), b * std::cos(2.0 * kPi * u3))
        .normalized();
}

} // namespace

namespace {
// A cube of edge 2 * half_mm with perFace markers scattered on each face.
MarkerObject makeCube(const char* name, double half_mm, int perFace, double diameter_mm,
                      double margin_mm, double spacing_mm, std::uint64_t layoutSeed) {
    MarkerObject cube;
    cube.name = name;
    cube.markerDiameter_mm = diameter_mm;
    cube.markers = scatter(cubeFaces(half_mm, perFace), margin_mm, spacing_mm, layoutSeed);
    cube.bodyBoxes.push_back({Vec3::Zero(), Vec3::Constant(half_mm)});
    return cube;
}
} // namespace

MarkerObject makeCube70() {
    return makeCube("cube70", 35.0, 5, 6.0, 7.0, 15.0, 70);
}

MarkerObject makeCube50() {
    return makeCube("cube50", 25.0, 4, 5.0, 6.0, 13.0, 50);
}

MarkerObject makeSphere70() {
    MarkerObject sphere;
    sphere.name = "sphere70";
    sphere.markerDiameter_mm = 6.0;
    sphere.bodyRadius_mm = 35.0;
    // A Fibonacci lattice, jittered from a fixed seed so the sphere has no symmetry to confuse.
    Random random(24);
    const int count = 24;
    const double golden = kPi * (3.0 - std::sqrt(5.0));
    for (int i = 0; i < count; ++i) {
        const double z = 1.0 - 2.0 * (i + 0.5) / count;
        const double r = std::sqrt(1.0 - z * z);
        const double azimuth = golden * i + random.uniform(-0.25, 0.25);
        const double tilt = random.uniform(-0.08, 0.08);
        Vec3 n(r * std::cos(azimuth), r * std::sin(azimuth), z + tilt);
        n.normalize();
        sphere.markers.push_back({35.0 * n, n});
    }
    return sphere;
}

MarkerObject makeToyCar() {
    MarkerObject car;
    car.name = "toy_car";
    car.markerDiameter_mm = 6.0;
    const Vec3 x = Vec3::UnitX(), y = Vec3::UnitY(), z = Vec3::UnitZ();
    // Body 110 x 50 x 35 mm, cabin 54 x 44 x 22 mm on top of it; origin at the body's centre.
    const BodyBox body{Vec3::Zero(), Vec3(55.0, 25.0, 17.5)};
    const BodyBox cabin{Vec3(-5.0, 0.0, 28.5), Vec3(27.0, 22.0, 11.0)};
    car.bodyBoxes = {body, cabin};
    const std::vector<Patch> patches{
        {Vec3(40.0, 0.0, 17.5), x, y, 15.0, 25.0, 4},   // hood
        {Vec3(-43.0, 0.0, 17.5), x, y, 12.0, 25.0, 3},  // trunk
        {Vec3(0.0, 25.0, 0.0), z, x, 17.5, 55.0, 7},    // left side
        {Vec3(0.0, -25.0, 0.0), x, z, 55.0, 17.5, 7},   // right side
        {Vec3(55.0, 0.0, 0.0), y, z, 25.0, 17.5, 3},    // front
        {Vec3(-55.0, 0.0, 0.0), z, y, 17.5, 25.0, 3},   // back
        {Vec3(-5.0, 0.0, 39.5), x, y, 27.0, 22.0, 5},   // roof
        {Vec3(-5.0, 22.0, 28.5), z, x, 11.0, 27.0, 2},  // cabin left
        {Vec3(-5.0, -22.0, 28.5), x, z, 27.0, 11.0, 2}, // cabin right
        {Vec3(22.0, 0.0, 28.5), y, z, 22.0, 11.0, 1},   // windscreen
        {Vec3(-32.0, 0.0, 28.5), z, y, 11.0, 22.0, 1},  // rear window
    };
    car.markers = scatter(patches, 5.0, 13.0, 38);
    return car;
}

MarkerObject makeWand() {
    MarkerObject wand;
    wand.name = "wand";
    wand.markerDiameter_mm = 14.0;
    // Spherical markers on a stick: seen from every side, so no normal.
    wand.markers = {{Vec3(-78.5, 0.0, 0.0), Vec3::Zero()},
                    {Vec3(-23.5, 0.0, 0.0), Vec3::Zero()},
                    {Vec3(78.5, 0.0, 0.0), Vec3::Zero()}};
    return wand;
}

// ---------------------------------------------------------------------------------------------

Motion::Motion(const MotionSpec& spec, std::uint64_t seed)
    : spec_(spec) {
    Random random(seed);
    initial_ = randomRotation(random);
    const double spinZ = random.uniform(-0.3, 0.3);
    const double spinX = random.uniform(-0.3, 0.3);
    spinAxis_ = Vec3(spinX, 1.0, spinZ).normalized();
    tumbleAxis_ = spinAxis_.cross(Vec3(random.uniform(-0.5, 0.5), 0.0, 1.0)).normalized();
    // Three incommensurate waves per axis make a path that does not visibly repeat.
    const std::array<double, 3> shares{0.65, 0.25, 0.10};
    const std::array<double, 3> harmonics{1.0, 1.73, 2.91};
    const std::array<double, 3> shakeHarmonics{1.0, 2.3, 3.7};
    for (int axis = 0; axis < 3; ++axis) {
        for (std::size_t k = 0; k < 3; ++k) {
            wander_[axis].push_back(
                {spec.wanderAmplitude_mm[axis] * shares[k],
                 spec.wanderFrequency_hz * harmonics[k] * random.uniform(0.8, 1.2),
                 random.uniform(0.0, 2.0 * kPi)});
            shake_[axis].push_back(
                {spec.shakeAmplitude_mm * shares[k],
                 spec.shakeFrequency_hz * shakeHarmonics[k] * random.uniform(0.8, 1.2),
                 random.uniform(0.0, 2.0 * kPi)});
            twist_[axis].push_back(
                {spec.shakeAmplitude_rad * shares[k],
                 spec.shakeFrequency_hz * shakeHarmonics[k] * random.uniform(0.8, 1.2),
                 random.uniform(0.0, 2.0 * kPi)});
        }
    }
}

double Motion::sum(const std::vector<Wave>& waves, double t_s) {
    double value = 0.0;
    for (const Wave& w : waves)
        value += w.amplitude * std::sin(2.0 * kPi * w.frequency_hz * t_s + w.phase);
    return value;
}

RigidTransform Motion::poseAt(double t_s) const {
    double erratic = 0.0;
    if (spec_.erraticShare >= 1.0) {
        erratic = 1.0;
    } else if (spec_.erraticShare > 0.0) {
        // Alternating blocks: calm, then erratic for erraticShare of each period.
        const double phase = std::fmod(t_s / spec_.erraticPeriod_s, 1.0);
        const double start = 1.0 - spec_.erraticShare;
        erratic = smoothstep(start, start + 0.05, phase) * (1.0 - smoothstep(0.95, 1.0, phase));
    }

    Vec3 position = spec_.centre_rig_mm;
    Vec3 twist = Vec3::Zero();
    for (int axis = 0; axis < 3; ++axis) {
        position[axis] += sum(wander_[axis], t_s) + erratic * sum(shake_[axis], t_s);
        twist[axis] = erratic * sum(twist_[axis], t_s);
    }
    if (spec_.leaveAt_s >= 0.0 && spec_.returnAt_s > spec_.leaveAt_s) {
        const double ramp_s = std::min(0.8, 0.5 * (spec_.returnAt_s - spec_.leaveAt_s));
        const double away = smoothstep(spec_.leaveAt_s, spec_.leaveAt_s + ramp_s, t_s) *
                            (1.0 - smoothstep(spec_.returnAt_s - ramp_s, spec_.returnAt_s, t_s));
        position += away * spec_.leaveOffset_mm;
    }

    const Quat turning =
        Quat(Eigen::AngleAxisd(spec_.spinRate_radps * t_s + twist.x(), spinAxis_)) *
        Quat(Eigen::AngleAxisd(spec_.tumbleRate_radps * t_s + twist.y(), tumbleAxis_)) *
        Quat(Eigen::AngleAxisd(twist.z(), Vec3::UnitZ()));
    RigidTransform pose;
    pose.rotation = (turning * initial_).normalized();
    pose.translation_mm = position;
    return pose;
}

// ---------------------------------------------------------------------------------------------

namespace {

// A rig of any build: T_scene_from_camera for camera \a index (0 left, 1 right).
RigidTransform sceneFromCamera(const RigSpec& spec, int index) {
    const double degree = std::numbers::pi / 180.0;
    const double side = index == 0 ? -1.0 : 1.0;
    // Turned inward about the camera's y axis (down), then rolled about its optical axis.
    const Mat3 middleFromCamera =
        (Eigen::AngleAxisd(-side * 0.5 * spec.convergence_deg * degree, Vec3::UnitY()) *
         Eigen::AngleAxisd(spec.cameraRoll_deg[static_cast<std::size_t>(index)] * degree,
                           Vec3::UnitZ()))
            .toRotationMatrix();
    const Mat3 sceneFromMiddle =
        Eigen::AngleAxisd(spec.rigRoll_deg * degree, Vec3::UnitZ()).toRotationMatrix();
    const Vec3 middle_scene_mm = kSceneCentre_mm - spec.viewingDistance_mm * Vec3::UnitZ();
    return RigidTransform::fromMatrix(
        sceneFromMiddle * middleFromCamera,
        middle_scene_mm + sceneFromMiddle * Vec3(side * 0.5 * spec.baseline_mm, 0.0, 0.0));
}

} // namespace

StereoRig makeRig(const RigSpec& spec) {
    CameraIntrinsics in;
    in.width_px = spec.width_px;
    in.height_px = spec.height_px;
    in.fx_px = spec.focal_px;
    in.fy_px = spec.focal_px;
    in.cx_px = 0.5 * (spec.width_px - 1);
    in.cy_px = 0.5 * (spec.height_px - 1);
    in.distortion = {spec.k1, spec.k2, 0.0, 0.0, spec.k3};

    CameraIntrinsics in1 = in;
    // Two real lenses are never identical.
    in1.fx_px *= spec.focalRatio1;
    in1.fy_px *= spec.focalRatio1 - 0.001;
    in1.cx_px += 3.5;
    in1.cy_px -= 2.0;

    CameraExtrinsics ex1;
    if (spec.convergence_deg >= 0.0) {
        const RigidTransform cam1FromRig =
            sceneFromCamera(spec, 1).inverse() * sceneFromCamera(spec, 0);
        ex1.rotation_cam_from_rig = cam1FromRig.rotationMatrix();
        ex1.translation_cam_from_rig_mm = cam1FromRig.translation_mm;
        return StereoRig(CameraModel(in, CameraExtrinsics{}), CameraModel(in1, ex1));
    }
    const double toeIn = std::atan2(spec.baseline_mm, spec.convergenceDistance_mm);
    // Turning about +y by the toe-in points camera 1's axis back toward -x, at camera 0's axis.
    ex1.rotation_cam_from_rig = Eigen::AngleAxisd(toeIn, Vec3::UnitY()).toRotationMatrix();
    const Vec3 centre1(spec.baseline_mm, 0.0, 0.0);
    ex1.translation_cam_from_rig_mm = -(ex1.rotation_cam_from_rig * centre1);
    return StereoRig(CameraModel(in, CameraExtrinsics{}), CameraModel(in1, ex1));
}

RigidTransform rigFromScene(const RigSpec& spec) {
    if (spec.convergence_deg < 0.0)
        return RigidTransform::identity();
    return sceneFromCamera(spec, 0).inverse();
}

Scene anotherSession(const Scene& scene, std::uint64_t sessionSeed) {
    Scene session = scene;
    std::uint64_t stream = sessionSeed * 7919 + 0xA5;
    for (SceneObject& object : session.objects)
        object.motion = Motion(object.motion.spec(), ++stream);
    for (Occluder& occluder : session.occluders)
        occluder.motion = Motion(occluder.motion.spec(), ++stream);
    if (session.occluders.empty()) {
        Vec3 centre = Vec3::Zero();
        for (const SceneObject& object : session.objects)
            centre += object.motion.spec().centre_rig_mm;
        if (!session.objects.empty())
            centre /= static_cast<double>(session.objects.size());
        session.occluders.push_back(
            {Motion(passingHand(centre - Vec3(0.0, 0.0, 120.0), 0.11), ++stream), 40.0});
    }
    session.spurious.staticPerCamera = std::max(session.spurious.staticPerCamera, 3);
    session.spurious.flickeringPerCamera = std::max(session.spurious.flickeringPerCamera, 6);
    return session;
}

MotionSpec passingHand(const Vec3& centre_rig_mm, double frequency_hz) {
    MotionSpec hand;
    hand.centre_rig_mm = centre_rig_mm;
    hand.wanderAmplitude_mm = {150.0, 40.0, 20.0};
    hand.wanderFrequency_hz = frequency_hz;
    hand.spinRate_radps = 0.0;
    hand.tumbleRate_radps = 0.0;
    hand.erraticShare = 0.0;
    return hand;
}

StereoRig knockedRig(const StereoRig& rig, double offset_mm, double turn_deg) {
    CameraExtrinsics ex = rig.camera(1).extrinsics();
    ex.rotation_cam_from_rig =
        Eigen::AngleAxisd(turn_deg * std::numbers::pi / 180.0, Vec3(0.6, 0.8, 0.0))
            .toRotationMatrix() *
        ex.rotation_cam_from_rig;
    ex.translation_cam_from_rig_mm += offset_mm * Vec3(0.48, -0.6, 0.64);
    return StereoRig(rig.camera(0), CameraModel(rig.camera(1).intrinsics(), ex));
}

MarkerObject makeClusters() {
    // Six clusters of two or three 10 mm spheres on posts, 10 to 16 mm apart in all three
    // directions: turning, their images pass through every separation from overlapping to apart.
    MarkerObject object;
    object.name = "clusters";
    object.markerDiameter_mm = 10.0;
    Random random(4242);
    for (int c = 0; c < 6; ++c) {
        const double angle = c * std::numbers::pi / 3.0;
        const Vec3 centre(55.0 * std::cos(angle), 55.0 * std::sin(angle), 8.0 * (c % 2));
        const int count = 2 + c % 2;
        object.markers.push_back({centre, Vec3::Zero()});
        for (int k = 1; k < count; ++k) {
            const double z = random.normal();
            const double y = random.normal();
            const double x = random.normal();
            Vec3 direction(x, y, z);
            direction.normalize();
            const double distance = object.markerDiameter_mm * random.uniform(1.3, 2.0);
            object.markers.push_back({centre + distance * direction, Vec3::Zero()});
        }
    }
    return object;
}

// ---------------------------------------------------------------------------------------------

namespace {

constexpr std::array<SceneInfo, 14> kScenes{{
    {"two_cubes", "7 cm and 5 cm cubes, slow and erratic, occluding each other (paper Table 1)"},
    {"cube_sphere", "7 cm cube and 7 cm sphere turned slowly side by side (paper Figure 7)"},
    {"toy_car", "toy car with 38 markers turned slowly to show every side"},
    {"crowd", "six objects at once: two identical 7 cm cubes, 5 cm cube, sphere, car, wand"},
    {"stress", "cube and sphere among many static, flickering and 3D spurious reflections"},
    {"erratic_cube", "7 cm cube in fast erratic hand motion"},
    {"leave_return", "7 cm cube leaves the view after 3 s and comes back at 6 s"},
    {"hand_occlusion", "7 cm cube turned slowly while a hand passes in front of it"},
    {"slow_cube", "7 cm cube alone, turned slowly: a calibration session"},
    {"wand", "three-marker wand waved through the volume"},
    {"touching", "clusters of markers 1-1.6 diameters apart turning, so that their images touch "
                 "and overlap, with a passing hand"},
    {"three_cubes", "three 7 cm cubes turned side by side: calibration cost (paper section 7.1)"},
    {"random_object", "one random object (ellipsoid, plate, ring, posts, star, box or car; 4-40 "
                      "markers) drawn from the seed, with hand, glints and noise as drawn"},
    {"random_objects", "two to four random objects at once, drawn from the seed"},
}};

MotionSpec slowTurns(const Vec3& centre) {
    MotionSpec m;
    m.centre_rig_mm = centre;
    m.wanderAmplitude_mm = {50.0, 35.0, 40.0};
    m.spinRate_radps = 0.6;
    m.tumbleRate_radps = 0.27;
    m.erraticShare = 0.0;
    return m;
}

MotionSpec erratic(const Vec3& centre) {
    MotionSpec m = slowTurns(centre);
    m.spinRate_radps = 1.2;
    m.tumbleRate_radps = 0.7;
    m.shakeAmplitude_mm = 25.0;
    m.shakeAmplitude_rad = 0.35;
    m.shakeFrequency_hz = 2.2;
    m.erraticShare = 1.0;
    return m;
}

} // namespace

std::span<const SceneInfo> sceneCatalogue() {
    return kScenes;
}

std::optional<Scene> makeScene(std::string_view name, std::uint64_t seed) {
    Scene scene;
    scene.name = std::string(name);
    for (const SceneInfo& info : kScenes)
        if (name == info.name)
            scene.description = info.description;
    if (scene.description.empty())
        return std::nullopt;

    // Each moving thing gets its own stream of phases, so adding one leaves the others alone.
    std::uint64_t stream = seed * 1000;
    auto add = [&scene, &stream](MarkerObject object, const MotionSpec& motion) {
        scene.objects.push_back({std::move(object), Motion(motion, ++stream)});
    };
    const double midline = 0.5 * scene.rig.baseline_mm;

    if (name == "random_object" || name == "random_objects") {
        const int count = name == "random_object" ? 1 : 2 + static_cast<int>(seed % 3);
        Scene random = makeRandomScene(count, seed);
        random.name = scene.name;
        random.description = scene.description;
        return random;
    }
    if (name == "two_cubes") {
        // Calm and erratic blocks alternate; the paths cross so the cubes hide each other.
        MotionSpec a = erratic({midline - 50.0, -10.0, 570.0});
        a.wanderAmplitude_mm = {75.0, 35.0, 45.0};
        a.erraticShare = 0.5;
        a.shakeAmplitude_mm = 15.0;
        a.shakeAmplitude_rad = 0.25;
        MotionSpec b = a;
        b.centre_rig_mm = {midline + 50.0, 10.0, 520.0};
        b.erraticPeriod_s = 6.0;
        add(makeCube70(), a);
        add(makeCube50(), b);
    } else if (name == "cube_sphere") {
        add(makeCube70(), slowTurns({midline - 60.0, 0.0, 560.0}));
        add(makeSphere70(), slowTurns({midline + 60.0, 0.0, 560.0}));
    } else if (name == "toy_car") {
        MotionSpec m = slowTurns({midline, 0.0, 580.0});
        m.wanderAmplitude_mm = {40.0, 30.0, 30.0};
        add(makeToyCar(), m);
    } else if (name == "crowd") {
        const std::array<Vec3, 6> centres{
            Vec3(midline - 150.0, -85.0, 620.0), Vec3(midline, -85.0, 620.0),
            Vec3(midline + 150.0, -85.0, 620.0), Vec3(midline - 150.0, 85.0, 620.0),
            Vec3(midline, 85.0, 620.0),          Vec3(midline + 150.0, 85.0, 620.0)};
        std::array<MarkerObject, 6> objects{makeCube70(),   makeCube70(), makeCube50(),
                                            makeSphere70(), makeToyCar(), makeWand()};
        for (std::size_t i = 0; i < objects.size(); ++i) {
            MotionSpec m = slowTurns(centres[i]);
            m.wanderAmplitude_mm = {25.0, 20.0, 30.0};
            add(std::move(objects[i]), m);
        }
    } else if (name == "stress") {
        add(makeCube70(), slowTurns({midline - 60.0, 0.0, 560.0}));
        add(makeSphere70(), slowTurns({midline + 60.0, 0.0, 560.0}));
        scene.spurious = {15, 12, 0.4, 10};
    } else if (name == "erratic_cube") {
        add(makeCube70(), erratic({midline, 0.0, 560.0}));
    } else if (name == "leave_return") {
        MotionSpec m = slowTurns({midline, 0.0, 560.0});
        m.leaveAt_s = 3.0;
        m.returnAt_s = 6.0;
        add(makeCube70(), m);
    } else if (name == "hand_occlusion") {
        add(makeCube70(), slowTurns({midline, 0.0, 580.0}));
        scene.occluders.push_back(
            {Motion(passingHand({midline, 30.0, 470.0}, 0.15), ++stream), 40.0});
    } else if (name == "slow_cube") {
        add(makeCube70(), slowTurns({midline, 0.0, 560.0}));
    } else if (name == "three_cubes") {
        for (int i = 0; i < 3; ++i) {
            MotionSpec m = slowTurns({midline - 120.0 + 120.0 * i, 0.0, 600.0});
            m.wanderAmplitude_mm = {30.0, 25.0, 30.0};
            add(makeCube70(), m);
        }
    } else if (name == "touching") {
        add(makeClusters(), slowTurns({midline, 0.0, 520.0}));
        scene.occluders.push_back(
            {Motion(passingHand({midline, 40.0, 430.0}, 0.12), ++stream), 40.0});
    } else if (name == "wand") {
        // Waved as a rig calibration asks: through the whole shared view, near and far.
        MotionSpec m = erratic({midline, 0.0, 620.0});
        m.wanderAmplitude_mm = {250.0, 150.0, 160.0};
        m.wanderFrequency_hz = 0.15;
        m.shakeAmplitude_mm = 10.0;
        m.shakeAmplitude_rad = 0.2;
        add(makeWand(), m);
    }
    return scene;
}

} // namespace edgetrack::sim
