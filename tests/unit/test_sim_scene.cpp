// Tests of the simulated world: objects, motions, visibility and occlusion, determinism.
#include <gtest/gtest.h>

#include "hal/sim/scene.hpp"
#include "hal/sim/world.hpp"

using namespace edgetrack;
using namespace edgetrack::sim;

namespace {
double minimumSpacing(const MarkerObject& object) {
    double spacing = 1e9;
    for (std::size_t i = 0; i < object.markers.size(); ++i)
        for (std::size_t j = i + 1; j < object.markers.size(); ++j)
            spacing = std::min(spacing, (object.markers[i].position_object_mm -
                                         object.markers[j].position_object_mm)
                                            .norm());
    return spacing;
}
} // namespace

TEST(SimObjects, ThePapersObjects) {
    EXPECT_EQ(makeCube70().markers.size(), 30u);
    EXPECT_EQ(makeCube50().markers.size(), 24u);
    EXPECT_EQ(makeSphere70().markers.size(), 24u);
    EXPECT_EQ(makeToyCar().markers.size(), 38u);
    EXPECT_EQ(makeWand().markers.size(), 3u);
    EXPECT_GE(minimumSpacing(makeCube70()), 15.0);
    EXPECT_GE(minimumSpacing(makeToyCar()), 13.0);
}

TEST(SimObjects, MarkersLieOnTheSurfaceWithOutwardNormals) {
    for (const SimMarker& m : makeCube70().markers) {
        EXPECT_NEAR(m.position_object_mm.cwiseAbs().maxCoeff(), 35.0, 1e-9);
        EXPECT_NEAR(m.normal_object.norm(), 1.0, 1e-12);
        EXPECT_GT(m.normal_object.dot(m.position_object_mm), 0.0);
    }
    for (const SimMarker& m : makeSphere70().markers) {
        EXPECT_NEAR(m.position_object_mm.norm(), 35.0, 1e-9);
        EXPECT_GT(m.normal_object.dot(m.position_object_mm), 0.0);
    }
}

TEST(SimObjects, LayoutIsTheSameObjectEveryTime) {
    const MarkerObject a = makeToyCar(), b = makeToyCar();
    for (std::size_t i = 0; i < a.markers.size(); ++i)
        EXPECT_EQ(a.markers[i].position_object_mm, b.markers[i].position_object_mm);
}

TEST(SimScenes, CatalogueBuildsAndHasTheRequiredScenes) {
    for (const char* required : {"two_cubes", "cube_sphere", "toy_car", "crowd", "stress"}) {
        bool listed = false;
        for (const SceneInfo& info : sceneCatalogue())
            listed = listed || std::string_view(info.name) == required;
        EXPECT_TRUE(listed) << required;
    }
    for (const SceneInfo& info : sceneCatalogue()) {
        const auto scene = makeScene(info.name, 3);
        ASSERT_TRUE(scene) << info.name;
        EXPECT_FALSE(scene->objects.empty()) << info.name;
        EXPECT_EQ(scene->description, info.description);
    }
    EXPECT_EQ(makeScene("crowd", 1)->objects.size(), 6u);
    EXPECT_FALSE(makeScene("no_such_scene", 1));
}

TEST(SimScenes, ObjectsStayInViewMostOfTheTime) {
    // Scenes are meant for tracking: each object must be visible to both cameras most of the time.
    for (const char* name : {"two_cubes", "cube_sphere", "toy_car", "crowd", "erratic_cube"}) {
        const World world(*makeScene(name, 1), 1);
        Observation obs;
        std::vector<int> framesWithFourMarkers(world.scene().objects.size(), 0);
        const int frames = 400;
        for (int f = 0; f < frames; f += 1) {
            world.observe(static_cast<std::uint64_t>(f * 5), obs);
            std::vector<int> seen(world.scene().objects.size(), 0);
            for (const MarkerView& m : obs.markers)
                if (m.visible[0] && m.visible[1])
                    ++seen[static_cast<std::size_t>(m.object)];
            for (std::size_t o = 0; o < seen.size(); ++o) {
                const auto enough =
                    std::min<std::size_t>(4, world.scene().objects[o].object.markers.size());
                framesWithFourMarkers[o] += static_cast<std::size_t>(seen[o]) >= enough ? 1 : 0;
            }
        }
        for (std::size_t o = 0; o < framesWithFourMarkers.size(); ++o)
            EXPECT_GT(framesWithFourMarkers[o], frames * 3 / 4) << name << " object " << o;
    }
}

TEST(SimMotion, IsAPureFunctionOfTime) {
    const Scene scene = *makeScene("erratic_cube", 9);
    const Motion& motion = scene.objects[0].motion;
    const RigidTransform a = motion.poseAt(1.234);
    motion.poseAt(7.0);
    const RigidTransform b = motion.poseAt(1.234);
    EXPECT_EQ(a.translation_mm, b.translation_mm);
    EXPECT_EQ(a.rotation.coeffs(), b.rotation.coeffs());
    // Another seed moves differently.
    const Scene other = *makeScene("erratic_cube", 10);
    EXPECT_NE(other.objects[0].motion.poseAt(1.234).translation_mm, a.translation_mm);
}

