// Reading and writing recording directories (INTERFACES §1-2): rig, frames, images, blobs, points,
// truth.
#pragma once

#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "core/result.hpp"
#include "core/rigid_transform.hpp"
#include "core/stereo_rig.hpp"

namespace edgetrack::recording {

/// \brief The data levels a recording can hold, lowest (rawest) first.
enum class Level { Images, Blobs, Points };

const char* levelName(Level level);
std::optional<Level> parseLevel(std::string_view name);

/// \brief frames.csv: one row per frame pair.
struct FrameRow {
    std::int64_t frame = 0;
    double time_s = 0.0;
};

/// \brief blobs.csv: a blob centre in raw (distorted) pixels of one camera.
struct BlobRow {
    std::int64_t frame = 0;
    int camera = 0;
    double u_px = 0.0;
    double v_px = 0.0;
    /// Area in pixels; absent (nullopt) when the file has no area column.
    std::optional<double> area_px;
};

/// \brief points.csv: one unlabelled 3D marker, rig frame (mm).
struct PointRow {
    std::int64_t frame = 0;
    double time_s = 0.0;
    Vec3 position_rig_mm = Vec3::Zero();
};

/// \brief truth.csv: the pose of one simulated object, p_rig = T_rig_from_object(p_object).
struct TruthRow {
    std::int64_t frame = 0;
    double time_s = 0.0;
    int object = 0;
    RigidTransform T_rig_from_object;
};

/// \brief truth/object_K.csv: one marker of object K in the object's own frame (mm).
struct TruthMarker {
    int marker = 0;
    Vec3 position_object_mm = Vec3::Zero();
};

/// \brief An 8-bit greyscale image, row-major, no padding.
struct Image8 {
    int width = 0;
    int height = 0;
    std::vector<std::uint8_t> pixels;
};

/// \brief rig.toml: two cameras (camera 0 defines the rig frame).
Result<StereoRig> readRig(const std::filesystem::path& path);
Result<StereoRig> parseRig(std::string_view text, std::string_view name);
Status writeRig(const std::filesystem::path& path, const StereoRig& rig);

/// \brief The CSV tables (INTERFACES section 1): read*() reads the file, parse*() its text, with
/// \a name leading every error.
Result<std::vector<FrameRow>> readFrames(const std::filesystem::path& path);
Result<std::vector<FrameRow>> parseFrames(std::string_view text, std::string_view name);
Result<std::vector<BlobRow>> readBlobs(const std::filesystem::path& path);
Result<std::vector<BlobRow>> parseBlobs(std::string_view text, std::string_view name);
Result<std::vector<PointRow>> readPoints(const std::filesystem::path& path);
Result<std::vector<PointRow>> parsePoints(std::string_view text, std::string_view name);
Result<std::vector<TruthRow>> readTruth(const std::filesystem::path& path);
Result<std::vector<TruthRow>> parseTruth(std::string_view text, std::string_view name);
Result<std::vector<TruthMarker>> readObjectMarkers(const std::filesystem::path& path);
Result<std::vector<TruthMarker>> parseObjectMarkers(std::string_view text, std::string_view name);

Status writeFrames(const std::filesystem::path& path, const std::vector<FrameRow>& rows);
/// \brief Writes the area column when \a withArea is true (rows without an area write 0).
Status writeBlobs(const std::filesystem::path& path, const std::vector<BlobRow>& rows,
                  bool withArea);
Status writePoints(const std::filesystem::path& path, const std::vector<PointRow>& rows);
Status writeTruth(const std::filesystem::path& path, const std::vector<TruthRow>& rows);
Status writeObjectMarkers(const std::filesystem::path& path,
                          const std::vector<TruthMarker>& markers);

/**
 * \brief Read a binary 8-bit PGM (P5, maxval 255).
 * \param expectedWidth, expectedHeight the camera's size from rig.toml; 0 accepts any size.
 */
Result<Image8> readPgm(const std::filesystem::path& path, int expectedWidth = 0,
                       int expectedHeight = 0);
Result<Image8> parsePgm(std::string_view bytes, std::string_view name, int expectedWidth = 0,
                        int expectedHeight = 0);
Status writePgm(const std::filesystem::path& path, const Image8& image);

/// \brief REC/images/NNNNNN_C.pgm
std::filesystem::path imagePath(const std::filesystem::path& recording, std::int64_t frame,
                                int camera);

/// \return the frame whose image \a fileName (a name in images/) is, NNNNNN_C.pgm with C 0 or 1;
/// nothing for any other name.
std::optional<std::int64_t> imageFrameOf(std::string_view fileName);

/// \brief What a recording directory holds.
struct Inventory {
    bool rig = false;
    bool frames = false;
    bool images = false;
    bool blobs = false;
    bool points = false;
    bool truth = false;
};

/// \brief Look at a recording directory without reading its data.
Result<Inventory> inspect(const std::filesystem::path& recording);

/**
 * \brief The level a tool reads: \a requested if present, else the lowest level present.
 * \return an error naming the directory when the level (or any level) is missing, or when the
 * images or blobs level lacks its rig.toml.
 */
Result<Level> chooseLevel(const std::filesystem::path& recording, const Inventory& inventory,
                          std::optional<Level> requested);

} // namespace edgetrack::recording
