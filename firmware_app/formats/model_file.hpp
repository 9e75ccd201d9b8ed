// Model files (INTERFACES §4): one JSON file per rigid body, MODELDIR/body_<id>.json.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/marker_model.hpp"
#include "core/result.hpp"
#include "firmware_app/formats/named_model.hpp"

namespace edgetrack::app {

/// \return MODELDIR/body_<id>.json
std::filesystem::path modelPath(const std::filesystem::path& directory, std::uint32_t id);

/// \brief Write \a model as JSON (marker coordinates in mm to 1e-4 mm).
Status writeModelJson(const std::filesystem::path& path, const MarkerModel& model,
                      std::string_view name);

/**
 * \brief Read and check one model file: markers are finite triples, edges join two different
 * markers that exist, s_min is between 3 and the number of markers, and there are at most
 * \a maxMarkers markers.
 * \return the model, or a one-line error naming the file and what is wrong.
 */
Result<NamedModel> readModelJson(const std::filesystem::path& path, std::size_t maxMarkers);
Result<NamedModel> parseModelJson(std::string_view text, std::string_view name,
                                  std::size_t maxMarkers);

/// \brief Every body_*.json of \a directory, ordered by id; ids must be unique.
Result<std::vector<NamedModel>> readModelDirectory(const std::filesystem::path& directory,
                                                   std::size_t maxMarkers);

} // namespace edgetrack::app
