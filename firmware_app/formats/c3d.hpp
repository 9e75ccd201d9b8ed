// Reader of C3D motion-capture files (c3d.org): 3D points with their labels and validity.
#pragma once

#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

#include "core/geometry.hpp"
#include "core/result.hpp"

namespace edgetrack::recording {

/// \brief The 3D point data of a C3D file.
struct C3dPoints {
    double frameRate_hz = 0.0;
    /// Number of the first frame as the file counts it (usually 1).
    std::int64_t firstFrame = 1;
    std::size_t frameCount = 0;
    std::size_t pointCount = 0;
    /// POINT:LABELS, trimmed; empty strings when the file has fewer labels than points.
    std::vector<std::string> labels;
    /// Frame-major: sample (frame f, point p) is at f * pointCount + p. Millimetres, in the
    /// recording system's frame.
    std::vector<Vec3> positions_mm;
    /// False where the recording system flagged the sample invalid (negative residual).
    std::vector<bool> valid;

    const Vec3& position(std::size_t frame, std::size_t point) const {
        return positions_mm[frame * pointCount + point];
    }
    bool isValid(std::size_t frame, std::size_t point) const {
        return valid[frame * pointCount + point];
    }
};

/**
 * \brief Read the 3D points of a C3D file: Intel, DEC or SGI/MIPS number formats, integer or
 * floating-point samples, units converted to millimetres (POINT:UNITS "m", "cm" or "mm").
 * Analog data is skipped.
 * \return a one-line error naming the file for anything malformed or truncated.
 */
Result<C3dPoints> readC3d(const std::filesystem::path& path);

/// \brief Parse C3D bytes; \a name appears in errors.
Result<C3dPoints> parseC3d(std::string_view bytes, std::string_view name);

} // namespace edgetrack::recording
