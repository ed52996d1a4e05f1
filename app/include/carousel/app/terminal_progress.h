// Draws a core::Progress as a progress bar per stage on a terminal, or as plain lines
// (stage start, every quarter, stage end) when the output is not a terminal (logs, CI).
#pragma once

#include <chrono>
#include <iosfwd>
#include <mutex>
#include <string>

#include "carousel/core/progress.h"

namespace carousel::app {

class TerminalProgress {
 public:
  // `interactive`: redraw one line in place with '\r' (true for a TTY).
  TerminalProgress(std::ostream& out, bool interactive, int width = 30);
  // The listener to give a Progress. The TerminalProgress must outlive it.
  Progress::Listener Listener();
  void OnUpdate(const ProgressUpdate& update);

 private:
  std::ostream& out_;
  bool interactive_;
  int width_;
  std::mutex mutex_;
  std::string stage_;
  int last_quarter_ = -1;
  bool line_open_ = false;
  std::chrono::steady_clock::time_point stage_start_;
};

}  // namespace carousel::app
