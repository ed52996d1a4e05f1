// carousel run --sim | --rig RIG.json | --resume SESSION [--calibration]: the one-button session.
#include <unistd.h>

#include <iomanip>
#include <iostream>
#include <memory>

#include "carousel/studio/defaults.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/run_session.h"
#include "command.h"
#include "print.h"

namespace carousel::app {
namespace {

struct RunArgs {
  studio::RunOptions options;
  bool sim = false;
  std::filesystem::path rig;  // a rig file: the hardware backends
  std::filesystem::path resume;
  bool calibration = false;  // a calibration session
  studio::CalibrationPlan plan;
};

// Hardware calibration: the operator places the board; Enter continues (on a terminal).
void AskForBoardPlacement(int index, int placements, std::ostream& err) {
  err << "\nboard placement " << index + 1 << " of " << placements
      << (index == 0 ? ": stand the board on the turntable"
                     : ": lean the board differently (e.g. further back) without moving the "
                       "cameras")
      << (::isatty(STDIN_FILENO) ? ", then press Enter" : "") << std::endl;
  if (::isatty(STDIN_FILENO)) {
    std::string line;
    std::getline(std::cin, line);
  }
}

// Hardware product passes: the operator lays the product down another way; Enter continues.
void AskToTurnProduct(int pass, int passes, std::ostream& err) {
  err << "\npass " << pass + 1 << " of " << passes
      << (pass == 0 ? ": stand the product as it stood in the first pass"
                    : ": lay the product down another way (on its side, upside down), near the "
                      "plate's centre")
      << (::isatty(STDIN_FILENO) ? ", then press Enter" : "") << std::endl;
  if (::isatty(STDIN_FILENO)) {
    std::string line;
    std::getline(std::cin, line);
  }
}

int RunOneButton(RunArgs& args, Io& io) {
  studio::RunResult result;
  if (args.calibration) {
    if (args.options.product.empty()) args.options.product = "rig-calibration";
    args.options.calibration = args.plan;
    args.options.place_board = [&io](int index, int placements) {
      AskForBoardPlacement(index, placements, io.err);
    };
  }
  args.options.turn_product = [&io](int pass, int passes) {
    AskToTurnProduct(pass, passes, io.err);
  };
  if (args.resume.empty() && !args.sim && args.rig.empty()) {
    io.err << "carousel run: say where to capture: --sim (the simulated rig), --rig RIG.json "
              "(the studio's turntable and cameras), or --resume SESSION\n";
    return kExitUsage;
  }
  CliProgress cli(io.err);
  if (!args.resume.empty()) {
    result = studio::ResumeSession(args.resume, cli.progress(), args.options.turn_product);
  } else {
    CAROUSEL_THROW_IF(args.options.product.empty(), InvalidArgument,
                      "carousel run: --product SKU is required");
    if (!args.rig.empty()) args.options.hardware = studio::ReadRigConfig(args.rig);
    result = studio::RunSession(args.options, cli.progress());
  }
  if (result.calibration || std::filesystem::exists(result.session / "calibration")) {
    io.out << "session " << result.session.string() << ": " << result.photos_taken
           << " photos taken, " << result.photos_kept << " kept from before, "
           << result.photos_retaken << " retaken\n";
    if (result.calibration) PrintCalibration(*result.calibration, io.out);
    io.out << "calibration: " << (result.session / "calibration" / "rig_calibration.json").string()
           << " (carousel run --calibration-file FILE, or \"calibration_file\" in rig.json)\n";
    return kExitOk;
  }
  io.out << "session " << result.session.string() << ": " << result.photos_taken
         << " photos taken, " << result.photos_kept << " kept from before, "
         << result.photos_adopted << " adopted, " << result.photos_retaken
         << " retaken; reconstruct " << (result.reconstructed ? "ran" : "was current")
         << ", texture " << (result.textured ? "ran" : "was current") << "\n";
  if (result.photos_taken > 0 && result.max_trigger_skew_ms > 0)
    io.out << std::fixed << std::setprecision(1) << "trigger skew between cameras: at most "
           << result.max_trigger_skew_ms << " ms\n";
  if (result.reconstruct) PrintReconstruct(result.session, *result.reconstruct, io.out);
  if (result.textured) PrintTexture(result.session, result.texture, io.out);
  if (result.publish) PrintPublish(result.session, *result.publish, io.out);
  const auto model = result.session / "model";
  io.out << "model: " << (model / "model.obj").string() << " (+ model.mtl, model.png), "
         << (model / "model.glb").string() << "\n";
  return kExitOk;
}

}  // namespace

void AddRunCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<RunArgs>();
  args->options.sim.data_dir = studio::DefaultDataDir();
  command.add_flag("--sim", args->sim, "on the simulated rig");
  command.add_option("--resume", args->resume, "continue a killed or failed session");
  command.add_option("--rig", args->rig,
                     "rig file (turntable port, cameras, calibration, capture plan): capture "
                     "with the studio's hardware");
  command.add_option("--product", args->options.product, "product SKU (names the session folder)");
  command.add_option("--out", args->options.out, "folder of the sessions")->capture_default_str();
  // What a resume needs again is kept in run.json: the simulated capture's recorded fields and
  // the held-out views.
  AddOptionFlags(&command, args->options.sim,
                 studio::SimCaptureOptions::Fields().Only(studio::RunSimFieldNames()));
  AddOptionFlags(&command, args->options.texture,
                 studio::TextureSessionOptions::Fields().Only({"exclude-views"}));
  AddOptionFlags(&command, args->options.publish, studio::PublishSessionOptions::Fields());
  AddNoPublishFlag(&command, &args->options.publish_model);
  command.add_flag("--force", args->options.force,
                   "start over (the old session is kept beside it)");
  command.add_flag("--calibration", args->calibration,
                   "a calibration session: the table turns with the board on it (once per "
                   "placement), the photos become calibration/rig_calibration.json");
  AddOptionFlags(&command, args->plan, studio::CalibrationPlan::Fields());
  command.add_option("--calibration-file", args->options.calibration_file,
                     "the photos' cameras from this rig calibration (carousel run "
                     "--calibration) instead of the rig's own");
  command.get_option("--resume")->excludes("--sim");
  command.get_option("--rig")->excludes("--sim");
  command.get_option("--rig")->excludes("--resume");
  dispatch.On(&command, [args](Io& io) { return RunOneButton(*args, io); });
}

}  // namespace carousel::app
