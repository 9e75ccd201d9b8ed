// Strict reader and writer of the recordings' numeric CSV files (INTERFACES §1).
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.hpp"

namespace edgetrack::recording {

enum class ColumnType { Integer, Real };

/// \brief One expected column; optional columns may only come last.
struct CsvColumn {
    std::string_view name;
    ColumnType type = ColumnType::Real;
    bool optional = false;
};

/// \brief Upper bound on columns of any recording file (truth.csv has ten).
inline constexpr std::size_t kMaxCsvColumns = 12;

/// \brief One parsed data row: every field is a finite number (integers are exact in a double).
struct CsvRow {
    std::size_t line = 0;
    std::size_t fieldCount = 0;
    std::array<double, kMaxCsvColumns> values{};

    double operator[](std::size_t column) const { return values[column]; }
    std::int64_t integer(std::size_t column) const {
        return static_cast<std::int64_t>(values[column]);
    }
};

/// \brief A whole file: which optional columns its header has, and its rows.
struct CsvTable {
    std::size_t columnCount = 0;
    std::vector<CsvRow> rows;
};

/**
 * \brief Parse CSV text whose header must be exactly \a columns (the optional tail may be absent).
 *
 * Fields are comma separated, `.` decimals; spaces around a field and a CR before the newline are
 * tolerated; empty lines are not. Every error is one line that starts with "<name>:<line>: ".
 */
Result<CsvTable> parseCsv(std::string_view text, std::string_view name,
                          std::span<const CsvColumn> columns);

/// \brief Read and parse a CSV file; the error names the file's path.
Result<CsvTable> readCsvFile(const std::filesystem::path& path, std::span<const CsvColumn> columns);

/// \brief Read a whole file into a string; the error names the path.
Result<std::string> readTextFile(const std::filesystem::path& path);

/// \brief Write \a text to \a path through a temporary file and a rename, so readers never see a
/// half-written file.
Status writeTextFileAtomically(const std::filesystem::path& path, std::string_view text);

/// \brief Append the shortest decimal text that reads back as exactly \a value.
void appendNumber(std::string& out, double value);
void appendNumber(std::string& out, std::int64_t value);

/// \brief Append a whole CSV line of numbers followed by '\n'.
template <typename... Numbers>
void appendCsvLine(std::string& out, Numbers... values) {
    bool first = true;
    auto one = [&](auto value) {
        if (!first)
            out += ',';
        first = false;
        appendNumber(out, value);
    };
    (one(values), ...);
    out += '\n';
}

} // namespace edgetrack::recording
