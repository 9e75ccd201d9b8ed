// Typed, range-checked reading of one TOML table, with errors that name the file, line and key.
#pragma once

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <string_view>

#include <toml++/toml.h>

#include "core/result.hpp"

namespace edgetrack::recording {

/**
 * \brief Reads one table's keys into typed values; the one reader of edgetrack.toml and rig.toml.
 *
 * Each call reads one key, checks its type and range and stores it; the first failure is kept in
 * the error given to the constructor (later calls then do nothing), as
 * `FILE:LINE: LABELkey: what`, e.g. `edgetrack.toml:12: [tracking] max_rms_mm: must be > 0 (got
 * -1)` or `rec/rig.toml:15: camera[1].fx: expected a number`. Missing keys keep their value
 * (Keys::Optional, settings with defaults) or fail (Keys::Required, measured data). Every key
 * asked for is remembered, so refuseUnknownKeys() can report a typo.
 */
class TomlTableReader {
public:
    enum class Keys : std::uint8_t { Optional, Required };

    /// \param label what precedes a key in messages: "[tracking] ", "camera[1]."
    /// \param table nothing when the file has no such table (every key then keeps its value).
    TomlTableReader(std::string_view file, std::string label, const toml::table* table,
                    std::optional<Error>& error, Keys keys = Keys::Optional)
        : file_(file)
        , label_(std::move(label))
        , table_(table)
        , error_(error)
        , keys_(keys) {}

    static constexpr double kNoLimit = std::numeric_limits<double>::max();

    /// \brief A finite number in [min, max] ((min, max] with \a minExclusive).
    void real(const char* key, double& value, double min = -kNoLimit, double max = kNoLimit,
              bool minExclusive = false);

    /// \brief An integer in [min, max].
    template <typename Integer>
    void integer(const char* key, Integer& value, std::int64_t min, std::int64_t max) {
        const toml::node* node = find(key);
        if (node == nullptr)
            return;
        if (!node->is_integer())
            return fail(*node, key, "expected an integer");
        const std::int64_t read = *node->value<std::int64_t>();
        if (read < min || read > max)
            return fail(*node, key,
                        "must be between " + std::to_string(min) + " and " + std::to_string(max) +
                            " (got " + std::to_string(read) + ")");
        value = static_cast<Integer>(read);
    }

    void flag(const char* key, bool& value);
    void text(const char* key, std::string& value, bool mayBeEmpty = false);
    void path(const char* key, std::filesystem::path& value);

    /// \brief An array of exactly N finite numbers.
    template <std::size_t N>
    void numbers(const char* key, std::array<double, N>& value) {
        const toml::node* node = find(key);
        if (node == nullptr)
            return;
        const toml::array* array = node->as_array();
        if (array == nullptr || array->size() != N)
            return fail(*node, key, "expected an array of " + std::to_string(N) + " numbers");
        std::array<double, N> read{};
        for (std::size_t i = 0; i < N; ++i) {
            const std::optional<double> number = numberOf(*array->get(i));
            if (!number)
                return fail(*array->get(i), key,
                            "element " + std::to_string(i) + " is not a number");
            if (!std::isfinite(*number))
                return fail(*array->get(i), key, "NaN and infinity are not allowed");
            read[i] = *number;
        }
        value = read;
    }

    /**
     * \brief The node of \a key for a reader of a type this class does not know, or nothing
     * (absent, or an error already); report what is wrong with it through fail().
     */
    const toml::node* find(const char* key);
    /// \brief Report \a what about \a key, at \a node's line (the first report wins).
    void fail(const toml::node& node, const char* key, const std::string& what);
    /// \brief A check of a key that was read (or across keys), reported at the key.
    void require(bool condition, const char* key, const std::string& what);
    /// \brief Report the first key of the table that no call above asked for.
    void refuseUnknownKeys();
    /// \brief A key that holds a sub-table read by another reader.
    void allowTable(std::string_view key) { subtables_.insert(std::string(key)); }

    bool failed() const { return error_.has_value(); }

private:
    static std::optional<double> numberOf(const toml::node& node);
    static std::string show(double v);

    std::string_view file_;
    std::string label_;
    const toml::table* table_;
    std::optional<Error>& error_;
    Keys keys_;
    std::set<std::string, std::less<>> known_;
    std::set<std::string, std::less<>> subtables_;
};

} // namespace edgetrack::recording
