#include "turntable_command.h"

#include <memory>
#include "carousel/studio/defaults.h"

#include <chrono>
#include <cmath>
#include <csignal>
#include <iomanip>
#include <numbers>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/rig/serial_turntable.h"
#include "carousel/sim/avr_turntable.h"
#include "command.h"

namespace carousel::app {
namespace {

volatile std::sig_atomic_t g_stop = 0;
extern "C" void OnStop(int) { g_stop = 1; }

double Degrees(double rad) { return rad * 180.0 / std::numbers::pi; }

void PrintStatus(rig::SerialTurntable& table, std::ostream& out) {
  const cp_status raw = table.RawStatus();
  const rig::TurntableStatus status = table.Status();
  out << std::fixed << std::setprecision(3) << "angle " << Degrees(status.angle_rad) << " deg ("
      << raw.position << " microsteps), target " << Degrees(status.target_rad) << " deg, "
      << (status.moving ? "moving" : "at rest") << ", " << (status.homed ? "homed" : "not homed")
      << ", backlight " << (status.backlight ? "on" : "off") << ", driver "
      << ((raw.flags & CP_FLAG_ENABLED) ? "enabled" : "disabled") << ", sensor "
      << ((raw.flags & CP_FLAG_SENSOR) ? "active" : "clear") << ", fault "
      << (status.fault.empty() ? "none" : status.fault) << ", frames dropped by the controller "
      << raw.dropped_frames << '\n';
}

void PrintConfig(const cp_config& c, std::ostream& out) {
  out << "steps per motor revolution " << c.steps_per_rev << ", microsteps " << c.microsteps
      << ", gear " << c.gear_num << ":" << c.gear_den << " (" << cp_steps_per_table_rev(&c)
      << " microsteps per table revolution), max speed " << c.max_speed
      << " microsteps/s, acceleration " << c.acceleration << " microsteps/s^2, homing speed "
      << c.homing_speed << " microsteps/s, backlash " << c.backlash << " microsteps\n";
}

}  // namespace

int RunTurntable(const TurntableArgs& args, std::ostream& out, std::ostream& /*err*/) {
  rig::SerialTurntableOptions options;
  options.port = args.port;
  rig::SerialTurntable table(options);
  const auto timeout = std::chrono::milliseconds(static_cast<long long>(args.timeout_s * 1000));
  if (args.action == "identify") {
    const rig::TurntableInfo info = table.Identify();
    out << info.model << ", firmware " << info.firmware << ", on " << info.port << '\n';
  } else if (args.action == "status") {
    PrintStatus(table, out);
  } else if (args.action == "home") {
    table.Home(timeout);
    PrintStatus(table, out);
  } else if (args.action == "goto") {
    table.MoveTo(args.degrees * std::numbers::pi / 180.0, timeout);
    PrintStatus(table, out);
  } else if (args.action == "trigger") {
    std::uint8_t mask = 0;
    for (const int c : args.cameras) {
      if (c < 0 || c >= CP_MAX_CAMERAS)
        throw InvalidArgument("trigger: camera " + std::to_string(c) + " outside 0..3");
      mask = static_cast<std::uint8_t>(mask | (1u << c));
    }
    if (args.duration_ms < 1 || args.duration_ms > static_cast<int>(CP_MAX_TRIGGER_MS))
      throw InvalidArgument("trigger: --ms must be in 1..10000");
    table.Trigger(mask, args.focus ? CP_OUTPUT_FOCUS : CP_OUTPUT_SHUTTER,
                  static_cast<std::uint16_t>(args.duration_ms));
    out << (args.focus ? "focus" : "shutter") << " outputs " << static_cast<int>(mask) << " on for "
        << args.duration_ms << " ms\n";
  } else if (args.action == "backlight") {
    if (args.on && args.off) throw InvalidArgument("backlight: --on or --off, not both");
    if (args.on || args.off) table.SetBacklight(args.on);
    out << "backlight " << (table.Status().backlight ? "on" : "off") << '\n';
  } else if (args.action == "config") {
    cp_config c = table.Config();
    bool changed = false;
    auto set = [&](const std::optional<int>& value, std::uint16_t* field, const char* name) {
      if (!value) return;
      if (*value < 0 || *value > 65535)
        throw InvalidArgument(std::string("config: --") + name + " must be in 0..65535");
      *field = static_cast<std::uint16_t>(*value);
      changed = true;
    };
    set(args.steps_per_rev, &c.steps_per_rev, "steps-per-rev");
    set(args.microsteps, &c.microsteps, "microsteps");
    set(args.max_speed, &c.max_speed, "max-speed");
    set(args.acceleration, &c.acceleration, "acceleration");
    set(args.homing_speed, &c.homing_speed, "homing-speed");
    set(args.backlash, &c.backlash, "backlash");
    if (!args.gear.empty()) {
      const auto colon = args.gear.find(':');
      try {
        if (colon == std::string::npos) throw std::invalid_argument("no colon");
        c.gear_num = static_cast<std::uint16_t>(std::stoi(args.gear.substr(0, colon)));
        c.gear_den = static_cast<std::uint16_t>(std::stoi(args.gear.substr(colon + 1)));
      } catch (const std::logic_error&) {
        throw InvalidArgument("config: --gear must be NUM:DEN, e.g. 3:1");
      }
      changed = true;
    }
    if (changed) c = table.SetConfig(c);
    PrintConfig(c, out);
  } else {
    throw InvalidArgument("turntable: unknown action '" + args.action +
                          "' (identify, home, goto, status, trigger, backlight, config)");
  }
  return 0;
}

int RunSimTurntable(const SimTurntableArgs& args, std::ostream& out, std::ostream& /*err*/) {
  sim::AvrTurntableOptions options;
  options.firmware = args.firmware.empty() ? studio::DefaultFirmwarePath() : args.firmware;
  options.time_scale = args.time_scale;
  options.link = args.link;
  sim::AvrTurntable table(options);
  out << "simulated turntable controller (firmware " << options.firmware.string() << ") on "
      << table.port() << "\n"
      << "try: carousel turntable --port " << table.port() << " identify\n"
      << std::flush;
  g_stop = 0;
  auto previous_int = std::signal(SIGINT, OnStop);
  auto previous_term = std::signal(SIGTERM, OnStop);
  const auto start = std::chrono::steady_clock::now();
  while (!g_stop && (args.seconds <= 0.0 || std::chrono::steady_clock::now() - start <
                                                std::chrono::duration<double>(args.seconds)))
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  std::signal(SIGINT, previous_int);
  std::signal(SIGTERM, previous_term);
  out << table.steps().size() << " step pulses, motor at " << table.motor_steps()
      << " microsteps\n";
  return 0;
}

void AddTurntableCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<TurntableArgs>();
  command.add_option("--port", args->port, "serial port, e.g. /dev/ttyACM0")->required();
  command
      .add_option("action", args->action,
                  "identify, home, goto, status, trigger, backlight or config")
      ->required();
  command.add_option("degrees", args->degrees, "goto: absolute table angle");
  command.add_option("--timeout", args->timeout_s, "home/goto timeout, seconds")
      ->capture_default_str();
  command.add_option("--cameras", args->cameras, "trigger: cameras 0..3")
      ->delimiter(',')
      ->capture_default_str();
  command.add_flag("--focus", args->focus, "trigger: focus instead of shutter");
  command.add_option("--ms", args->duration_ms, "trigger: pulse length, ms")->capture_default_str();
  command.add_flag("--on", args->on, "backlight: switch it on");
  command.add_flag("--off", args->off, "backlight: switch it off");
  command.add_option("--steps-per-rev", args->steps_per_rev, "config: motor steps");
  command.add_option("--microsteps", args->microsteps, "config: microstepping");
  command.add_option("--gear", args->gear, "config: NUM:DEN, table revs = motor revs x DEN / NUM");
  command.add_option("--max-speed", args->max_speed, "config: microsteps/s");
  command.add_option("--acceleration", args->acceleration, "config: microsteps/s^2");
  command.add_option("--homing-speed", args->homing_speed, "config: microsteps/s");
  command.add_option("--backlash", args->backlash, "config: microsteps");
  dispatch.On(&command, [args](Io& io) { return RunTurntable(*args, io.out, io.err); });
}

void AddSimTurntableCommand(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<SimTurntableArgs>();
  command.add_option("--firmware", args->firmware, "firmware ELF");
  command.add_option("--link", args->link, "symlink to the PTY");
  command.add_option("--time-scale", args->time_scale, "simulated s per s")->capture_default_str();
  command.add_option("--seconds", args->seconds, "run time, 0 = until Ctrl-C")
      ->capture_default_str();
  dispatch.On(&command, [args](Io& io) { return RunSimTurntable(*args, io.out, io.err); });
}

}  // namespace carousel::app
