// How a field calibration's learnt models join the models already on the board.
#pragma once

#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "core/marker_model.hpp"
#include "firmware_app/firmware/known_in_session.hpp"
#include "firmware_app/formats/named_model.hpp"

namespace edgetrack::app {

/// \brief The new model set and what happened to each learnt model.
struct MergedModels {
    std::vector<NamedModel> models;
    /// Per model: the index of the learnt model it is, or -1 for a known model kept as it was.
    std::vector<int> learntIndex;
    std::size_t added = 0;
    std::size_t updated = 0;
    /// Ids of known bodies learnt again whose new layout was not taken: it would track worse
    /// (fewer markers, or more needed in view to be found). The model from before stays.
    std::vector<std::uint32_t> kept;
    /// Learnt models whose layout is part of a body with more than twice their markers.
    std::size_t fragments = 0;
    /// Learnt models that did not fit \a maxModels.
    std::size_t refused = 0;
};

/**
 * \brief Merge \a learnt into \a known.
 *
 * A learnt model is a known body when \a sameObjects says so (the two were in one place in the
 * session: findKnownInSession), or else, for a body the session did not see, when it has that
 * body's layout (sameShape). It is then registered onto the known layout, so it keeps the body's
 * id, name and frame: what a host fixed to that frame stays where it was. It replaces the known
 * layout only when it would track no worse: at least as many markers, and an S_min no higher;
 * otherwise the known model stays and its id is listed in MergedModels::kept. Other learnt models
 * take the lowest free ids, up to \a maxModels. A learnt model whose layout is part of a learnt
 * or known model with more than twice its markers is a fragment of that body (a piece the
 * calibrator did not merge back, or a glimpse of a known body): tracked, it would be found inside
 * the body, so it is dropped. S_min and sameShapeAs are recomputed over the result, at the
 * tolerance the tracker pairs distances with (\a trackingTolerance_mm, ModelTrackingConfig's
 * distanceTolerance_mm, when below \a shape's): a wrong pose starts from four data points whose
 * distances agree with the model's within it, so layouts that differ by more cannot be taken
 * for each other, and a larger tolerance only asks for markers that are never in view together
 * (a 24-marker sphere: S_min 11 at 2 mm, 8 at 1 mm).
 * Allocates: it runs when a calibration ends, not per frame.
 */
MergedModels mergeLearntModels(std::span<const NamedModel> known,
                               std::span<const MarkerModel> learnt,
                               std::span<const SameObject> sameObjects, std::size_t maxModels,
                               const SminConfig& shape, double trackingTolerance_mm);

/**
 * \brief Why a learnt model will seldom or never be found, or nothing when it can be: the tracker
 * finds a body only with S_min of its markers in view, and a layout so regular that more are
 * needed than its session ever showed at once (\a mostSeenTogether, 0 when unknown) is seldom
 * in such a view. The text follows the model's name: "needs 11 of its markers ...".
 */
std::optional<std::string> seldomFindable(const MarkerModel& model, std::size_t mostSeenTogether);

/// \brief A deep copy (models own fixed-capacity storage and are move-only).
MarkerModel copyOf(const MarkerModel& model);
std::vector<NamedModel> copyOf(std::span<const NamedModel> models);

} // namespace edgetrack::app
