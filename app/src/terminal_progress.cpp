#include "carousel/app/terminal_progress.h"

#include <cmath>
#include <iomanip>
#include <ostream>

namespace carousel::app {

TerminalProgress::TerminalProgress(std::ostream& out, bool interactive, int width)
    : out_(out), interactive_(interactive), width_(width) {}

Progress::Listener TerminalProgress::Listener() {
  return [this](const ProgressUpdate& update) { OnUpdate(update); };
}

void TerminalProgress::OnUpdate(const ProgressUpdate& update) {
  std::lock_guard<std::mutex> lock(mutex_);
  const bool new_stage = update.stage != stage_;
  if (new_stage) {
    if (line_open_) out_ << '\n';
    line_open_ = false;
    stage_ = update.stage;
    last_quarter_ = -1;
    stage_start_ = std::chrono::steady_clock::now();
  }
  const int percent = static_cast<int>(std::floor(update.fraction * 100.0 + 1e-9));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - stage_start_).count();
  if (interactive_) {
    const int filled = static_cast<int>(std::lround(update.fraction * width_));
    out_ << '\r' << stage_ << " [" << std::string(filled, '#') << std::string(width_ - filled, '.')
         << "] " << std::setw(3) << percent << '%';
    if (update.stage_done) {
      out_ << "  " << std::fixed << std::setprecision(1) << seconds << " s\n";
      line_open_ = false;
    } else {
      line_open_ = true;
    }
    out_.flush();
    return;
  }
  // Plain lines: the stage start, each quarter reached, the end.
  const int quarter = update.stage_done ? 4 : percent / 25;
  if (quarter <= last_quarter_) return;
  last_quarter_ = quarter;
  out_ << stage_ << ": " << percent << '%';
  if (update.stage_done) out_ << " (" << std::fixed << std::setprecision(1) << seconds << " s)";
  out_ << '\n';
  out_.flush();
}

}  // namespace carousel::app
