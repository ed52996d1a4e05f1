// What every command group of the `carousel` program shares: the table entry a group adds
// itself through, the terminal progress a long command draws, and flags made from the options'
// descriptions (core/options.h). Private to app/.
#pragma once

#include <unistd.h>

#include <filesystem>
#include <functional>
#include <iostream>
#include <memory>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include <CLI/CLI.hpp>

#include "carousel/app/cli.h"
#include "carousel/app/terminal_progress.h"
#include "carousel/core/error.h"
#include "carousel/core/options.h"
#include "carousel/core/options_json.h"
#include "carousel/core/progress.h"

namespace carousel::app {

// Where a command writes: normal output and errors/progress.
struct Io {
  std::ostream& out;
  std::ostream& err;
};

// What runs once a (sub)command is parsed; returns the exit code.
using Runner = std::function<int(Io&)>;

// The parsed leaf command's runner is found here after parsing.
class Dispatch {
 public:
  void On(CLI::App* command, Runner runner) { runners_.emplace_back(command, std::move(runner)); }
  // The runner of the deepest parsed command that has one (nullptr: none).
  const Runner* Parsed() const;

 private:
  std::vector<std::pair<CLI::App*, Runner>> runners_;
};

// One row of the program's table: a command group adds its subcommand(s) to `app`.
struct CommandGroup {
  const char* name;
  const char* help;
  void (*add)(CLI::App& command, Dispatch& dispatch);
};

// The groups, one per file (run_command.cpp, process_command.cpp, ...).
void AddSelfCheckCommand(CLI::App& command, Dispatch& dispatch);
void AddSimCommands(CLI::App& command, Dispatch& dispatch);
void AddImportCommand(CLI::App& command, Dispatch& dispatch);
void AddReconstructCommand(CLI::App& command, Dispatch& dispatch);
void AddTextureCommands(CLI::App& command, Dispatch& dispatch);
void AddProcessCommand(CLI::App& command, Dispatch& dispatch);
void AddPublishCommand(CLI::App& command, Dispatch& dispatch);
void AddBatchCommand(CLI::App& command, Dispatch& dispatch);
void AddRunCommand(CLI::App& command, Dispatch& dispatch);
void AddTurntableCommand(CLI::App& command, Dispatch& dispatch);
void AddCameraCommand(CLI::App& command, Dispatch& dispatch);
void AddCalibrateCommands(CLI::App& command, Dispatch& dispatch);
// The simulated devices, under `sim` (camera_command.cpp, turntable_command.cpp).
void AddSimCameraCommand(CLI::App& command, Dispatch& dispatch);
void AddSimTurntableCommand(CLI::App& command, Dispatch& dispatch);

// A Progress drawn on stderr (a bar on a terminal, lines otherwise), cancelled by Ctrl-C.
class CliProgress {
 public:
  explicit CliProgress(std::ostream& err);
  ~CliProgress();
  CliProgress(const CliProgress&) = delete;
  CliProgress& operator=(const CliProgress&) = delete;
  Progress& progress() { return progress_; }

 private:
  CancellationToken token_;
  TerminalProgress bar_;
  Progress progress_;
  void (*previous_)(int) = nullptr;
};

// Creates the folder a file given with --out goes into, when it is missing. \throw IoError.
void CreateParentFolder(const std::filesystem::path& file);

// The help text of a described field: "faces of the optimized mesh (>= 100 faces)".
std::string OptionHelp(const OptionInfo& info);

// `base` (a session's recorded options, say) with the fields whose flags were given on
// `command`'s command line taken from `given`, the object AddOptionFlags bound them to: what the
// user typed changes only what it names.
template <typename Owner>
Owner WithGivenFlags(const CLI::App& command, const OptionTable<Owner>& table, const Owner& given,
                     Owner base) {
  nlohmann::json merged = OptionsToJson(table, base);
  const nlohmann::json typed = OptionsToJson(table, given);
  for (const OptionField<Owner>& field : table.fields()) {
    const OptionInfo& info = field.info;
    const std::string off = info.negative_name.empty() ? "no-" + info.name : info.negative_name;
    for (const std::string& flag : {"--" + info.name, "--" + off}) {
      const CLI::Option* option = command.get_option_no_throw(flag);
      if (option != nullptr && option->count() > 0) merged[info.name] = typed[info.name];
    }
  }
  OptionsFromJson(table, merged, &base, "the command line");
  return base;
}

// --no-publish: the session stops after the texture stage (clears *publish_model).
void AddNoPublishFlag(CLI::App* command, bool* publish_model);

// Adds a flag per field of `table`, bound to `object` (which must outlive the parse): numbers,
// words and lists as --name VALUE (lists comma-separated), a bool as --name (or --no-name when
// it is on by default), enums and composite values through their text. Values are range-
// checked by the options' Validate() after parsing, which names the flag.
template <typename Owner>
void AddOptionFlags(CLI::App* command, Owner& object, const OptionTable<Owner>& table) {
  for (const OptionField<Owner>& field : table.fields()) {
    const OptionInfo& info = field.info;
    const std::string flag = "--" + info.name;
    const std::string help = OptionHelp(info);
    if (field.is_choice()) {
      auto set = field.text_set;
      CLI::Option* option = command->add_option_function<std::string>(
          flag,
          [&object, set](const std::string& text) {
            try {
              set(object, text);
            } catch (const InvalidArgument& e) {
              throw CLI::ValidationError(e.what());
            }
          },
          help);
      const std::string current = field.text_get(object);
      if (!current.empty()) option->default_str(current);
      continue;
    }
    std::visit(
        [&](auto* value) {
          using T = std::remove_pointer_t<decltype(value)>;
          if constexpr (std::is_same_v<T, bool>) {
            if (*value) {
              const std::string off =
                  "--" + (info.negative_name.empty() ? "no-" + info.name : info.negative_name);
              command->add_flag(
                  off, [value](std::int64_t) { *value = false; }, "off: " + help);
            } else {
              command->add_flag(flag, *value, help);
            }
          } else if constexpr (std::is_same_v<T, std::vector<int>> ||
                               std::is_same_v<T, std::vector<double>>) {
            command->add_option(flag, *value, help)->delimiter(',')->capture_default_str();
          } else {
            command->add_option(flag, *value, help)->capture_default_str();
          }
        },
        field.ref(object));
  }
}

}  // namespace carousel::app
