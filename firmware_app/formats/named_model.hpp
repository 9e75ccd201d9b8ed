// A marker model with the name its file or flash slot gives it.
#pragma once

#include <string>

#include "core/marker_model.hpp"

namespace edgetrack::app {

/// \brief A model as a file or the flash holds it: the model and its display name.
struct NamedModel {
    MarkerModel model;
    std::string name;
};

} // namespace edgetrack::app
