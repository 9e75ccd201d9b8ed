// Stereo rigs of any build, drawn from a seed: the rigs quality runs sweep instead of our own.
#pragma once

#include <cstdint>

#include "hal/sim/scene.hpp"

namespace edgetrack::sim {

/**
 * \brief A stereo rig as people build them, drawn from \a seed (seed 0: the project's own rig,
 * the default RigSpec).
 *
 * Baseline 60 to 400 mm; axes converging by 0 to 25 degrees; the rig rolled by up to 20 degrees
 * and each sensor by up to 2 in its lens; focal length 500 to 1500 px with camera 1 up to 2%
 * off; images from 640 x 480 to 1600 x 1300; radial distortion of M12 lenses (barrel, k1 down to
 * -0.4 with the k2 and k3 that keep the mapping monotonic over the whole image); the scene's
 * centre 450 to 700 mm away; aperture 0.6 to 2 mm, focused at the scene's centre. A draw whose
 * scene centre does not lie in the middle 70% of both images (a narrow lens on a wide parallel
 * rig sees nothing in common) is drawn again: nobody builds that rig for this volume.
 */
RigSpec randomRig(std::uint64_t seed);

/// \brief Whether \a spec's distortion maps the radius out to the image's corners monotonically
/// (a lens model that folds the image back cannot be undistorted there).
bool monotonicOverImage(const RigSpec& spec);

} // namespace edgetrack::sim
