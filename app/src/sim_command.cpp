// carousel sim capture|rig|camera|turntable: the simulated rig, a studio in a box, its PTP/IP
// camera and its turntable firmware.
#include <csignal>
#include <filesystem>
#include <iomanip>
#include <memory>
#include <thread>

#include "carousel/studio/defaults.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/studio/simulated_studio.h"
#include "command.h"

namespace carousel::app {
namespace {

struct SimCaptureArgs {
  studio::SimCaptureOptions options;
  std::filesystem::path out;
};

struct SimRigArgs {
  studio::SimulatedStudioOptions options;
  std::filesystem::path out = "rig.json";
};

volatile std::sig_atomic_t g_rig_stop = 0;
extern "C" void OnRigStop(int) { g_rig_stop = 1; }

// Runs the studio in a box until Ctrl-C (or SIGTERM), its rig file written for the others.
int RunSimRig(SimRigArgs& args, Io& io) {
  CreateParentFolder(args.out);
  const std::filesystem::path rig_file = std::filesystem::absolute(args.out);
  args.options.folder = rig_file.parent_path();
  const studio::SimulatedStudio studio(args.options);
  const studio::RigConfig config = studio.Config();
  studio::WriteRigConfig(rig_file, config);
  io.out << "simulated studio: the turntable firmware in simavr on " << config.turntable.port
         << "\n";
  for (std::size_t c = 0; c < config.cameras.size(); ++c)
    io.out << "camera " << c << ": PTP/IP emulator " << config.cameras[c].serial << " on "
           << config.cameras[c].port << "\n";
  io.out << "rig file: " << rig_file.string() << "\n"
         << "try: carousel run --rig " << rig_file.string() << " --product SKU, or "
         << "carousel-studio --rig " << rig_file.string() << "\n"
         << "Ctrl-C stops the studio\n"
         << std::flush;
  g_rig_stop = 0;
  auto previous_int = std::signal(SIGINT, OnRigStop);
  auto previous_term = std::signal(SIGTERM, OnRigStop);
  while (!g_rig_stop) std::this_thread::sleep_for(std::chrono::milliseconds(50));
  std::signal(SIGINT, previous_int);
  std::signal(SIGTERM, previous_term);
  return kExitOk;
}

}  // namespace

void AddSimCommands(CLI::App& command, Dispatch& dispatch) {
  command.require_subcommand(1);
  auto args = std::make_shared<SimCaptureArgs>();
  args->options.data_dir = studio::DefaultDataDir();
  CLI::App* capture = command.add_subcommand(
      "capture", "photograph a scene on the simulated turntable into a new session folder");
  capture->add_option("--out", args->out, "session folder to create")->required();
  AddOptionFlags(capture, args->options, studio::SimCaptureOptions::Fields());
  capture->add_flag("--force", args->options.overwrite, "replace an existing session folder");
  dispatch.On(capture, [args](Io& io) {
    CreateParentFolder(args->out);
    CliProgress cli(io.err);
    const studio::SimCaptureResult result =
        studio::SimulateCapture(args->options, args->out, cli.progress());
    io.out << "session " << result.session.string() << ": " << result.views << " views, "
           << std::fixed << std::setprecision(1) << result.render_seconds << " s rendering\n";
    return kExitOk;
  });

  auto rig_args = std::make_shared<SimRigArgs>();
  rig_args->options.sim.data_dir = studio::DefaultDataDir();
  CLI::App* rig = command.add_subcommand(
      "rig",
      "a studio in a box: the turntable firmware in simavr behind a PTY and PTP/IP camera "
      "emulators photographing the simulated product, with the rig file that drives them");
  rig->add_option("--out", rig_args->out, "the rig file to write")->capture_default_str();
  AddOptionFlags(rig, rig_args->options, studio::SimulatedStudioOptions::Fields());
  dispatch.On(rig, [rig_args](Io& io) { return RunSimRig(*rig_args, io); });

  AddSimCameraCommand(*command.add_subcommand(
                          "camera", "a PTP/IP camera on 127.0.0.1 photographing the simulated rig"),
                      dispatch);
  AddSimTurntableCommand(
      *command.add_subcommand("turntable",
                              "the turntable firmware in simavr, its serial port on a PTY"),
      dispatch);
}

}  // namespace carousel::app
