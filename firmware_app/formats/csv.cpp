// Strict reader and writer of the recordings' numeric CSV files (INTERFACES §1).
#include "firmware_app/formats/csv.hpp"

#include <charconv>
#include <cmath>
#include <fstream>
#include <sstream>
#include <system_error>

namespace edgetrack::recording {

namespace {

/// The largest integer a row's double holds exactly (2^53).
constexpr std::int64_t kMaxExactInteger = std::int64_t{1} << 53;

std::string_view trim(std::string_view s) {
    while (!s.empty() && (s.front() == ' ' || s.front() == '\t'))
        s.remove_prefix(1);
    while (!s.empty() && (s.back() == ' ' || s.back() == '\t' || s.back() == '\r'))
        s.remove_suffix(1);
    return s;
}

Error lineError(std::string_view name, std::size_t line, const std::string& what) {
    return Error{std::string(name) + ":" + std::to_string(line) + ": " + what};
}

std::string quoted(std::string_view field) {
    constexpr std::size_t kShown = 40;
    std::string s = "\"" + std::string(field.substr(0, kShown));
    if (field.size() > kShown)
        s += "...";
    return s + "\"";
}

std::string expectedHeader(std::span<const CsvColumn> columns) {
    std::string header;
    for (const CsvColumn& c : columns) {
        if (!header.empty())
            header += c.optional ? "[," : ",";
        header += c.name;
        if (c.optional)
            header += "]";
    }
    return header;
}

// Splits a line at commas into at most kMaxCsvColumns + 1 fields (one more reveals "too many").
std::size_t splitFields(std::string_view line,
                        std::array<std::string_view, kMaxCsvColumns + 1>& out) {
    std::size_t count = 0;
    while (true) {
        const std::size_t comma = line.find(',');
        out[count++] = trim(line.substr(0, comma));
        if (comma == std::string_view::npos || count == out.size())
            return count;
        line.remove_prefix(comma + 1);
    }
}

} // namespace

Result<CsvTable> parseCsv(std::string_view text, std::string_view name,
                          std::span<const CsvColumn> columns) {
    std::size_t required = 0;
    while (required < columns.size() && !columns[required].optional)
        ++required;

    // A UTF-8 byte order mark (spreadsheets write one) is no part of the header, as JSON readers
    // take it too.
    if (text.starts_with("\xEF\xBB\xBF"))
        text.remove_prefix(3);
    CsvTable table;
    std::size_t lineNumber = 0;
    bool headerSeen = false;
    std::array<std::string_view, kMaxCsvColumns + 1> fields;

    while (!text.empty()) {
        const std::size_t newline = text.find('\n');
        std::string_view line = text.substr(0, newline);
        text.remove_prefix(newline == std::string_view::npos ? text.size() : newline + 1);
        ++lineNumber;
        if (!line.empty() && line.back() == '\r')
            line.remove_suffix(1);

        if (!headerSeen) {
            headerSeen = true;
            const std::size_t n = splitFields(line, fields);
            bool matches = n >= required && n <= columns.size();
            for (std::size_t i = 0; matches && i < n; ++i)
                matches = fields[i] == columns[i].name;
            if (!matches)
                return lineError(name, lineNumber,
                                 "bad header " + quoted(line) + ", expected \"" +
                                     expectedHeader(columns) + "\"");
            table.columnCount = n;
            continue;
        }
        if (trim(line).empty()) {
            if (text.empty())
                break; // a final newline, or a blank last line, ends the file
            return lineError(name, lineNumber, "empty line");
        }

        const std::size_t n = splitFields(line, fields);
        if (n != table.columnCount)
            return lineError(name, lineNumber,
                             "expected " + std::to_string(table.columnCount) + " fields, found " +
                                 (n > columns.size() ? "more" : std::to_string(n)));
        CsvRow row;
        row.line = lineNumber;
        row.fieldCount = n;
        for (std::size_t i = 0; i < n; ++i) {
            const std::string_view field = fields[i];
            const char* first = field.data();
            const char* last = field.data() + field.size();
            const std::string column(columns[i].name);
            if (columns[i].type == ColumnType::Integer) {
                std::int64_t value = 0;
                const auto [end, ec] = std::from_chars(first, last, value);
                if (field.empty() || ec != std::errc{} || end != last)
                    return lineError(name, lineNumber,
                                     "field '" + column + "' is not an integer: " + quoted(field));
                // Rows hold doubles: an integer beyond 2^53 would not come back as itself (and
                // 2^63 - 1 comes back as 2^63, which no int64 holds).
                if (value > kMaxExactInteger || value < -kMaxExactInteger)
                    return lineError(name, lineNumber,
                                     "field '" + column +
                                         "' is out of range (at most 2^53): " + quoted(field));
                row.values[i] = static_cast<double>(value);
            } else {
                double value = 0.0;
                const auto [end, ec] = std::from_chars(first, last, value);
                if (field.empty() || ec != std::errc{} || end != last)
                    return lineError(name, lineNumber,
                                     "field '" + column + "' is not a number: " + quoted(field));
                if (!std::isfinite(value))
                    return lineError(name, lineNumber,
                                     "field '" + column + "' is " + quoted(field) +
                                         ": NaN and infinity are not allowed");
                row.values[i] = value;
            }
        }
        table.rows.push_back(row);
    }
    if (!headerSeen)
        return lineError(name, 1, "missing header, expected \"" + expectedHeader(columns) + "\"");
    return table;
}

Result<std::string> readTextFile(const std::filesystem::path& path) {
    std::error_code ec;
    // A directory opens as a stream on Linux and fails only at its first read.
    if (std::filesystem::is_directory(path, ec))
        return Error{path.string() + ": is a directory, not a file"};
    std::ifstream in(path, std::ios::binary);
    if (!in)
        return Error{path.string() + ": cannot open for reading"};
    std::ostringstream content;
    try {
        content << in.rdbuf();
    } catch (const std::exception& e) {
        return Error{path.string() + ": read error: " + e.what()};
    }
    if (in.bad() || (!content && in.peek() != std::ifstream::traits_type::eof()))
        return Error{path.string() + ": read error"};
    return content.str();
}

Result<CsvTable> readCsvFile(const std::filesystem::path& path,
                             std::span<const CsvColumn> columns) {
    Result<std::string> text = readTextFile(path);
    if (!text)
        return text.error();
    return parseCsv(*text, path.string(), columns);
}

namespace {

Status writeStream(const std::filesystem::path& path, std::string_view text,
                   std::ios::openmode mode) {
    std::ofstream out(path, std::ios::binary | mode);
    if (!out)
        return Error{path.string() + ": cannot open for writing"};
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
    out.flush();
    if (!out)
        return Error{path.string() + ": write error (disk full?)"};
    return Ok{};
}

} // namespace

Status writeTextFileAtomically(const std::filesystem::path& path, std::string_view text) {
    namespace fs = std::filesystem;
    std::error_code ec;
    // A symbolic link is followed: its target is the file replaced, and the link stays.
    fs::path target = path;
    if (fs::is_symlink(path, ec)) {
        target = fs::weakly_canonical(path, ec);
        if (ec)
            return Error{path.string() + ": cannot follow the link: " + ec.message()};
    }
    const fs::file_status status = fs::status(target, ec);
    if (fs::is_directory(status))
        return Error{path.string() + ": is a directory, not a file"};
    // A device or a FIFO (/dev/null, a pipe to another program) is written to, never replaced.
    if (fs::exists(status) && !fs::is_regular_file(status))
        return writeStream(target, text, std::ios::out);
    fs::path temporary = target;
    temporary += ".tmp";
    if (Status s = writeStream(temporary, text, std::ios::trunc); !s) {
        fs::remove(temporary, ec); // nothing half-written is left behind (a full disk)
        return s;
    }
    fs::rename(temporary, target, ec);
    if (ec) {
        const std::string message = ec.message();
        fs::remove(temporary, ec);
        return Error{path.string() + ": cannot replace: " + message};
    }
    return Ok{};
}

void appendNumber(std::string& out, double value) {
    std::array<char, 32> buffer;
    const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
    out.append(buffer.data(), result.ptr);
}

void appendNumber(std::string& out, std::int64_t value) {
    std::array<char, 24> buffer;
    const auto result = std::to_chars(buffer.data(), buffer.data() + buffer.size(), value);
    out.append(buffer.data(), result.ptr);
}

} // namespace edgetrack::recording
