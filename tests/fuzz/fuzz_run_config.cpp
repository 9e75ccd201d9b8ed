// Fuzz target: `edgetrack run --board sim` with a fuzzed edgetrack.toml and models directory.
//
// The input is split at NUL bytes: the configuration, then up to three model files
// (body_0.json ...). Each is written into a directory of this process and the firmware runs three
// frames of the simulated board's wand scene with them, as `run --scene wand --config FILE
// --models DIR --frames 3` would.
// The run must end with exit 0 or 1 (an error it names), never crash or hang.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <string_view>
#include <unistd.h>

#include "firmware_app/app/run_command.hpp"
#include "tests/fuzz/fuzz_input.hpp"

namespace {

namespace fs = std::filesystem;

/// This process's directory: the configuration and the models (the simulated board's flash is
/// in memory).
const fs::path& workDirectory() {
    static const fs::path directory = [] {
        fs::path d = fs::temp_directory_path() / ("edgetrack-fuzz-run-" + std::to_string(getpid()));
        fs::create_directories(d);
        return d;
    }();
    return directory;
}

void writeFile(const fs::path& path, std::string_view text) {
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    out.write(text.data(), static_cast<std::streamsize>(text.size()));
}

} // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    using namespace edgetrack;
    const std::string_view input(reinterpret_cast<const char*>(data), size);
    const fs::path& work = workDirectory();
    const fs::path models = work / "models";
    fs::remove_all(models);
    fs::create_directories(models);

    std::size_t start = 0;
    int part = 0;
    while (start <= input.size() && part < 4) {
        std::size_t end = input.find('\0', start);
        if (end == std::string_view::npos)
            end = input.size();
        const std::string_view text = input.substr(start, end - start);
        if (part == 0)
            writeFile(work / "edgetrack.toml", text);
        else
            writeFile(models / ("body_" + std::to_string(part - 1) + ".json"), text);
        start = end + 1;
        ++part;
    }

    app::RunCommandOptions options;
    options.config = work / "edgetrack.toml";
    options.models = models;
    options.board = "sim";
    // The wand's three markers: rendering the images is most of a run's time, and what is fuzzed
    // is the configuration and the models, not the scene.
    options.scene = "wand";
    options.frames = 3;
    // Loopback only, whatever the configuration names: a fuzzer sends nowhere else.
    options.udp = "127.0.0.1:9";
    options.buttonFromStdin = false;
    std::ostringstream out, err;
    const int code = app::runFirmwareCommand(options, out, err);
    if (code != 0 && code != 1)
        fuzz::fail("run ended with an exit code other than 0 or 1");
    if (code == 1 && err.str().empty())
        fuzz::fail("run failed without saying why");
    return 0;
}
