// `edgetrack sim`: writes a recording of a simulated scene (INTERFACES §1, §3).
#include "firmware_app/tools/sim_command.hpp"

#include <iomanip>
#include <vector>

#include "hal/sim/levels.hpp"
#include "hal/sim/scene.hpp"
#include "hal/sim/world.hpp"

namespace edgetrack::app {

namespace fs = std::filesystem;
using recording::Level;

void listScenes(std::ostream& out) {
    for (const sim::SceneInfo& info : sim::sceneCatalogue())
        out << std::left << std::setw(16) << info.name << info.description << "\n";
}

Status writeSimRecording(const SimRecordingOptions& options) {
    std::optional<sim::Scene> scene = sim::makeScene(options.scene, options.seed);
    if (!scene)
        return Error{"unknown scene '" + options.scene + "' (edgetrack sim --list shows them)"};
    if (options.frames <= 0)
        return Error{"--frames must be positive"};

    std::error_code ec;
    if (fs::exists(options.out, ec) && !fs::is_empty(options.out, ec))
        return Error{options.out.string() + ": exists and is not empty; choose a new directory"};
    fs::create_directories(options.out, ec);
    if (ec)
        return Error{options.out.string() + ": cannot create: " + ec.message()};
    if (options.level == Level::Images) {
        fs::create_directories(options.out / "images", ec);
        if (ec)
            return Error{(options.out / "images").string() + ": cannot create: " + ec.message()};
    }
    fs::create_directories(options.out / "truth", ec);
    if (ec)
        return Error{(options.out / "truth").string() + ": cannot create: " + ec.message()};

    const std::size_t objectCount = scene->objects.size();
    std::vector<sim::MarkerObject> objects;
    for (const sim::SceneObject& o : scene->objects)
        objects.push_back(o.object);
    const sim::World world(std::move(*scene), options.seed);

    if (Status s = recording::writeRig(options.out / "rig.toml", world.rig()); !s)
        return s;
    for (std::size_t k = 0; k < objectCount; ++k) {
        std::vector<recording::TruthMarker> markers;
        for (std::size_t m = 0; m < objects[k].markers.size(); ++m)
            markers.push_back({static_cast<int>(m), objects[k].markers[m].position_object_mm});
        const fs::path path = options.out / "truth" / ("object_" + std::to_string(k) + ".csv");
        if (Status s = recording::writeObjectMarkers(path, markers); !s)
            return s;
    }

    const sim::RigSpec& rigSpec = world.scene().rig;
    const sim::FrameRenderer renderer(rigSpec.width_px, rigSpec.height_px,
                                      world.scene().background_dn, world.scene().noiseSigma_dn,
                                      options.seed);
    recording::Image8 image;
    image.width = rigSpec.width_px;
    image.height = rigSpec.height_px;
    image.pixels.resize(static_cast<std::size_t>(image.width) *
                        static_cast<std::size_t>(image.height));

    std::vector<recording::FrameRow> frames;
    std::vector<recording::TruthRow> truth;
    std::vector<recording::BlobRow> blobs;
    std::vector<recording::PointRow> points;
    sim::Observation observation;
    std::vector<sim::SimBlob> frameBlobs;
    std::vector<Vec3> framePoints;
    sim::LevelNoise noise;
    noise.pointSigma_mm = world.scene().pointNoise_mm;

    for (std::int64_t f = 0; f < options.frames; ++f) {
        const auto frame = static_cast<std::uint64_t>(f);
        world.observe(frame, observation);
        const double time_s = observation.time_s;
        frames.push_back({f, time_s});
        for (std::size_t k = 0; k < objectCount; ++k)
            truth.push_back({f, time_s, static_cast<int>(k), observation.objectPoses[k]});

        sim::Random random(options.seed * 0x100000001B3ull + frame);
        switch (options.level) {
        case Level::Images:
            for (int camera = 0; camera < 2; ++camera) {
                renderer.render(image.pixels, image.width, camera, observation, 1.0, frame);
                if (Status s =
                        recording::writePgm(recording::imagePath(options.out, f, camera), image);
                    !s)
                    return s;
            }
            break;
        case Level::Blobs:
            for (int camera = 0; camera < 2; ++camera) {
                sim::blobsFromObservation(observation, camera, noise, random, frameBlobs);
                for (const sim::SimBlob& b : frameBlobs)
                    blobs.push_back({f, camera, b.centre_px.x(), b.centre_px.y(), b.area_px});
            }
            break;
        case Level::Points:
            sim::pointsFromObservation(observation, noise, random, framePoints);
            for (const Vec3& p : framePoints)
                points.push_back({f, time_s, p});
            break;
        }
    }

    if (Status s = recording::writeFrames(options.out / "frames.csv", frames); !s)
        return s;
    if (Status s = recording::writeTruth(options.out / "truth.csv", truth); !s)
        return s;
    if (options.level == Level::Blobs)
        return recording::writeBlobs(options.out / "blobs.csv", blobs, true);
    if (options.level == Level::Points)
        return recording::writePoints(options.out / "points.csv", points);
    return Ok{};
}

} // namespace edgetrack::app
