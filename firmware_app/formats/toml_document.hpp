// TOML documents (edgetrack.toml, rig.toml) parsed with one error format.
#pragma once

#include <string_view>

#include <toml++/toml.h>

#include "core/result.hpp"

namespace edgetrack::recording {

/**
 * \brief Parse \a text as a TOML document.
 * \return the root table, or one line "<name>:<line>: <what>".
 *
 * toml++ is built without its internal assertions (cmake/toml_implementation.cpp): malformed
 * text is a parse error in every build type, never an abort.
 */
Result<toml::table> parseTomlDocument(std::string_view text, std::string_view name);

} // namespace edgetrack::recording
