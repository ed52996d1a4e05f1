#include <csignal>
#include <system_error>

#include "command.h"

namespace carousel::app {
namespace {

// Ctrl-C cancels the running stage through its token (lock-free atomic store: signal-safe).
CancellationToken* g_interrupt_token = nullptr;
extern "C" void OnInterrupt(int) {
  if (g_interrupt_token != nullptr) g_interrupt_token->Cancel();
}

int Depth(const CLI::App* command) {
  int depth = 0;
  for (const CLI::App* c = command; c->get_parent() != nullptr; c = c->get_parent()) ++depth;
  return depth;
}

}  // namespace

const Runner* Dispatch::Parsed() const {
  const Runner* best = nullptr;
  int best_depth = -1;
  for (const auto& [command, runner] : runners_) {
    if (command->parsed() && Depth(command) > best_depth) {
      best = &runner;
      best_depth = Depth(command);
    }
  }
  return best;
}

CliProgress::CliProgress(std::ostream& err)
    : bar_(err, ::isatty(STDERR_FILENO) == 1 && &err == &std::cerr),
      progress_(bar_.Listener(), token_) {
  g_interrupt_token = &token_;
  previous_ = std::signal(SIGINT, OnInterrupt);
}

CliProgress::~CliProgress() {
  std::signal(SIGINT, previous_);
  g_interrupt_token = nullptr;
}

void CreateParentFolder(const std::filesystem::path& file) {
  const std::filesystem::path parent = std::filesystem::absolute(file).parent_path();
  std::error_code ec;
  if (std::filesystem::is_directory(parent, ec)) return;
  std::filesystem::create_directories(parent, ec);
  if (ec)
    throw IoError(parent, "cannot create the folder for " + file.string() + ": " + ec.message());
}

std::string OptionHelp(const OptionInfo& info) {
  std::string help = info.help;
  std::string range = info.RangeText();
  if (!info.choices.empty()) {
    range.clear();
    for (std::size_t i = 0; i < info.choices.size(); ++i)
      range += (i == 0 ? "" : ", ") + info.choices[i];
  }
  if (range.empty()) range = info.unit;
  if (!range.empty()) help += " (" + range + ")";
  return help;
}

void AddNoPublishFlag(CLI::App* command, bool* publish_model) {
  command->add_flag(
      "--no-publish", [publish_model](std::int64_t) { *publish_model = false; },
      "stop after the texture stage (no web GLB, viewer page, catalog images or report page)");
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

}  // namespace carousel::app
