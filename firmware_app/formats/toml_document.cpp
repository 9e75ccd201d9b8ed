// TOML documents (edgetrack.toml, rig.toml) parsed with one error format.
#include "firmware_app/formats/toml_document.hpp"

#include <string>

namespace edgetrack::recording {

Result<toml::table> parseTomlDocument(std::string_view text, std::string_view name) {
    toml::parse_result parsed = toml::parse(text, name);
    if (!parsed) {
        const toml::parse_error& e = parsed.error();
        return Error{std::string(name) + ":" + std::to_string(e.source().begin.line) + ": " +
                     std::string(e.description())};
    }
    return std::move(parsed).table();
}

} // namespace edgetrack::recording
