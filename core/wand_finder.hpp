// Finds a straight calibration wand (markers at known spacings) among one camera's blobs.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <span>

#include "core/blob_detector.hpp"
#include "core/camera_model.hpp"

namespace edgetrack {

/// \brief Most markers a wand may carry.
inline constexpr std::size_t kMaxWandMarkers = 8;

/**
 * \brief A straight wand: markers on one line, spacing_mm[k] apart from marker k to k + 1 (mm).
 *
 * Marker 0 is the end the spacings are counted from (the `--wand D1,D2,...` of INTERFACES §3).
 */
struct WandSpec {
    std::array<double, kMaxWandMarkers - 1> spacing_mm{};
    std::size_t markerCount = 0;

    /// \brief The wand of spacings \a spacings_mm (mm); invalid unless 1 to 7 positive spacings.
    static WandSpec fromSpacings(std::span<const double> spacings_mm);

    /// \return true with two to kMaxWandMarkers markers and every spacing positive.
    bool isValid() const;
    /// \return the distance of marker \a k from marker 0 along the wand (mm).
    double offset_mm(std::size_t k) const;
    /// \return the distance from the first marker to the last (mm).
    double length_mm() const { return offset_mm(markerCount - 1); }
    /// \return true when the wand reads the same from both ends (its ends cannot be told apart).
    bool isSymmetric() const;
};

struct WandFinderConfig {
    /// Largest distance of an inner marker from the line through the two ends, in pixels of the
    /// undistorted image (so lens distortion does not bend the line).
    double lineTolerance_px = 1.5;
    /// Largest ratio of the two ends' distances from the camera. Perspective moves the inner
    /// markers along the line by this ratio, so it is what the spacings are checked against: a
    /// 16 cm wand at 40 cm or more stays well within 1.6.
    double maxDepthRatio = 1.6;
    /// Inner markers must agree on the depth ratio within this factor (wands of 4+ markers).
    double depthRatioAgreement = 1.08;
    /// Frames with more blobs than this are refused without a search (a burst of reflections).
    std::size_t maxBlobs = 24;
};

/// \brief Why a camera's frame gave no wand.
enum class WandMiss : std::uint8_t {
    None, ///< found
    TooManyBlobs,
    NotFound,  ///< no set of blobs lies on a line with the wand's spacings
    Ambiguous, ///< two or more sets do; the frame is refused rather than guessed
};

/// \brief The wand in one camera's image.
struct WandSighting {
    /// Raw (distorted) pixel centres of markers 0 .. markerCount-1, in wand order.
    std::array<Vec2, kMaxWandMarkers> pixels{};
    std::size_t markerCount = 0;
    /// True when the spacings fit both ways round (a symmetric wand, or one seen end-on): the
    /// order may be reversed, and stereo has to decide.
    bool endsAmbiguous = false;
};

struct WandFinderCounters {
    std::uint64_t images = 0;
    std::uint64_t found = 0;
    std::uint64_t tooManyBlobs = 0;
    std::uint64_t notFound = 0;
    std::uint64_t ambiguous = 0;
};

/**
 * \brief Finds the wand in one camera's blobs, from the undistorted image geometry alone.
 *
 * Any two blobs are candidate ends; the blobs within WandFinderConfig::lineTolerance_px of the
 * line between them and between them in order are the inner markers. A line in space seen in
 * perspective maps the wand's fractions s (offset / length) to image fractions
 * t = s / (s + (1 - s) rho), rho being the ratio of the two ends' depths, so each inner marker
 * yields rho; the wand is there when every inner marker gives a plausible rho, and the same one.
 * Of two ways round, the one whose rho is plausible names the ends; with both plausible the
 * sighting says its ends are ambiguous. A frame where two different sets of blobs pass is refused.
 * No heap: the search runs over the blobs in place.
 */
class WandFinder {
public:
    WandFinder(const WandSpec& wand, const WandFinderConfig& config);

    /// \return true when the wand spec is valid and the tolerances positive.
    bool isValid() const { return valid_; }

    /**
     * \brief Look for the wand among \a blobs of \a camera.
     * \param miss set to why nothing was found (WandMiss::None when found); may be null.
     */
    std::optional<WandSighting> find(const CameraModel& camera, std::span<const Blob> blobs,
                                     WandMiss* miss = nullptr);

    const WandFinderCounters& counters() const { return counters_; }

private:
    /// One candidate: blob indices in wand order and whether the reverse fits too.
    struct Candidate {
        std::array<std::uint16_t, kMaxWandMarkers> blobIndex{};
        bool endsAmbiguous = false;
    };

    std::optional<Candidate> tryEnds(std::span<const Vec2> ideal_px, std::size_t first,
                                     std::size_t last) const;
    /// \return the ends' depth ratio that inner markers at image fractions \a t imply, when they
    /// agree and it is plausible, reading the wand from marker 0 (\a reversed false) or the end.
    std::optional<double> depthRatio(std::span<const double> t, bool reversed) const;

    WandSpec wand_;
    WandFinderConfig config_;
    WandFinderCounters counters_;
    std::array<Vec2, 64> ideal_px_{};
    bool valid_ = false;
};

} // namespace edgetrack
