#include "carousel/studio/cli.h"

#include <unistd.h>

#include <csignal>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/progress.h"
#include "carousel/core/version.h"
#include "carousel/studio/self_check.h"
#include "carousel/studio/terminal_progress.h"

namespace carousel::studio {
namespace {

// The subcommands later issues fill in. Each is registered now so that `carousel --help`
// shows the whole program; until built, it says so and exits with kExitUnavailable.
struct PlannedCommand {
  const char* name;
  const char* summary;
  const char* issue;
};

constexpr PlannedCommand kPlannedCommands[] = {
    {"sim", "simulated rig: render a capture session of a scene, run emulated devices",
     "issue 3 (simulated rig)"},
    {"import", "turn a calibrated dataset (Middlebury, COLMAP) into a session",
     "issue 3 (simulated rig, dataset import)"},
    {"reconstruct", "silhouettes, visual hull and optimized mesh of a session",
     "issue 4 (reconstruction)"},
    {"texture", "texture atlas and texture map of a session's mesh; export OBJ and GLB",
     "issues 5 and 6 (texture atlas, texture transfer)"},
    {"process", "run every processing stage of one or more sessions", "issue 9 (studio pipeline)"},
    {"run", "the one-button session: capture, reconstruct, texture, export",
     "issue 9 (studio pipeline)"},
    {"camera", "list, configure and fire cameras (libgphoto2)", "issue 8 (cameras)"},
    {"turntable", "identify, home, move and configure the turntable controller",
     "issue 7 (turntable)"},
    {"calibrate", "camera intrinsics and rig calibration", "issue 10 (calibration)"},
};

// Ctrl-C cancels the running stage through its token (lock-free atomic store: signal-safe).
CancellationToken* g_interrupt_token = nullptr;
extern "C" void OnInterrupt(int) {
  if (g_interrupt_token != nullptr) g_interrupt_token->Cancel();
}

class InterruptScope {
 public:
  explicit InterruptScope(CancellationToken* token) {
    g_interrupt_token = token;
    previous_ = std::signal(SIGINT, OnInterrupt);
  }
  ~InterruptScope() {
    std::signal(SIGINT, previous_);
    g_interrupt_token = nullptr;
  }
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;

 private:
  void (*previous_)(int) = SIG_DFL;
};

std::filesystem::path DefaultDataDir() {
  if (const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR"); env != nullptr && *env) {
    return env;
  }
  return {};
}

int RunSelfCheckCommand(const SelfCheckOptions& options, std::ostream& out, std::ostream& err) {
  CancellationToken token;
  InterruptScope interrupt(&token);
  TerminalProgress bar(err, ::isatty(STDERR_FILENO) == 1 && &err == &std::cerr);
  Progress progress(bar.Listener(), token);
  const SelfCheckResult result = RunSelfCheck(options, progress);
  for (const SelfCheckItem& item : result.items) {
    const char* status = item.status == SelfCheckItem::Status::kPassed    ? "PASS"
                         : item.status == SelfCheckItem::Status::kSkipped ? "SKIP"
                                                                          : "FAIL";
    out << status << "  " << item.name << ": " << item.detail << '\n';
  }
  out << (result.AllPassed() ? "self-check passed" : "self-check FAILED") << '\n';
  return result.AllPassed() ? kExitOk : kExitFailure;
}

int ExitCodeFor(const std::exception& error) {
  if (dynamic_cast<const Cancelled*>(&error)) return kExitCancelled;
  if (dynamic_cast<const InvalidArgument*>(&error)) return kExitUsage;
  if (dynamic_cast<const FormatError*>(&error)) return kExitDataError;
  if (dynamic_cast<const IoError*>(&error)) return kExitIoError;
  if (dynamic_cast<const DeviceError*>(&error)) return kExitDeviceError;
  if (dynamic_cast<const ProtocolError*>(&error)) return kExitProtocol;
  return kExitFailure;
}

}  // namespace

int RunCli(int argc, const char* const* argv, std::ostream& out, std::ostream& err) {
  CLI::App app{"Carousel: one button from a product on a turntable to a textured 3D model.",
               "carousel"};
  app.set_version_flag("--version",
                       std::string("carousel ") + kVersion + " (" + LibraryVersions() + ")");
  app.require_subcommand(1);
  std::string log_level = "info";
  std::string log_file;
  app.add_option("--log-level", log_level, "debug, info, warn, error or off")
      ->capture_default_str();
  app.add_option("--log-file", log_file, "also append the log to this file");
  app.footer(
      "Exit codes: 0 ok, 1 failure, 64 usage, 65 malformed input file, 69 not built yet,\n"
      "74 file I/O error, 75 device error, 76 protocol error, 130 cancelled.");

  SelfCheckOptions self_check;
  self_check.data_dir = DefaultDataDir();
  CLI::App* self_check_command =
      app.add_subcommand("self-check",
                         "check this build: camera model vs OpenCV, image and "
                         "mesh files, shared test data");
  self_check_command->add_option("--data", self_check.data_dir,
                                 "shared test data folder (default: $CAROUSEL_SHARED_DATA_DIR)");
  self_check_command->add_option("--scratch", self_check.scratch_dir,
                                 "folder for temporary files (default: the system's)");
  self_check_command
      ->add_option("--points", self_check.points, "random points in the camera-model check")
      ->capture_default_str();

  std::vector<CLI::App*> planned;
  for (const PlannedCommand& command : kPlannedCommands) {
    CLI::App* sub = app.add_subcommand(command.name, command.summary);
    sub->allow_extras();
    sub->prefix_command();
    planned.push_back(sub);
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e, out, err);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e, out, err);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e, out, err);
  } catch (const CLI::ParseError& e) {
    app.exit(e, out, err);
    return kExitUsage;
  }

  try {
    SetLogLevel(ParseLogLevel(log_level));
    if (!log_file.empty()) SetLogFile(log_file);
    for (std::size_t i = 0; i < planned.size(); ++i) {
      if (planned[i]->parsed()) {
        err << "carousel " << kPlannedCommands[i].name << ": not built yet (see "
            << kPlannedCommands[i].issue << ")\n";
        return kExitUnavailable;
      }
    }
    if (self_check_command->parsed()) return RunSelfCheckCommand(self_check, out, err);
    err << "carousel: no subcommand\n";
    return kExitUsage;
  } catch (const std::exception& e) {
    err << "carousel: error: " << e.what() << '\n';
    return ExitCodeFor(e);
  }
}

}  // namespace carousel::studio
