// Random marker objects and scenes, so that calibration is measured on objects nobody picked.
#pragma once

#include <cstdint>
#include <span>

#include "hal/sim/scene.hpp"

namespace edgetrack::sim {

/// \brief The shapes random objects are drawn from.
enum class ObjectFamily : std::uint8_t {
    Ellipsoid, ///< markers on an ellipsoid's surface, facing outward
    Plate,     ///< markers on the top of a flat plate, a few on its rim
    Ring,      ///< a ring (or two) of markers around a cylinder
    Posts,     ///< markers on the tops of posts of different heights on a base
    Star,      ///< markers on the tips of spokes pointing every way
    Box,       ///< a box with a few markers per face
    Car,       ///< a car-like body with a cabin
};

/// \return the family's name ("ellipsoid", "plate", ...).
const char* familyName(ObjectFamily family);
/// \return every family, in declaration order.
std::span<const ObjectFamily> allFamilies();

/**
 * \brief A random rigid object of \a family with about \a markerCount markers (4 to 40).
 *
 * Markers stand at least 12 mm apart (so that their blobs separate at the working distance) and
 * are seen within a cone of 90 to 150 degrees about their normals; size, proportions and layout
 * come from \a seed. When the shape has no room for \a markerCount markers it carries fewer, never
 * fewer than four.
 */
MarkerObject makeRandomObject(ObjectFamily family, int markerCount, std::uint64_t seed);

/**
 * \brief A scene of \a objectCount random objects (1 to 4), everything drawn from \a seed:
 * families, marker counts (4 to 40, more often few), visibility cones, motions (slow turns, at
 * times erratic), a hand passing in front (in half the scenes), spurious reflections (in a third)
 * and point noise of 0.05 to 0.3 mm.
 */
Scene makeRandomScene(int objectCount, std::uint64_t seed);

} // namespace edgetrack::sim
