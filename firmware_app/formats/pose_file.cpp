// Pose CSV files (INTERFACES §5): writing with fixed precision, strict reading for tests and tools.
#include "firmware_app/formats/pose_file.hpp"

#include <array>
#include <cmath>
#include <cstdio>

#include "firmware_app/formats/csv.hpp"

namespace edgetrack::app {

using recording::ColumnType;
using recording::CsvColumn;

void appendPoseRow(std::string& out, const PoseRow& row) {
    const std::array<double, 4> q = wxyzFromQuaternion(row.T_rig_from_model.rotation);
    const Vec3& t = row.T_rig_from_model.translation_mm;
    char line[256];
    std::snprintf(line, sizeof line, "%lld,%.6f,%u,%.4f,%.4f,%.4f,%.9f,%.9f,%.9f,%.9f,%u,%.4f\n",
                  static_cast<long long>(row.frame), row.time_s, row.body, t.x(), t.y(), t.z(),
                  q[0], q[1], q[2], q[3], row.markers, row.rms_mm);
    out += line;
}

Result<std::vector<PoseRow>> readPoses(const std::filesystem::path& path) {
    static constexpr std::array<CsvColumn, 12> kColumns{{{"frame", ColumnType::Integer},
                                                         {"time_s", ColumnType::Real},
                                                         {"body", ColumnType::Integer},
                                                         {"x", ColumnType::Real},
                                                         {"y", ColumnType::Real},
                                                         {"z", ColumnType::Real},
                                                         {"qw", ColumnType::Real},
                                                         {"qx", ColumnType::Real},
                                                         {"qy", ColumnType::Real},
                                                         {"qz", ColumnType::Real},
                                                         {"markers", ColumnType::Integer},
                                                         {"rms_mm", ColumnType::Real}}};
    Result<recording::CsvTable> table = recording::readCsvFile(path, kColumns);
    if (!table)
        return table.error();
    std::vector<PoseRow> rows;
    rows.reserve(table->rows.size());
    auto rowError = [&](const recording::CsvRow& row, const std::string& what) {
        return Error{path.string() + ":" + std::to_string(row.line) + ": " + what};
    };
    for (const recording::CsvRow& row : table->rows) {
        if (!rows.empty() && row.integer(0) < rows.back().frame)
            return rowError(row, "frames out of order");
        if (row.integer(2) < 0 || row.integer(10) < 0 || row[11] < 0.0)
            return rowError(row, "body, markers and rms_mm must not be negative");
        const double norm =
            std::sqrt(row[6] * row[6] + row[7] * row[7] + row[8] * row[8] + row[9] * row[9]);
        if (std::abs(norm - 1.0) > 1e-4)
            return rowError(row, "quaternion is not unit (norm " + std::to_string(norm) + ")");
        PoseRow pose;
        pose.frame = row.integer(0);
        pose.time_s = row[1];
        pose.body = static_cast<std::uint32_t>(row.integer(2));
        pose.T_rig_from_model.translation_mm = Vec3(row[3], row[4], row[5]);
        pose.T_rig_from_model.rotation = quaternionFromWxyz(row[6], row[7], row[8], row[9]);
        pose.markers = static_cast<std::uint32_t>(row.integer(10));
        pose.rms_mm = row[11];
        rows.push_back(pose);
    }
    return rows;
}

} // namespace edgetrack::app
