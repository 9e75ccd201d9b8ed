// Typed, range-checked reading of one TOML table, with errors that name the file, line and key.
#include "firmware_app/formats/toml_table.hpp"

#include <sstream>

namespace edgetrack::recording {

void TomlTableReader::real(const char* key, double& value, double min, double max,
                           bool minExclusive) {
    const toml::node* node = find(key);
    if (node == nullptr)
        return;
    const std::optional<double> read = numberOf(*node);
    if (!read)
        return fail(*node, key, "expected a number");
    if (!std::isfinite(*read))
        return fail(*node, key, "NaN and infinity are not allowed");
    if (minExclusive ? *read <= min : *read < min)
        return fail(*node, key,
                    std::string(minExclusive ? "must be > " : "must be >= ") + show(min) +
                        " (got " + show(*read) + ")");
    if (*read > max)
        return fail(*node, key, "must be <= " + show(max) + " (got " + show(*read) + ")");
    value = *read;
}

void TomlTableReader::flag(const char* key, bool& value) {
    const toml::node* node = find(key);
    if (node == nullptr)
        return;
    if (!node->is_boolean())
        return fail(*node, key, "expected true or false");
    value = *node->value<bool>();
}

void TomlTableReader::text(const char* key, std::string& value, bool mayBeEmpty) {
    const toml::node* node = find(key);
    if (node == nullptr)
        return;
    if (!node->is_string())
        return fail(*node, key, "expected a string");
    std::string read = *node->value<std::string>();
    if (read.empty() && !mayBeEmpty)
        return fail(*node, key, "must not be empty");
    value = std::move(read);
}

void TomlTableReader::path(const char* key, std::filesystem::path& value) {
    std::string read = value.string();
    text(key, read, true);
    value = read;
}

const toml::node* TomlTableReader::find(const char* key) {
    known_.insert(key);
    if (error_ || table_ == nullptr)
        return nullptr;
    const toml::node* node = table_->get(key);
    if (node == nullptr && keys_ == Keys::Required)
        fail(*table_, key, "missing");
    return node;
}

void TomlTableReader::fail(const toml::node& node, const char* key, const std::string& what) {
    if (error_)
        return;
    error_ = Error{std::string(file_) + ":" + std::to_string(node.source().begin.line) + ": " +
                   label_ + key + ": " + what};
}

void TomlTableReader::require(bool condition, const char* key, const std::string& what) {
    if (condition || error_)
        return;
    const toml::node* node = table_ != nullptr ? table_->get(key) : nullptr;
    if (node != nullptr)
        fail(*node, key, what);
    else
        error_ = Error{std::string(file_) + ": " + label_ + key + ": " + what};
}

void TomlTableReader::refuseUnknownKeys() {
    if (table_ == nullptr || error_)
        return;
    for (const auto& [key, node] : *table_)
        if (!known_.contains(key.str()) && !subtables_.contains(key.str()))
            return fail(node, std::string(key.str()).c_str(), "unknown key");
}

std::optional<double> TomlTableReader::numberOf(const toml::node& node) {
    if (node.is_floating_point())
        return node.value<double>();
    if (node.is_integer())
        return static_cast<double>(*node.value<std::int64_t>());
    return std::nullopt;
}

std::string TomlTableReader::show(double v) {
    std::ostringstream out;
    out << v;
    return out.str();
}

} // namespace edgetrack::recording
