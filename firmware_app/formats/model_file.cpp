// Model files: JSON through nlohmann/json, checked field by field with one-line errors.
#include "firmware_app/formats/model_file.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>

#include "firmware_app/formats/csv.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;
using nlohmann::json;

fs::path modelPath(const fs::path& directory, std::uint32_t id) {
    return directory / ("body_" + std::to_string(id) + ".json");
}

namespace {

std::string number(double value) {
    char buffer[32];
    std::snprintf(buffer, sizeof buffer, "%.4f", value);
    return buffer;
}

} // namespace

Status writeModelJson(const fs::path& path, const MarkerModel& model, std::string_view name) {
    // Written by hand rather than by json::dump so that each marker and edge is one line and the
    // numbers keep a fixed precision: the files are read and compared by people too.
    std::ostringstream out;
    out << "{ \"id\": " << model.id << ", \"name\": " << json(std::string(name)).dump() << ",\n";
    out << "  \"markers\": [";
    for (std::size_t i = 0; i < model.markers_model_mm.size(); ++i) {
        const Vec3& m = model.markers_model_mm[i];
        out << (i == 0 ? "\n    " : ",\n    ") << "[" << number(m.x()) << ", " << number(m.y())
            << ", " << number(m.z()) << "]";
    }
    out << "\n  ],\n  \"edges\": [";
    for (std::size_t i = 0; i < model.edges.size(); ++i) {
        const ModelEdge& e = model.edges[i];
        out << (i == 0 ? "\n    " : ",\n    ") << "[" << e.from << ", " << e.to << ", "
            << number(e.distance_mm) << "]";
    }
    out << "\n  ],\n  \"s_min\": " << model.sMin << " }\n";
    // Through a temporary file: a full disk leaves the old file, never an empty one.
    return recording::writeTextFileAtomically(path, out.str());
}

Result<NamedModel> parseModelJson(std::string_view text, std::string_view name,
                                  std::size_t maxMarkers) {
    const std::string where(name);
    auto fail = [&](const std::string& message) -> Result<NamedModel> {
        return Error{where + ": " + message};
    };
    json document;
    try {
        document = json::parse(text);
    } catch (const json::exception& e) {
        // e.what() reads "[json.exception.parse_error.101] parse error at line 2, column 5: ...",
        // or, for a number too large for a double, "[json.exception.out_of_range.406] number
        // overflow parsing '1E999'" (found by tests/fuzz): the part after the bracket.
        const std::string what = e.what();
        const std::size_t at = what.find("] ");
        return fail(at == std::string::npos ? what : what.substr(at + 2));
    }
    if (!document.is_object())
        return fail("not a JSON object");
    for (const char* key : {"id", "markers", "edges", "s_min"})
        if (!document.contains(key))
            return fail(std::string("missing \"") + key + "\"");
    const json& id = document["id"];
    if (!id.is_number_unsigned() || id.get<std::uint64_t>() > 0xffffffffu)
        return fail("\"id\" is not a non-negative integer");
    const json& markers = document["markers"];
    if (!markers.is_array() || markers.size() < 3)
        return fail("\"markers\" is not an array of at least 3 markers");
    if (markers.size() > maxMarkers)
        return fail(std::to_string(markers.size()) + " markers; at most " +
                    std::to_string(maxMarkers) + " fit");

    NamedModel out;
    out.model = MarkerModel(maxMarkers);
    out.model.id = id.get<std::uint32_t>();
    out.name = "body " + std::to_string(out.model.id);
    if (document.contains("name")) {
        if (!document["name"].is_string())
            return fail("\"name\" is not a string");
        out.name = document["name"].get<std::string>();
    }
    for (std::size_t i = 0; i < markers.size(); ++i) {
        const json& m = markers[i];
        if (!m.is_array() || m.size() != 3 ||
            !std::all_of(m.begin(), m.end(), [](const json& v) { return v.is_number(); }))
            return fail("marker " + std::to_string(i) + " is not [x, y, z]");
        const Vec3 p(m[0].get<double>(), m[1].get<double>(), m[2].get<double>());
        if (!p.allFinite())
            return fail("marker " + std::to_string(i) + " is not finite");
        out.model.markers_model_mm.push_back(p);
    }
    const json& edges = document["edges"];
    if (!edges.is_array())
        return fail("\"edges\" is not an array");
    for (std::size_t k = 0; k < edges.size(); ++k) {
        const json& e = edges[k];
        const std::string which = "edge " + std::to_string(k);
        if (!e.is_array() || e.size() != 3 || !e[0].is_number_unsigned() ||
            !e[1].is_number_unsigned() || !e[2].is_number())
            return fail(which + " is not [i, j, distance_mm]");
        const auto i = e[0].get<std::uint64_t>(), j = e[1].get<std::uint64_t>();
        const double d = e[2].get<double>();
        if (i >= markers.size() || j >= markers.size() || i == j)
            return fail(which + " joins markers " + std::to_string(i) + " and " +
                        std::to_string(j) + " of " + std::to_string(markers.size()));
        if (!std::isfinite(d) || d < 0.0)
            return fail(which + " has a bad distance");
        if (!out.model.edges.push_back({static_cast<std::uint16_t>(std::min(i, j)),
                                        static_cast<std::uint16_t>(std::max(i, j)), d}))
            return fail("more edges than pairs of markers");
    }
    const json& sMin = document["s_min"];
    if (!sMin.is_number_unsigned() || sMin.get<std::uint64_t>() < 3 ||
        sMin.get<std::uint64_t>() > markers.size())
        return fail("\"s_min\" is not between 3 and the number of markers");
    out.model.sMin = sMin.get<std::uint32_t>();
    return out;
}

Result<NamedModel> readModelJson(const fs::path& path, std::size_t maxMarkers) {
    Result<std::string> text = recording::readTextFile(path);
    if (!text)
        return text.error();
    return parseModelJson(*text, path.string(), maxMarkers);
}

Result<std::vector<NamedModel>> readModelDirectory(const fs::path& directory,
                                                   std::size_t maxMarkers) {
    std::error_code ec;
    if (!fs::is_directory(directory, ec))
        return Error{directory.string() + ": not a model directory"};
    std::vector<fs::path> files;
    for (const fs::directory_entry& entry : fs::directory_iterator(directory, ec)) {
        const std::string file = entry.path().filename().string();
        if (file.rfind("body_", 0) == 0 && entry.path().extension() == ".json")
            files.push_back(entry.path());
    }
    if (ec)
        return Error{directory.string() + ": cannot list: " + ec.message()};
    std::vector<NamedModel> models;
    for (const fs::path& file : files) {
        Result<NamedModel> model = readModelJson(file, maxMarkers);
        if (!model)
            return model.error();
        models.push_back(std::move(*model));
    }
    std::sort(models.begin(), models.end(),
              [](const NamedModel& a, const NamedModel& b) { return a.model.id < b.model.id; });
    for (std::size_t i = 1; i < models.size(); ++i)
        if (models[i].model.id == models[i - 1].model.id)
            return Error{directory.string() + ": two models have id " +
                         std::to_string(models[i].model.id)};
    if (models.empty())
        return Error{directory.string() + ": holds no body_*.json model"};
    return models;
}

} // namespace edgetrack::app
