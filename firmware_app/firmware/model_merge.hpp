// How a field calibration's learnt models join the models already on the board.
#pragma once

#include <cstddef>
#include <span>
#include <vector>

#include "core/marker_model.hpp"
#include "firmware_app/formats/named_model.hpp"

namespace edgetrack::app {

/// \brief The new model set and what happened to each learnt model.
struct MergedModels {
    std::vector<NamedModel> models;
    /// Per model: the index of the learnt model it is, or -1 for a known model kept as it was.
    std::vector<int> learntIndex;
    std::size_t added = 0;
    std::size_t updated = 0;
    /// Learnt models whose layout is part of a body with more than twice their markers.
    std::size_t fragments = 0;
    /// Learnt models that did not fit \a maxModels.
    std::size_t refused = 0;
};

/**
 * \brief Merge \a learnt into \a known.
 *
 * A learnt model with the layout of a known one (sameShape) replaces it under the known id, so a
 * host's body numbers survive a recalibration; other learnt models take the lowest free ids, up to
 * \a maxModels. A learnt model whose layout is part of a learnt or known model with more than
 * twice its markers is a fragment of that body (a piece the calibrator did not merge back, or a
 * glimpse of a known body): tracked, it would be found inside the body, and it must not replace
 * the whole body's model, so it is dropped. S_min and sameShapeAs are recomputed over the result.
 * Allocates: it runs when a calibration ends, not per frame.
 */
MergedModels mergeLearntModels(std::span<const NamedModel> known,
                               std::span<const MarkerModel> learnt, std::size_t maxModels,
                               const SminConfig& shape);

/// \brief A deep copy (models own fixed-capacity storage and are move-only).
MarkerModel copyOf(const MarkerModel& model);
std::vector<NamedModel> copyOf(std::span<const NamedModel> models);

} // namespace edgetrack::app
