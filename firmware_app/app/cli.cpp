// The edgetrack command line (INTERFACES §3): parses arguments and runs one sub-command.
#include "firmware_app/app/cli.hpp"

#include <cstdint>
#include <iostream>
#include <optional>
#include <string>
#include <unistd.h>
#include <vector>

#include <CLI/CLI.hpp>

#include "firmware_app/app/run_command.hpp"
#include "firmware_app/formats/recording.hpp"
#include "firmware_app/tools/calibrate_command.hpp"
#include "firmware_app/tools/model_command.hpp"
#include "firmware_app/tools/reconstruct_command.hpp"
#include "firmware_app/tools/rig_calibrate_command.hpp"
#include "firmware_app/tools/sim_command.hpp"
#include "firmware_app/tools/track_command.hpp"

namespace edgetrack::app {

namespace {

struct RunOptions {
    std::string config;
    std::string board = "sim";
    std::string scene;
    std::int64_t frames = 0;
    std::string udp;
    std::string can;
    std::string canLog;
    std::string models;
    std::vector<std::string> faults;
};

struct SimOptions {
    std::string scene;
    std::int64_t frames = 0;
    std::string out;
    std::uint64_t seed = 1;
    std::string level = "images";
    bool list = false;
};

struct RecordingOptions {
    std::string config;
    std::string input;
    std::string out;
    std::string models;
    std::string from;
};

// Accepts exactly the level names of INTERFACES §1 that a sub-command can start from.
CLI::Validator levelValidator(std::vector<std::string> allowed) {
    std::string names;
    for (const std::string& a : allowed)
        names += (names.empty() ? "" : "|") + a;
    return CLI::Validator(
        [allowed, names](std::string& value) -> std::string {
            for (const std::string& a : allowed)
                if (value == a)
                    return {};
            return "level must be one of " + names;
        },
        names, "LEVEL");
}

void addConfigOption(CLI::App* command, RecordingOptions& options) {
    command->add_option("--config", options.config,
                        "Settings as on the board (edgetrack.toml; default: built-in defaults)");
}

/// Reads --config of an offline command into \a settings; on failure prints why.
bool loadSettings(const RecordingOptions& options, const char* command, CommandSettings& settings,
                  std::ostream& err) {
    Result<CommandSettings> loaded = loadCommandSettings(options.config);
    if (!loaded) {
        err << "edgetrack " << command << ": " << loaded.error().message << "\n";
        return false;
    }
    settings = std::move(*loaded);
    return true;
}

} // namespace

int runCommandLine(int argc, const char* const* argv, std::ostream& out, std::ostream& err) {
    CLI::App app{"edgetrack: stereo IR marker tracker with on-board object calibration"};
    app.require_subcommand(1);
    app.failure_message(CLI::FailureMessage::simple);

    RunOptions run;
    CLI::App* runCommand = app.add_subcommand("run", "Run the firmware: capture, track, output");
    runCommand->add_option("--config", run.config, "Configuration file (TOML)");
    runCommand->add_option("--board", run.board, "Hardware backend")
        ->check(CLI::IsMember({"sim", "linux"}));
    runCommand->add_option("--scene", run.scene, "Scene of the simulated board");
    runCommand->add_option("--frames", run.frames, "Stop after N frames (0: run until stopped)")
        ->check(CLI::NonNegativeNumber);
    runCommand->add_option("--udp", run.udp, "DTrack UDP destination HOST:PORT");
    runCommand->add_option("--can", run.can, "CAN interface for pose frames");
    runCommand->add_option("--can-log", run.canLog,
                           "Log the CAN frames sent to FILE (candump -L format); enables CAN");
    runCommand->add_option("--models", run.models, "Load models from this directory");
    runCommand->add_option("--fault", run.faults,
                           "Simulated board only: camera-stall@T+D, can-bus-off@T or "
                           "button-bounce@T (seconds from the start; repeatable)");

    SimOptions sim;
    CLI::App* simCommand = app.add_subcommand("sim", "Write a recording of a simulated scene");
    CLI::Option* listFlag = simCommand->add_flag("--list", sim.list, "List the scenes and exit");
    simCommand->add_option("--scene", sim.scene, "Scene name (see --list)")->excludes(listFlag);
    simCommand->add_option("--frames", sim.frames, "Number of frames")
        ->check(CLI::PositiveNumber)
        ->excludes(listFlag);
    simCommand->add_option("--out", sim.out, "Recording directory to write")->excludes(listFlag);
    simCommand->add_option("--seed", sim.seed, "Random seed");
    simCommand->add_option("--level", sim.level, "Lowest level to write")
        ->check(levelValidator({"images", "blobs", "points"}));

    RecordingOptions reconstruct;
    CLI::App* reconstructCommand =
        app.add_subcommand("reconstruct", "Blobs, stereo and triangulation of a recording");
    reconstructCommand->add_option("--input", reconstruct.input, "Recording to read")->required();
    reconstructCommand->add_option("--out", reconstruct.out, "Recording to write")->required();
    reconstructCommand->add_option("--from", reconstruct.from, "Level to start from")
        ->check(levelValidator({"images", "blobs"}));
    addConfigOption(reconstructCommand, reconstruct);

    RecordingOptions calibrate;
    CLI::App* calibrateCommand =
        app.add_subcommand("calibrate", "Learn the rigid marker objects of a recording");
    calibrateCommand->add_option("--input", calibrate.input, "Recording or .c3d file")->required();
    calibrateCommand->add_option("--out", calibrate.out, "Model directory to write")->required();
    calibrateCommand->add_option("--from", calibrate.from, "Level to start from")
        ->check(levelValidator({"images", "blobs", "points"}));
    addConfigOption(calibrateCommand, calibrate);

    RecordingOptions track;
    CLI::App* trackCommand = app.add_subcommand("track", "Find the models' poses in a recording");
    trackCommand->add_option("--models", track.models, "Model directory")->required();
    trackCommand->add_option("--input", track.input, "Recording or .c3d file")->required();
    trackCommand->add_option("--out", track.out, "Pose CSV to write")->required();
    trackCommand->add_option("--from", track.from, "Level to start from")
        ->check(levelValidator({"images", "blobs", "points"}));
    addConfigOption(trackCommand, track);

    CLI::App* modelCommand =
        app.add_subcommand("model", "List, show, export and import the models on flash");
    modelCommand->require_subcommand(1);
    ModelCommandOptions model;
    struct ModelAction {
        const char* name;
        const char* help;
    };
    std::vector<CLI::App*> modelActions;
    for (const ModelAction& action :
         {ModelAction{"list", "List the models on flash (or in --models DIR)"},
          ModelAction{"show", "Show one model's markers (--id N)"},
          ModelAction{"export", "Write the models on flash as model files (--out DIR)"},
          ModelAction{"import", "Save the model files of --models DIR to flash"}}) {
        CLI::App* sub = modelCommand->add_subcommand(action.name, action.help);
        sub->add_option("--config", model.config,
                        "Configuration whose [flash] names the partition");
        sub->add_option("--flash", model.flash, "Flash partition file (default: [flash] device)");
        const std::string name = action.name;
        if (name != "export")
            sub->add_option("--models", model.models, "Model directory")
                ->required(name == "import");
        if (name == "show")
            sub->add_option("--id", model.id, "Model id")->required();
        if (name == "export")
            sub->add_option("--out", model.out, "Directory to write")->required();
        modelActions.push_back(sub);
    }

    CLI::App* rigCommand = app.add_subcommand("rig", "Measure the stereo rig");
    rigCommand->require_subcommand(1);
    RecordingOptions rig;
    std::string wandText;
    bool refineIntrinsics = false;
    CLI::App* rigCalibrateCommand = rigCommand->add_subcommand(
        "calibrate", "Measure camera 1's pose (and intrinsics) from a recording of a wand");
    rigCalibrateCommand->add_option("--input", rig.input, "Recording of the wand")->required();
    rigCalibrateCommand
        ->add_option("--wand", wandText, "Marker spacings from one end, mm: D1[,D2...]")
        ->required();
    rigCalibrateCommand->add_option("--out", rig.out, "rig.toml to write")->required();
    rigCalibrateCommand->add_option("--from", rig.from, "Level to start from")
        ->check(levelValidator({"images", "blobs"}));
    rigCalibrateCommand->add_flag("--refine-intrinsics", refineIntrinsics,
                                  "Refine both cameras' focal lengths and principal points");
    addConfigOption(rigCalibrateCommand, rig);

    try {
        app.parse(argc, argv);
    } catch (const CLI::CallForHelp&) {
        // help() follows the parsed sub-commands, so "edgetrack sim --help" shows sim's options.
        out << app.help();
        return 0;
    } catch (const CLI::CallForAllHelp&) {
        out << app.help("", CLI::AppFormatMode::All);
        return 0;
    } catch (const CLI::ParseError& e) {
        // One line, as INTERFACES §3 asks; --help has the details.
        err << "edgetrack: " << e.what() << "\n";
        return kExitUsage;
    }

    if (runCommand->parsed()) {
        RunCommandOptions options;
        options.config = run.config;
        options.board = run.board;
        options.scene = run.scene;
        options.frames = run.frames;
        options.udp = run.udp;
        options.can = run.can;
        options.canLog = run.canLog;
        options.models = run.models;
        options.faults = run.faults;
        return runFirmwareCommand(options, out, err);
    }
    if (simCommand->parsed()) {
        if (sim.list) {
            listScenes(out);
            return 0;
        }
        if (sim.scene.empty() || sim.frames == 0 || sim.out.empty()) {
            err << "edgetrack sim: --scene, --frames and --out are required (or --list)\n";
            return kExitUsage;
        }
        SimRecordingOptions options;
        options.scene = sim.scene;
        options.frames = sim.frames;
        options.out = sim.out;
        options.seed = sim.seed;
        options.level = *recording::parseLevel(sim.level);
        if (Status s = writeSimRecording(options); !s) {
            err << "edgetrack sim: " << s.error().message << "\n";
            return kExitFailure;
        }
        out << "edgetrack sim: wrote " << sim.frames << " frames of '" << sim.scene << "' ("
            << sim.level << " level, seed " << sim.seed << ") to " << sim.out << "\n";
        return 0;
    }
    if (reconstructCommand->parsed()) {
        ReconstructOptions options;
        options.input = reconstruct.input;
        options.out = reconstruct.out;
        if (!reconstruct.from.empty())
            options.from = recording::parseLevel(reconstruct.from);
        if (!loadSettings(reconstruct, "reconstruct", options.settings, err))
            return kExitFailure;
        if (Status s = runReconstruct(options, out); !s) {
            err << "edgetrack reconstruct: " << s.error().message << "\n";
            return kExitFailure;
        }
        return 0;
    }
    if (calibrateCommand->parsed()) {
        CalibrateOptions options;
        options.input = calibrate.input;
        options.out = calibrate.out;
        if (!calibrate.from.empty())
            options.from = recording::parseLevel(calibrate.from);
        if (!loadSettings(calibrate, "calibrate", options.settings, err))
            return kExitFailure;
        // Progress is for a person watching a terminal, not for logs or tests.
        options.showProgress = &err == &std::cerr && ::isatty(STDERR_FILENO) != 0;
        if (Status s = runCalibrate(options, out, err); !s) {
            err << "edgetrack calibrate: " << s.error().message << "\n";
            return kExitFailure;
        }
        return 0;
    }
    if (trackCommand->parsed()) {
        TrackOptions options;
        options.models = track.models;
        options.input = track.input;
        options.out = track.out;
        if (!track.from.empty())
            options.from = recording::parseLevel(track.from);
        if (!loadSettings(track, "track", options.settings, err))
            return kExitFailure;
        options.showProgress = &err == &std::cerr && ::isatty(STDERR_FILENO) != 0;
        if (Status s = runTrack(options, out, err); !s) {
            err << "edgetrack track: " << s.error().message << "\n";
            return kExitFailure;
        }
        return 0;
    }
    if (rigCalibrateCommand->parsed()) {
        RigCalibrateOptions options;
        options.input = rig.input;
        options.out = rig.out;
        options.refineIntrinsics = refineIntrinsics;
        if (!rig.from.empty())
            options.from = recording::parseLevel(rig.from);
        Result<std::vector<double>> spacings = parseWandSpacings(wandText);
        if (!spacings) {
            err << "edgetrack rig calibrate: " << spacings.error().message << "\n";
            return kExitUsage;
        }
        options.wandSpacings_mm = *spacings;
        if (!loadSettings(rig, "rig calibrate", options.settings, err))
            return kExitFailure;
        if (Status s = runRigCalibrate(options, out); !s) {
            err << "edgetrack rig calibrate: " << s.error().message << "\n";
            return kExitFailure;
        }
        return 0;
    }
    if (modelCommand->parsed()) {
        for (CLI::App* action : modelActions)
            if (action->parsed())
                model.action = action->get_name();
        if (Status s = runModelCommand(model, out); !s) {
            err << "edgetrack model " << model.action << ": " << s.error().message << "\n";
            return kExitFailure;
        }
        return 0;
    }
    return kExitUsage;
}

} // namespace edgetrack::app
