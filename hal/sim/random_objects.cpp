// Random marker objects and scenes, so that calibration is measured on objects nobody picked.
#include "hal/sim/random_objects.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <numbers>
#include <string>

#include "hal/sim/random.hpp"

namespace edgetrack::sim {

namespace {

constexpr double kPi = std::numbers::pi;
/// Markers closer than this would merge into one blob at the far end of the working volume.
constexpr double kMinSpacing_mm = 12.0;

constexpr std::array<ObjectFamily, 7> kFamilies{
    ObjectFamily::Ellipsoid, ObjectFamily::Plate, ObjectFamily::Ring, ObjectFamily::Posts,
    ObjectFamily::Star,      ObjectFamily::Box,   ObjectFamily::Car};

Vec3 randomDirection(Random& random) {
    const double z = random.uniform(-1.0, 1.0);
    const double azimuth = random.uniform(0.0, 2.0 * kPi);
    const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
    return {r * std::cos(azimuth), r * std::sin(azimuth), z};
}

/// A marker candidate from a shape at a given scale: position and outward normal (object frame).
using Sampler = std::function<SimMarker(Random&, double scale)>;

/// Draws markers from \a sample until \a count stand kMinSpacing_mm apart; when the shape is too
/// small for them, grows it (scale) a few times, and in the end keeps what fits.
std::vector<SimMarker> place(Random& random, int count, const Sampler& sample, double& scale) {
    std::vector<SimMarker> markers;
    for (int growth = 0; growth < 6; ++growth) {
        markers.clear();
        for (int attempt = 0; attempt < 4000 && static_cast<int>(markers.size()) < count;
             ++attempt) {
            const SimMarker m = sample(random, scale);
            const bool apart = std::all_of(markers.begin(), markers.end(), [&](const SimMarker& o) {
                return (o.position_object_mm - m.position_object_mm).norm() >= kMinSpacing_mm;
            });
            if (apart)
                markers.push_back(m);
        }
        if (static_cast<int>(markers.size()) == count)
            break;
        scale *= 1.15;
    }
    return markers;
}

MarkerObject ellipsoid(Random& random, int count) {
    const double axisZ = random.uniform(0.45, 1.0);
    const double axisY = random.uniform(0.55, 1.0);
    const Vec3 axes = random.uniform(22.0, 45.0) * Vec3(1.0, axisY, axisZ);
    double scale = std::max(1.0, std::sqrt(count / 14.0));
    const Sampler sample = [&axes](Random& r, double s) {
        const Vec3 u = randomDirection(r);
        const Vec3 a = s * axes;
        const Vec3 p = a.cwiseProduct(u);
        const Vec3 normal = p.cwiseQuotient(a.cwiseProduct(a)).normalized();
        return SimMarker{p, normal};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    o.bodyBoxes.push_back({Vec3::Zero(), 0.55 * scale * axes});
    return o;
}

MarkerObject plate(Random& random, int count) {
    const double halfZ = random.uniform(2.0, 5.0);
    const double halfY = random.uniform(20.0, 45.0);
    const Vec3 half(random.uniform(30.0, 70.0), halfY, halfZ);
    double scale = std::max(1.0, std::sqrt(count / 16.0));
    const Sampler sample = [&half](Random& r, double s) {
        const Vec3 h(s * half.x(), s * half.y(), half.z());
        if (r.chance(0.8)) {
            // On the top, some on short stand-offs, so the layout is not always one plane.
            const double standOff = r.chance(0.3) ? r.uniform(5.0, 15.0) : 0.0;
            const double y = r.uniform(-h.y() + 4.0, h.y() - 4.0);
            const double x = r.uniform(-h.x() + 4.0, h.x() - 4.0);
            return SimMarker{Vec3(x, y, h.z() + standOff), Vec3::UnitZ()};
        }
        // On the rim, facing out.
        const bool alongX = r.chance(0.5);
        const double sign = r.chance(0.5) ? 1.0 : -1.0;
        if (alongX)
            return SimMarker{Vec3(r.uniform(-h.x() + 4.0, h.x() - 4.0), sign * h.y(), 0.0),
                             sign * Vec3::UnitY()};
        return SimMarker{Vec3(sign * h.x(), r.uniform(-h.y() + 4.0, h.y() - 4.0), 0.0),
                         sign * Vec3::UnitX()};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    o.bodyBoxes.push_back({Vec3::Zero(), Vec3(scale * half.x(), scale * half.y(), half.z())});
    return o;
}

MarkerObject ring(Random& random, int count) {
    const double radius = random.uniform(20.0, 40.0);
    const double halfHeight = random.uniform(8.0, 40.0);
    double scale = std::max(1.0, std::sqrt(count / 12.0));
    const Sampler sample = [radius, halfHeight](Random& r, double s) {
        const double angle = r.uniform(0.0, 2.0 * kPi);
        const Vec3 normal(std::cos(angle), std::sin(angle), 0.0);
        return SimMarker{s * radius * normal +
                             Vec3(0.0, 0.0, r.uniform(-halfHeight, halfHeight) * std::sqrt(s)),
                         normal};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    const double inner = 0.68 * scale * radius;
    o.bodyBoxes.push_back({Vec3::Zero(), Vec3(inner, inner, halfHeight * std::sqrt(scale))});
    return o;
}

MarkerObject posts(Random& random, int count) {
    const double baseY = random.uniform(30.0, 55.0);
    const Vec3 base(random.uniform(35.0, 60.0), baseY, 4.0);
    double scale = std::max(1.0, std::sqrt(count / 12.0));
    const Sampler sample = [&base](Random& r, double s) {
        const double height = r.uniform(12.0, 70.0);
        const double footY = r.uniform(-s * base.y(), s * base.y());
        const Vec3 foot(r.uniform(-s * base.x(), s * base.x()), footY, base.z());
        // A disc on the post's top, tilted a little from straight up.
        const Vec3 tilt = 0.5 * randomDirection(r);
        return SimMarker{foot + Vec3(0.0, 0.0, height), (Vec3::UnitZ() + tilt).normalized()};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    o.bodyBoxes.push_back({Vec3::Zero(), Vec3(scale * base.x(), scale * base.y(), base.z())});
    return o;
}

MarkerObject star(Random& random, int count) {
    double scale = std::max(1.0, std::sqrt(count / 16.0));
    const Sampler sample = [](Random& r, double s) {
        const Vec3 direction = randomDirection(r);
        return SimMarker{s * r.uniform(28.0, 52.0) * direction, direction};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    o.bodyRadius_mm = 12.0;
    return o;
}

MarkerObject box(Random& random, int count) {
    const double halfZ = random.uniform(10.0, 30.0);
    const double halfY = random.uniform(15.0, 40.0);
    const Vec3 half(random.uniform(20.0, 50.0), halfY, halfZ);
    double scale = std::max(1.0, std::sqrt(count / 18.0));
    const Sampler sample = [&half](Random& r, double s) {
        const Vec3 h = s * half;
        // A face chosen in proportion to its area.
        const std::array<double, 3> area{h.y() * h.z(), h.x() * h.z(), h.x() * h.y()};
        const double pick = r.uniform(0.0, area[0] + area[1] + area[2]);
        const int axis = pick < area[0] ? 0 : (pick < area[0] + area[1] ? 1 : 2);
        const double sign = r.chance(0.5) ? 1.0 : -1.0;
        Vec3 p;
        for (int k = 0; k < 3; ++k)
            p[k] = k == axis ? sign * h[k] : r.uniform(-h[k] + 4.0, h[k] - 4.0);
        Vec3 normal = Vec3::Zero();
        normal[axis] = sign;
        return SimMarker{p, normal};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    o.bodyBoxes.push_back({Vec3::Zero(), scale * half});
    return o;
}

MarkerObject car(Random& random, int count) {
    const double length = random.uniform(45.0, 80.0);
    const double bodyZ = random.uniform(12.0, 22.0);
    const Vec3 body(length, length * random.uniform(0.38, 0.5), bodyZ);
    const double cabinZ = random.uniform(8.0, 14.0);
    const Vec3 cabin(body.x() * random.uniform(0.35, 0.55), body.y() * 0.85, cabinZ);
    double scale = std::max(1.0, std::sqrt(count / 24.0));
    const Sampler sample = [&body, &cabin](Random& r, double s) {
        const Vec3 b = s * body;
        const Vec3 c = s * cabin;
        const Vec3 cabinCentre(-0.1 * b.x(), 0.0, b.z() + c.z());
        // Hood and trunk, sides, roof, cabin sides: the surfaces someone would stick markers on.
        const double pick = r.uniform();
        if (pick < 0.3) {
            const double y = r.uniform(-b.y() + 4.0, b.y() - 4.0);
            const double x = r.uniform(-b.x() + 4.0, b.x() - 4.0);
            return SimMarker{Vec3(x, y, b.z()), Vec3::UnitZ()};
        }
        if (pick < 0.65) {
            const double sign = r.chance(0.5) ? 1.0 : -1.0;
            const double z = r.uniform(-b.z() + 3.0, b.z() - 3.0);
            const double x = r.uniform(-b.x() + 4.0, b.x() - 4.0);
            return SimMarker{Vec3(x, sign * b.y(), z), sign * Vec3::UnitY()};
        }
        if (pick < 0.75) {
            const double sign = r.chance(0.5) ? 1.0 : -1.0;
            return SimMarker{Vec3(sign * b.x(), r.uniform(-b.y() + 4.0, b.y() - 4.0),
                                  r.uniform(-b.z() + 3.0, b.z() - 3.0)),
                             sign * Vec3::UnitX()};
        }
        if (pick < 0.9)
            return SimMarker{cabinCentre + Vec3(r.uniform(-c.x() + 3.0, c.x() - 3.0),
                                                r.uniform(-c.y() + 3.0, c.y() - 3.0), c.z()),
                             Vec3::UnitZ()};
        const double sign = r.chance(0.5) ? 1.0 : -1.0;
        return SimMarker{cabinCentre + Vec3(r.uniform(-c.x() + 3.0, c.x() - 3.0), sign * c.y(),
                                            r.uniform(-c.z() + 2.0, c.z() - 2.0)),
                         sign * Vec3::UnitY()};
    };
    MarkerObject o;
    o.markers = place(random, count, sample, scale);
    o.bodyBoxes.push_back({Vec3::Zero(), scale * body});
    o.bodyBoxes.push_back(
        {Vec3(-0.1 * scale * body.x(), 0.0, scale * (body.z() + cabin.z())), scale * cabin});
    return o;
}

double radiusOf(const MarkerObject& object) {
    double r = 0.0;
    for (const SimMarker& m : object.markers)
        r = std::max(r, m.position_object_mm.norm());
    return r;
}

} // namespace

const char* familyName(ObjectFamily family) {
    switch (family) {
    case ObjectFamily::Ellipsoid:
        return "ellipsoid";
    case ObjectFamily::Plate:
        return "plate";
    case ObjectFamily::Ring:
        return "ring";
    case ObjectFamily::Posts:
        return "posts";
    case ObjectFamily::Star:
        return "star";
    case ObjectFamily::Box:
        return "box";
    case ObjectFamily::Car:
        return "car";
    }
    return "?";
}

std::span<const ObjectFamily> allFamilies() {
    return kFamilies;
}

MarkerObject makeRandomObject(ObjectFamily family, int markerCount, std::uint64_t seed) {
    Random random(seed);
    const int count = std::clamp(markerCount, 4, 40);
    MarkerObject o;
    switch (family) {
    case ObjectFamily::Ellipsoid:
        o = ellipsoid(random, count);
        break;
    case ObjectFamily::Plate:
        o = plate(random, count);
        break;
    case ObjectFamily::Ring:
        o = ring(random, count);
        break;
    case ObjectFamily::Posts:
        o = posts(random, count);
        break;
    case ObjectFamily::Star:
        o = star(random, count);
        break;
    case ObjectFamily::Box:
        o = box(random, count);
        break;
    case ObjectFamily::Car:
        o = car(random, count);
        break;
    }
    o.name = std::string(familyName(family)) + std::to_string(o.markers.size());
    o.markerDiameter_mm = random.uniform(5.0, 8.0);
    // Visible within a cone of 90 to 150 degrees about the normal: flat retroreflective foil on
    // a curved face to half-sphere markers. (Narrower cones left a third of the objects never
    // showing four markers at once: nothing a user could train, and nothing a test learns from.)
    o.minFacingCosine = std::cos(random.uniform(45.0, 75.0) * kPi / 180.0);
    return o;
}

Scene makeRandomScene(int objectCount, std::uint64_t seed) {
    Random random(seed * 7919 + 17);
    Scene scene;
    const int count = std::clamp(objectCount, 1, 4);
    std::vector<MarkerObject> objects;
    double largest_mm = 0.0;
    for (int k = 0; k < count; ++k) {
        const ObjectFamily family = kFamilies[random.below(kFamilies.size())];
        // 4 to 40 markers, small counts more often: they are the hard cases for S_min and poses.
        const int markers = 4 + static_cast<int>(36.0 * std::pow(random.uniform(), 1.6));
        objects.push_back(makeRandomObject(family, markers, random.next()));
        largest_mm = std::max(largest_mm, radiusOf(objects.back()));
    }
    // Objects side by side (a row, or two rows of two), far enough apart not to pass through
    // each other, as people hold them.
    const double midline = 0.5 * scene.rig.baseline_mm;
    const double spacing = std::max(140.0, 2.0 * largest_mm + 30.0);
    const double depth = random.uniform(520.0, 640.0);
    for (int k = 0; k < count; ++k) {
        Vec3 centre(midline, 0.0, depth);
        if (count == 2)
            centre.x() += (k == 0 ? -0.5 : 0.5) * spacing;
        else if (count == 3)
            centre.x() += (k - 1) * spacing;
        else if (count == 4)
            centre +=
                Vec3((k % 2 == 0 ? -0.5 : 0.5) * spacing, (k < 2 ? -0.5 : 0.5) * spacing, 0.0);
        MotionSpec m;
        m.centre_rig_mm = centre;
        const double wander = count == 1 ? 45.0 : 25.0;
        m.wanderAmplitude_mm = {wander, 0.8 * wander, wander};
        m.spinRate_radps = random.uniform(0.35, 0.8);
        m.tumbleRate_radps = random.uniform(0.15, 0.4);
        m.erraticShare = 0.0;
        if (random.chance(0.3)) {
            m.erraticShare = 0.3;
            m.shakeAmplitude_mm = 10.0;
            m.shakeAmplitude_rad = 0.2;
        }
        scene.objects.push_back({std::move(objects[static_cast<std::size_t>(k)]),
                                 Motion(m, seed * 1000 + static_cast<std::uint64_t>(k) + 1)});
    }
    if (random.chance(0.5)) {
        // Drawn one after the other, in this order: the seed's scene stays the same.
        const Vec3 centre(midline, random.uniform(-30.0, 30.0), depth - 100.0);
        const double frequency_hz = random.uniform(0.1, 0.2);
        const MotionSpec hand = passingHand(centre, frequency_hz);
        scene.occluders.push_back({Motion(hand, seed * 1000 + 99), random.uniform(30.0, 45.0)});
    }
    if (random.chance(1.0 / 3.0))
        scene.spurious = {static_cast<int>(random.below(5)), static_cast<int>(random.below(5)), 0.3,
                          1 + static_cast<int>(random.below(4))};
    scene.pointNoise_mm = random.uniform(0.05, 0.3);
    return scene;
}

} // namespace edgetrack::sim