TEST(SimMotion, ErraticIsFasterThanSlow) {
    auto peakSpeed = [](const Motion& m) {
        double peak = 0.0;
        for (int i = 0; i < 2000; ++i) {
            const double t = i * 0.01;
            peak = std::max(
                peak,
                (m.poseAt(t + 0.01).translation_mm - m.poseAt(t).translation_mm).norm() / 0.01);
        }
        return peak;
    };
    const double slow = peakSpeed(makeScene("slow_cube", 1)->objects[0].motion);
    const double fast = peakSpeed(makeScene("erratic_cube", 1)->objects[0].motion);
    EXPECT_LT(slow, 150.0); // mm/s
    EXPECT_GT(fast, 2 * slow);
}

TEST(SimMotion, LeaveAndReturn) {
    const World world(*makeScene("leave_return", 1), 1);
    Observation obs;
    auto visibleMarkers = [&](double t_s) {
        world.observe(static_cast<std::uint64_t>(t_s * world.scene().frameRate_hz), obs);
        int n = 0;
        for (const MarkerView& m : obs.markers)
            n += (m.visible[0] || m.visible[1]) ? 1 : 0;
        return n;
    };
    EXPECT_GT(visibleMarkers(1.0), 4);
    EXPECT_EQ(visibleMarkers(4.5), 0);
    EXPECT_GT(visibleMarkers(7.0), 4);
}

TEST(SimVisibility, MarkersFacingAwayAreNotSeen) {
    Scene scene = *makeScene("slow_cube", 1);
    const World world(scene, 1);
    // Place the cube squarely in front of the cameras, unrotated: its -z face looks at them.
    const std::vector<RigidTransform> poses{
        RigidTransform{Quat::Identity(), Vec3(60.0, 0.0, 550.0)}};
    const MarkerObject& cube = world.scene().objects[0].object;
    int front = 0, back = 0;
    for (const SimMarker& m : cube.markers) {
        const Vec3 p = poses[0].apply(m.position_object_mm);
        const bool seen = world.markerVisible(p, m.normal_object, 0, 0, poses, {});
        if (m.normal_object.z() < -0.5) {
            EXPECT_TRUE(seen);
            ++front;
        }
        if (m.normal_object.z() > 0.5) {
            EXPECT_FALSE(seen);
            ++back;
        }
    }
    EXPECT_EQ(front, 5);
    EXPECT_EQ(back, 5);
}

TEST(SimVisibility, AHandInFrontHidesMarkers) {
    const World world(*makeScene("hand_occlusion", 1), 1);
    const std::vector<RigidTransform> poses{
        RigidTransform{Quat::Identity(), Vec3(60.0, 0.0, 550.0)}};
    int checked = 0;
    for (const SimMarker& m : world.scene().objects[0].object.markers) {
        if (m.normal_object.z() > -0.5)
            continue; // only the face toward the cameras
        const Vec3 p = poses[0].apply(m.position_object_mm);
        EXPECT_TRUE(world.markerVisible(p, m.normal_object, 0, 0, poses, {}));
        const Vec3 handBetween = 0.5 * (p + world.rig().camera(0).centre_rig_mm());
        EXPECT_FALSE(world.markerVisible(p, m.normal_object, 0, 0, poses, {handBetween}));
        ++checked;
    }
    EXPECT_EQ(checked, 5);
}

TEST(SimVisibility, OneObjectHidesAnother) {
    const World world(*makeScene("two_cubes", 1), 1);
    // The big cube right in front of camera 0, the small one behind it on the same line of sight.
    const std::vector<RigidTransform> poses{
        RigidTransform{Quat::Identity(), Vec3(0.0, 0.0, 400.0)},
        RigidTransform{Quat::Identity(), Vec3(0.0, 0.0, 650.0)}};
    int seen = 0;
    for (const SimMarker& m : world.scene().objects[1].object.markers) {
        const Vec3 p = poses[1].apply(m.position_object_mm);
        seen += world.markerVisible(p, m.normal_object, 0, 1, poses, {}) ? 1 : 0;
    }
    EXPECT_EQ(seen, 0);
}

TEST(SimWorld, ObservationIsDeterministicAndSpuriousReflectionsFlicker) {
    const World a(*makeScene("stress", 5), 5), b(*makeScene("stress", 5), 5);
    Observation oa, ob;
    std::size_t minGlints = 1000, maxGlints = 0;
    for (std::uint64_t f = 0; f < 50; ++f) {
        a.observe(f, oa);
        b.observe(f, ob);
        ASSERT_EQ(oa.markers.size(), ob.markers.size());
        for (std::size_t i = 0; i < oa.markers.size(); ++i)
            EXPECT_EQ(oa.markers[i].pixel[0], ob.markers[i].pixel[0]);
        ASSERT_EQ(oa.glints[0].size(), ob.glints[0].size());
        minGlints = std::min(minGlints, oa.glints[0].size());
        maxGlints = std::max(maxGlints, oa.glints[0].size());
    }
    EXPECT_GE(minGlints, 15u); // the static ones are always there
    EXPECT_GT(maxGlints, minGlints);
}
