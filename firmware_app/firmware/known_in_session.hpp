// Which learnt model is which known body: where both were in the calibration session's frames.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <vector>

#include "core/marker_model.hpp"
#include "core/model_tracker.hpp"
#include "core/rigid_transform.hpp"
#include "core/session_buffer.hpp"

namespace edgetrack::app {

/// \brief Where a known body was last found while a calibration session ran: the board tracks its
/// known models beside the session, so it knows which object in view is which body.
struct KnownSighting {
    /// Index of the body's model in the known set.
    std::size_t known = 0;
    /// Time (s, the board's clock) of the session frame it was last found in.
    double time_s = 0.0;
    /// Its pose then: model frame (mm) to rig frame (mm).
    RigidTransform T_rig_from_model;
};

/// \brief A learnt model that is a known body, and the transform that registers it onto it.
struct SameObject {
    std::size_t known = 0;
    std::size_t learnt = 0;
    /// Maps the learnt model's frame (mm) onto the known model's frame (mm).
    RigidTransform T_known_from_learnt;
    /// Markers of the two that coincided in the frame that tied them.
    std::size_t sharedMarkers = 0;
};

/// \brief Markers of a learnt layout paired with markers of a known one, each in its own frame
/// (mm).
struct MarkerPairs {
    std::vector<Vec3> learnt_mm;
    std::vector<Vec3> known_mm;
};

/**
 * \brief The markers of \a learnt that \a T_known_from_learnt puts within \a tolerance_mm of a
 * marker of \a known, each paired with the nearest known marker not taken by an earlier one: what
 * a registration of the one layout onto the other is fitted over.
 */
MarkerPairs coincidingMarkers(const MarkerModel& learnt, const MarkerModel& known,
                              const RigidTransform& T_known_from_learnt, double tolerance_mm);

/**
 * \brief Tie learnt models to the known bodies they are, by position, not by shape.
 *
 * A known body and a learnt model are one object when, at the session frame where the body was
 * last found, the learnt model (followed over the half second before that frame by a tracker of
 * the learnt models) puts at least three of its markers, off one line, within \a tolerance_mm of
 * the body's markers as its pose placed them. Two identical objects are so told apart, and a
 * layout learnt with other markers than before is still the object it is. The transform is fitted
 * over the coinciding markers in the two models' own frames, so the learnt layout can be expressed
 * in the known model's frame. Each known body and each learnt model takes part in one pair at
 * most, the pairs with more shared markers first. Allocates: it runs when a calibration ends.
 */
std::vector<SameObject>
findKnownInSession(const SessionBuffer& frames, std::span<const MarkerModel> known,
                   std::span<const KnownSighting> sightings, std::span<const MarkerModel> learnt,
                   const ModelTrackingConfig& tracking, double tolerance_mm);

} // namespace edgetrack::app
