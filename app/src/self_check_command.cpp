// carousel self-check
#include <memory>

#include "carousel/studio/defaults.h"
#include "carousel/studio/self_check.h"
#include "command.h"

namespace carousel::app {

void AddSelfCheckCommand(CLI::App& command, Dispatch& dispatch) {
  auto options = std::make_shared<studio::SelfCheckOptions>();
  options->data_dir = studio::DefaultDataDir();
  AddOptionFlags(&command, *options, studio::SelfCheckOptions::Fields());
  dispatch.On(&command, [options](Io& io) {
    CliProgress cli(io.err);
    const studio::SelfCheckResult result = studio::RunSelfCheck(*options, cli.progress());
    for (const studio::SelfCheckItem& item : result.items) {
      using Status = studio::SelfCheckItem::Status;
      const char* status = item.status == Status::kPassed    ? "PASS"
                           : item.status == Status::kSkipped ? "SKIP"
                                                             : "FAIL";
      io.out << status << "  " << item.name << ": " << item.detail << '\n';
    }
    io.out << (result.AllPassed() ? "self-check passed" : "self-check FAILED") << '\n';
    return result.AllPassed() ? kExitOk : kExitFailure;
  });
}

}  // namespace carousel::app
