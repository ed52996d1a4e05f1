// carousel-studio's command line, read through the same options descriptions as `carousel run`
// (core/options.h: the simulated capture's recorded fields, the held-out views, the publish
// options), so `--size 480x320` means the same in both. No CLI11 here (DESIGN.md: only app/
// links it); the flags are few and the tables carry the rest.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "carousel/studio/run_session.h"

namespace carousel::gui {

struct StudioArgs {
  // What the one button runs: the simulated rig (default) or a rig file's hardware.
  studio::RunOptions run;
  std::filesystem::path rig;          // --rig RIG.json
  std::vector<std::string> products;  // --product SKU (repeated: operator mode, one per press)
  bool operator_mode = false;         // --operator: full screen, SKU entry, one big button
  // --calibration: the autorun runs the calibration wizard (the board on the table) instead
  // of a product session; the plan's fields (--board, --placements, ...) as `carousel run`.
  bool calibration = false;
  studio::CalibrationPlan plan;
  bool autorun = false;  // --autorun: press the button for each --product
  // --autorun-choose-pose K: when the autorun's session ends with a pass whose pose is
  // ambiguous, choose its pose K as the photographer would (the button under picture K).
  int autorun_pose = 0;
  bool quit_when_done = false;           // --quit-when-done: exit once the autorun's sessions end
  std::filesystem::path screenshot_dir;  // --screenshot-dir: a PNG per stage change and at the end
  std::filesystem::path frame_log;       // --frame-log: one frame time per line, ms
  int width = 1280, height = 800;        // --window WxH
  bool help = false, version = false;
};

// \throw InvalidArgument naming the flag (unknown flag, missing or malformed value, a value out
// of range: the options' Validate()).
StudioArgs ParseStudioArgs(const std::vector<std::string>& args);

// The --help text (every flag, with the options' help and ranges).
std::string StudioUsage();

// Frame times: p50 / p99 / max of the milliseconds logged.
struct FrameStats {
  int frames = 0;
  double p50_ms = 0.0, p99_ms = 0.0, max_ms = 0.0;
};
FrameStats SummarizeFrameTimes(std::vector<double> ms);
// Reads a --frame-log file. \throw IoError/FormatError naming it.
std::vector<double> ReadFrameLog(const std::filesystem::path& file);

}  // namespace carousel::gui
