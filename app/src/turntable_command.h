// `carousel turntable --port DEV identify|home|goto DEG|status|trigger|config` (the serial
// controller of firmware-protocol/) and `carousel sim turntable` (the firmware in simavr on a
// PTY, for trying the former without hardware).
#pragma once

#include <filesystem>
#include <optional>
#include <ostream>
#include <string>
#include <vector>

namespace carousel::app {

struct TurntableArgs {
  std::string port;
  std::string action;              // identify, home, goto, status, trigger, backlight, config
  double degrees = 0.0;            // goto: absolute table angle
  std::vector<int> cameras = {0};  // trigger: camera outputs 0..3
  bool focus = false;              // trigger: focus outputs instead of shutters
  int duration_ms = 100;           // trigger
  bool on = false, off = false;    // backlight: switch it on / off (neither: report it)
  double timeout_s = 60.0;         // home / goto
  // config: values to change (unset: keep).
  std::optional<int> steps_per_rev, microsteps, max_speed, acceleration, homing_speed, backlash;
  std::string gear;  // "NUM:DEN"
};

int RunTurntable(const TurntableArgs& args, std::ostream& out, std::ostream& err);

struct SimTurntableArgs {
  std::filesystem::path firmware;  // the ELF; default: the build's
  std::filesystem::path link;      // symlink to the PTY
  double time_scale = 1.0;
  double seconds = 0.0;  // run time, 0 = until interrupted
};

int RunSimTurntable(const SimTurntableArgs& args, std::ostream& out, std::ostream& err);

}  // namespace carousel::app
