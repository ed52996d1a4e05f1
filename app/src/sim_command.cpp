// carousel sim capture|camera|turntable: the simulated rig, its PTP/IP camera and its
// turntable firmware.
#include <iomanip>
#include <memory>

#include "carousel/studio/defaults.h"
#include "carousel/studio/sim_capture.h"
#include "command.h"

namespace carousel::app {
namespace {

struct SimCaptureArgs {
  studio::SimCaptureOptions options;
  std::filesystem::path out;
};

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

  AddSimCameraCommand(*command.add_subcommand(
                          "camera", "a PTP/IP camera on 127.0.0.1 photographing the simulated rig"),
                      dispatch);
  AddSimTurntableCommand(
      *command.add_subcommand("turntable",
                              "the turntable firmware in simavr, its serial port on a PTY"),
      dispatch);
}

}  // namespace carousel::app
