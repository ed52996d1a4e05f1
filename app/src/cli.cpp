// The program's table of command groups (in the spirit of COLMAP's exe/colmap.cc) and RunCli:
// global options, parsing, an unknown command answered with the nearest known one, and every
// error turned into its exit code.
#include <algorithm>
#include <string>
#include <vector>

#include "carousel/core/logging.h"
#include "carousel/core/parallel.h"
#include "carousel/core/version.h"
#include "command.h"

namespace carousel::app {
namespace {

constexpr CommandGroup kCommands[] = {
    {"self-check",
     "check this build: camera model vs OpenCV, image and mesh files, shared test data",
     AddSelfCheckCommand},
    {"sim", "simulated rig: capture sessions, a PTP/IP camera, the turntable firmware",
     AddSimCommands},
    {"import", "turn a calibrated dataset (Middlebury, COLMAP text) into a session folder",
     AddImportCommand},
    {"reconstruct", "silhouettes, visual hull and optimized mesh of a session",
     AddReconstructCommand},
    {"texture", "texture atlas and texture map of a session's mesh", AddTextureCommands},
    {"process",
     "the processing stages (reconstruct, texture, publish) of one or more sessions, each "
     "skipped when its outputs are current",
     AddProcessCommand},
    {"publish",
     "the web GLB, viewer page, catalog images and report page of textured sessions (publish "
     "flags change what they name; the rest as the session last published)",
     AddPublishCommand},
    {"batch",
     "many sessions as independent tasks: N at once here, a Slurm job array (--slurm) or a "
     "Kubernetes Indexed Job (--k8s-manifest); a summary of every one",
     AddBatchCommand},
    {"run", "the one-button session: capture, reconstruct, texture, export, publish",
     AddRunCommand},
    {"turntable", "identify, home, move, trigger and configure the turntable controller",
     AddTurntableCommand},
    {"camera", "list, inspect, configure and fire cameras (libgphoto2: USB or ptpip:)",
     AddCameraCommand},
    {"calibrate", "camera intrinsics from board photos, the rig from a calibration session",
     AddCalibrateCommands},
};

// Levenshtein distance, for "did you mean".
std::size_t EditDistance(const std::string& a, const std::string& b) {
  std::vector<std::size_t> row(b.size() + 1);
  for (std::size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (std::size_t i = 1; i <= a.size(); ++i) {
    std::size_t diagonal = row[0];
    row[0] = i;
    for (std::size_t j = 1; j <= b.size(); ++j) {
      const std::size_t above = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diagonal + (a[i - 1] != b[j - 1] ? 1 : 0)});
      diagonal = above;
    }
  }
  return row[b.size()];
}

// The word a command line gives where `command` expects one of its subcommands, when it is
// none of them: "carousel proces" -> "proces". Empty when the line is fine (or has no word
// there: CLI11 then says what is missing).
std::string UnknownSubcommand(const CLI::App& command, const std::vector<std::string>& words,
                              std::size_t* index, const CLI::App** parent) {
  const std::vector<const CLI::App*> subs = command.get_subcommands({});
  if (subs.empty()) return {};
  for (std::size_t i = *index; i < words.size(); ++i) {
    const std::string& word = words[i];
    if (word == "--") return {};
    if (!word.empty() && word[0] == '-') {
      // An option of this level taking a value in the next word ("--log-level debug").
      if (word.find('=') == std::string::npos) {
        const CLI::Option* option = command.get_option_no_throw(word);
        if (option != nullptr && option->get_type_size() != 0) ++i;
      }
      continue;
    }
    for (const CLI::App* sub : subs) {
      if (sub->check_name(word)) {
        *index = i + 1;
        *parent = sub;
        return UnknownSubcommand(*sub, words, index, parent);
      }
    }
    // A positional argument of a command that also has subcommands (texture SESSION).
    if (!command.get_options([](const CLI::Option* o) { return o->get_positional(); }).empty())
      return {};
    *parent = &command;
    return word;
  }
  return {};
}

std::string Suggestion(const CLI::App& parent, const std::string& word) {
  std::string best;
  std::size_t best_distance = std::max<std::size_t>(2, word.size() / 3) + 1;
  for (const CLI::App* sub : parent.get_subcommands({})) {
    const std::size_t d = EditDistance(word, sub->get_name());
    const bool prefix = sub->get_name().rfind(word, 0) == 0 && !word.empty();
    if (prefix || d < best_distance) {
      best = sub->get_name();
      best_distance = prefix ? 0 : d;
    }
  }
  return best;
}

std::string CommandPath(const CLI::App& command) {
  std::string path = command.get_name();
  for (const CLI::App* c = command.get_parent(); c != nullptr; c = c->get_parent())
    path = c->get_name() + " " + path;
  return path;
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
  int threads = 0;
  app.add_option("--threads", threads,
                 "worker threads of every stage (0 = $CAROUSEL_THREADS, else one per core); the "
                 "outputs are the same whatever the count")
      ->check(CLI::Range(0, 4096));
  app.footer(
      "Exit codes: 0 ok, 1 failure, 64 usage, 65 malformed input file, 69 not built yet,\n"
      "74 file I/O error, 75 device error, 76 protocol error, 130 cancelled.");

  Dispatch dispatch;
  for (const CommandGroup& group : kCommands) {
    CLI::App* command = app.add_subcommand(group.name, group.help);
    group.add(*command, dispatch);
  }

  std::vector<std::string> words;
  for (int i = 1; i < argc; ++i) words.emplace_back(argv[i]);
  std::size_t index = 0;
  const CLI::App* parent = &app;
  const std::string unknown = UnknownSubcommand(app, words, &index, &parent);
  if (!unknown.empty()) {
    const std::string nearest = Suggestion(*parent, unknown);
    err << CommandPath(*parent) << ": '" << unknown << "' is not a command";
    if (!nearest.empty()) err << "; did you mean '" << nearest << "'?";
    err << " (" << CommandPath(*parent) << " --help lists them)\n";
    return kExitUsage;
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
  } catch (const std::exception& e) {
    err << "carousel: error: " << e.what() << '\n';
    return ExitCodeFor(e);
  }

  try {
    SetLogLevel(ParseLogLevel(log_level));
    if (!log_file.empty()) SetLogFile(log_file);
    if (threads > 0) SetDefaultThreadCount(threads);
    const Runner* runner = dispatch.Parsed();
    if (runner == nullptr) {
      err << "carousel: no subcommand\n";
      return kExitUsage;
    }
    Io io{out, err};
    return (*runner)(io);
  } catch (const std::exception& e) {
    err << "carousel: error: " << e.what() << '\n';
    return ExitCodeFor(e);
  }
}

}  // namespace carousel::app
