// Hardware in the loop: rig's serial turntable backend driving the real firmware ELF in
// simavr (sim::AvrTurntable) through a PTY. Assertions are on pin-level counts and
// simulated cycles, never on wall time.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/rig/serial_port.h"
#include "carousel/rig/serial_turntable.h"
#include "carousel/sim/avr_turntable.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using std::chrono::milliseconds;
constexpr auto kMoveTimeout = milliseconds(20000);

// Interrupt latency allowance on a STEP edge, cycles: the edge is written at the start of
// the timer ISR, which another ISR (UART, 1 ms tick) or a short atomic section can delay.
constexpr double kJitterCycles = 250.0;

struct StepRun {
  bool positive = true;
  std::vector<std::uint64_t> cycles;
};

// Consecutive steps in one direction.
std::vector<StepRun> Runs(const std::vector<sim::StepEdge>& steps) {
  std::vector<StepRun> runs;
  for (const auto& s : steps) {
    if (runs.empty() || runs.back().positive != s.positive) runs.push_back({s.positive, {}});
    runs.back().cycles.push_back(s.cycle);
  }
  return runs;
}

// Checks one run of steps against the speed and acceleration limits (steps/s, steps/s^2):
// every interval, and the speed change between windows of 16 steps. Returns the first
// violation, or "" when the run is within the profile.
std::string ProfileViolation(const StepRun& run, double f, double vmax, double a) {
  const auto& c = run.cycles;
  const double min_interval = f / vmax;
  for (std::size_t i = 1; i < c.size(); ++i)
    if (static_cast<double>(c[i] - c[i - 1]) < min_interval - 2 * kJitterCycles)
      return "step " + std::to_string(i) + " faster than " + std::to_string(vmax) + " steps/s";
  constexpr std::size_t kWindow = 16;
  std::vector<double> speed, span;
  for (std::size_t i = 0; i + kWindow < c.size(); i += kWindow) {
    const double t = static_cast<double>(c[i + kWindow] - c[i]);
    span.push_back(t / f);
    speed.push_back(kWindow * f / t);
    // The window's average speed: at most vmax (the timer rounds intervals up).
    if (speed.back() > vmax * (1.0 + 2 * kJitterCycles / t) + 1e-9)
      return "window at step " + std::to_string(i) + ": " + std::to_string(speed.back()) +
             " steps/s";
  }
  for (std::size_t i = 1; i < speed.size(); ++i) {
    const double dt = 0.5 * (span[i] + span[i - 1]);
    const double accel = std::abs(speed[i] - speed[i - 1]) / dt;
    // Jitter moves each window's ends by kJitterCycles.
    const double slack = (speed[i] * 2 * kJitterCycles / (span[i] * f) +
                          speed[i - 1] * 2 * kJitterCycles / (span[i - 1] * f)) /
                         dt;
    if (accel > a * 1.02 + slack)
      return "window " + std::to_string(i) + ": acceleration " + std::to_string(accel) +
             " steps/s^2";
  }
  return "";
}

class TurntableHil : public ::testing::Test {
 protected:
  void Start(std::int64_t sensor_width = 200) {
    sim::AvrTurntableOptions o;
    o.firmware = CAROUSEL_FIRMWARE_ELF;
    o.time_scale = 20.0;
    o.sensor_width = sensor_width;
    o.link = dir_.path() / "ttyTT0";
    sim_ = std::make_unique<sim::AvrTurntable>(o);
    rig::SerialTurntableOptions t;
    t.port = sim_->port();
    table_ = std::make_unique<rig::SerialTurntable>(t);
    config_ = table_->Config();
  }
  void SetUp() override { Start(); }
  void TearDown() override {
    if (!sim_) return;
    // No step pulse ever reaches a disabled driver.
    for (const auto& s : sim_->steps())
      ASSERT_TRUE(s.driver_enabled) << "step at cycle " << s.cycle;
  }
  void MoveAndWait(std::int32_t target) {
    table_->StartMoveToSteps(target);
    table_->WaitUntilStopped(kMoveTimeout);
  }

  testing::TempDir dir_;
  std::unique_ptr<sim::AvrTurntable> sim_;
  std::unique_ptr<rig::SerialTurntable> table_;
  cp_config config_{};
};

TEST_F(TurntableHil, IdentifiesItself) {
  const rig::TurntableInfo info = table_->Identify();
  EXPECT_EQ(info.model, "Carousel TT-328");
  EXPECT_NE(info.firmware.find("protocol 1.1"), std::string::npos) << info.firmware;
  EXPECT_EQ(info.port, sim_->port());
  EXPECT_EQ(config_.backlash, 32);
  EXPECT_NEAR(table_->AngleFromSteps(9600), 2 * M_PI, 1e-12);
}

TEST_F(TurntableHil, RandomMovesMatchStepCountsDirectionsAndProfile) {
  std::mt19937 random(7);
  std::uniform_int_distribution<std::int32_t> target_of(-6000, 6000);
  std::int32_t position = 0;
  const double f = sim_->frequency_hz();
  int reversals = 0;
  for (int move = 0; move < 60; ++move) {
    const std::int32_t target = move % 5 == 4 ? position : target_of(random);
    sim_->ClearLogs();
    if (move % 2 == 0) {
      table_->StartMoveToSteps(target);
    } else {
      table_->StartMoveBySteps(target - position);
    }
    table_->WaitUntilStopped(kMoveTimeout);
    const cp_status status = table_->RawStatus();
    ASSERT_EQ(status.position, target) << "move " << move;
    ASSERT_EQ(sim_->motor_steps(), target) << "move " << move;
    const auto runs = Runs(sim_->steps());
    const std::string what = "move " + std::to_string(move) + " " + std::to_string(position) +
                             " -> " + std::to_string(target);
    if (target > position) {
      ASSERT_EQ(runs.size(), 1u) << what;
      EXPECT_TRUE(runs[0].positive);
      EXPECT_EQ(runs[0].cycles.size(), static_cast<std::size_t>(target - position)) << what;
    } else if (target < position) {
      // Overshoot by the backlash, then approach upwards.
      ASSERT_EQ(runs.size(), 2u) << what;
      EXPECT_FALSE(runs[0].positive);
      EXPECT_EQ(runs[0].cycles.size(),
                static_cast<std::size_t>(position - target + config_.backlash))
          << what;
      EXPECT_TRUE(runs[1].positive);
      EXPECT_EQ(runs[1].cycles.size(), static_cast<std::size_t>(config_.backlash)) << what;
      ++reversals;
    } else {
      EXPECT_TRUE(runs.empty()) << what;
    }
    for (const StepRun& run : runs)
      EXPECT_EQ(ProfileViolation(run, f, config_.max_speed, config_.acceleration), "") << what;
    position = target;
  }
  EXPECT_GT(reversals, 15);
}

TEST_F(TurntableHil, ProfileCheckCatchesAViolation) {
  // The checker itself: a run that jumps to full speed must fail it.
  StepRun run;
  for (int i = 0; i < 200; ++i) run.cycles.push_back(static_cast<std::uint64_t>(i) * 4000u);
  run.cycles.insert(run.cycles.begin(), 0);
  for (auto& c : run.cycles) c += 100000;
  run.cycles[0] = 0;  // a long first interval, then 4000 steps/s at once
  EXPECT_NE(ProfileViolation(run, 16e6, 4000, 8000), "");
  // And a proper ramp passes: v_k^2 = 2 a k.
  StepRun ramp;
  double t = 0.0;
  for (int k = 1; k <= 400; ++k) {
    t += 16e6 / std::min(4000.0, std::sqrt(2.0 * 8000 * k));
    ramp.cycles.push_back(static_cast<std::uint64_t>(std::ceil(t)));
  }
  EXPECT_EQ(ProfileViolation(ramp, 16e6, 4000, 8000), "");
  // Twice the acceleration does not.
  StepRun fast;
  t = 0.0;
  for (int k = 1; k <= 400; ++k) {
    t += 16e6 / std::min(4000.0, std::sqrt(2.0 * 16000 * k));
    fast.cycles.push_back(static_cast<std::uint64_t>(std::ceil(t)));
  }
  EXPECT_NE(ProfileViolation(fast, 16e6, 4000, 8000), "");
}

TEST_F(TurntableHil, HomingFindsTheSensorEdge) {
  MoveAndWait(2500);
  table_->Home(kMoveTimeout);
  const cp_status status = table_->RawStatus();
  EXPECT_TRUE(status.flags & CP_FLAG_HOMED);
  EXPECT_EQ(status.fault, CP_FAULT_NONE);
  // Position 0 is the sensor's release edge when approached upwards: table position
  // `sensor_width` (modulo a revolution) in the harness's frame.
  const std::int64_t edge = sim_->table_position() - status.position;
  EXPECT_EQ(((edge % 9600) + 9600) % 9600, 200);
  // Positions after homing are relative to the edge.
  MoveAndWait(1000);
  EXPECT_EQ(((sim_->table_position() - 200) % 9600 + 9600) % 9600, 1000);
}

TEST_F(TurntableHil, HomingWithoutSensorFails) {
  sim_.reset();
  table_.reset();
  Start(/*sensor_width=*/0);
  try {
    table_->Home(kMoveTimeout);
    FAIL() << "homing without a sensor succeeded";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("home sensor not found"), std::string::npos) << e.what();
    EXPECT_EQ(e.device(), sim_->port());
  }
  EXPECT_FALSE(table_->Status().homed);
  // It searched 1.25 revolutions, no more.
  EXPECT_LE(std::abs(sim_->motor_steps()), 12000 + 100);
}

TEST_F(TurntableHil, StopDeceleratesAndEmergencyStopHaltsAtOnce) {
  const double f = sim_->frequency_hz();
  // The moves go far (500 s at full speed, 25 s of wall time at the simulator's 20x) so that a
  // test thread starved by a loaded machine cannot find them finished before it stops them.
  constexpr std::int32_t kFar = 2000000;
  table_->StartMoveToSteps(kFar);
  while (sim_->motor_steps() < 5000) std::this_thread::sleep_for(milliseconds(1));
  table_->Stop(false);
  const std::int64_t at_stop = sim_->motor_steps();
  table_->WaitUntilStopped(kMoveTimeout);
  const cp_status stopped = table_->RawStatus();
  EXPECT_EQ(stopped.position, sim_->motor_steps());
  EXPECT_LT(stopped.position, kFar);
  // Stopping distance from full speed: v^2 / 2a = 1000 steps.
  const double distance =
      static_cast<double>(config_.max_speed) * config_.max_speed / (2.0 * config_.acceleration);
  EXPECT_LE(sim_->motor_steps() - at_stop, distance + 2);
  for (const StepRun& run : Runs(sim_->steps()))
    EXPECT_EQ(ProfileViolation(run, f, config_.max_speed, config_.acceleration), "");

  table_->StartMoveToSteps(kFar);
  while (sim_->motor_steps() < stopped.position + 5000)
    std::this_thread::sleep_for(milliseconds(1));
  table_->Stop(true);
  const std::uint64_t acked = sim_->cycle();
  const auto steps = sim_->steps();
  EXPECT_EQ(
      std::count_if(steps.begin(), steps.end(), [&](const auto& s) { return s.cycle > acked; }), 0);
  const cp_status status = table_->RawStatus();
  EXPECT_FALSE(status.flags & CP_FLAG_MOVING);
  EXPECT_FALSE(status.flags & CP_FLAG_ENABLED);
  EXPECT_EQ(status.fault, CP_FAULT_ESTOP);
  EXPECT_EQ(status.position, sim_->motor_steps());
  EXPECT_EQ(table_->Status().fault, "emergency stop");
  // The driver is off after an emergency stop.
  const auto changes = sim_->enable_changes();
  ASSERT_FALSE(changes.empty());
  EXPECT_FALSE(changes.back().enabled);
  // A new move clears the fault.
  MoveAndWait(stopped.position);
  EXPECT_EQ(table_->RawStatus().fault, CP_FAULT_NONE);
}

TEST_F(TurntableHil, DriverEnableHasNoGlitchAtResetAndLeadsTheFirstStep) {
  // From power-on through the handshake, /ENABLE never went low.
  EXPECT_TRUE(sim_->enable_changes().empty());
  MoveAndWait(400);
  const auto changes = sim_->enable_changes();
  const auto steps = sim_->steps();
  ASSERT_GE(changes.size(), 2u);
  EXPECT_TRUE(changes.front().enabled);
  ASSERT_FALSE(steps.empty());
  // At least 2 ms between enabling the driver and its first step; disabled after the move.
  EXPECT_GE(steps.front().cycle - changes.front().cycle,
            static_cast<std::uint64_t>(0.002 * sim_->frequency_hz()));
  EXPECT_FALSE(changes.back().enabled);
  EXPECT_GT(changes.back().cycle, steps.back().cycle);
  // Hold keeps it enabled while idle.
  table_->SetHold(true);
  EXPECT_TRUE(table_->RawStatus().flags & CP_FLAG_ENABLED);
  table_->SetHold(false);
  EXPECT_FALSE(table_->RawStatus().flags & CP_FLAG_ENABLED);
}

TEST_F(TurntableHil, TriggerPulsesTheChosenOutputsForTheirDuration) {
  table_->Trigger(0x05, CP_OUTPUT_SHUTTER, 50);
  table_->Trigger(0x02, CP_OUTPUT_FOCUS, 1);  // replaces the running trigger
  std::this_thread::sleep_for(milliseconds(50));
  // Wait (simulated time) until every pulse ended.
  for (int i = 0; i < 200; ++i) {
    const auto pulses = sim_->output_pulses();
    if (!pulses.empty() &&
        std::all_of(pulses.begin(), pulses.end(), [](const auto& p) { return p.end_cycle != 0; }))
      break;
    std::this_thread::sleep_for(milliseconds(10));
  }
  const auto pulses = sim_->output_pulses();
  ASSERT_FALSE(pulses.empty());
  std::vector<int> outputs;
  for (const auto& p : pulses) {
    outputs.push_back(p.output);
    ASSERT_NE(p.end_cycle, 0u);
  }
  // The second trigger replaced the first: shutters 0 and 2 ended early, focus 1 (output 5)
  // lasted 1 ms.
  EXPECT_NE(std::find(outputs.begin(), outputs.end(), 0), outputs.end());
  EXPECT_NE(std::find(outputs.begin(), outputs.end(), 2), outputs.end());
  EXPECT_NE(std::find(outputs.begin(), outputs.end(), 5), outputs.end());
  EXPECT_EQ(std::find(outputs.begin(), outputs.end(), 1), outputs.end());
  for (const auto& p : pulses)
    if (p.output == 5) {
      const double ms = (p.end_cycle - p.start_cycle) * 1000.0 / sim_->frequency_hz();
      EXPECT_GE(ms, 0.0);
      EXPECT_LE(ms, 1.01);
    }
  // A single trigger lasts its duration (1 ms tick).
  sim_->ClearLogs();
  table_->Trigger(0x08, CP_OUTPUT_SHUTTER | CP_OUTPUT_FOCUS, 40);
  for (int i = 0; i < 300; ++i) {
    const auto p = sim_->output_pulses();
    if (p.size() == 2 && p[0].end_cycle != 0 && p[1].end_cycle != 0) break;
    std::this_thread::sleep_for(milliseconds(10));
  }
  const auto both = sim_->output_pulses();
  ASSERT_EQ(both.size(), 2u);
  for (const auto& p : both) {
    EXPECT_TRUE(p.output == 3 || p.output == 7) << p.output;
    const double ms = (p.end_cycle - p.start_cycle) * 1000.0 / sim_->frequency_hz();
    EXPECT_GE(ms, 39.0);
    EXPECT_LE(ms, 41.0);
  }
  EXPECT_THROW(table_->Trigger(0x10, CP_OUTPUT_SHUTTER, 10), InvalidArgument);
}

// The backlight output at pin level: off from reset, switched by LIGHT at once (moving or not),
// reported in the status, untouched by a move and an emergency stop, off again after a reset.
TEST_F(TurntableHil, BacklightSwitchesItsPinAndIsOffAfterEveryReset) {
  EXPECT_FALSE(sim_->backlight_on());
  EXPECT_FALSE(table_->Status().backlight);
  for (const auto& p : sim_->output_pulses()) EXPECT_NE(p.output, sim::kBacklightOutput);
  sim_->ClearLogs();
  const std::uint64_t before_on = sim_->cycle();
  table_->SetBacklight(true);
  EXPECT_TRUE(sim_->backlight_on());  // switched by the time the ACK arrived
  EXPECT_TRUE(table_->Status().backlight);
  EXPECT_TRUE(table_->RawStatus().flags & CP_FLAG_BACKLIGHT);
  // A move and an emergency stop leave it on; the light never blinks meanwhile.
  table_->StartMoveToSteps(2000);
  std::this_thread::sleep_for(milliseconds(20));
  EXPECT_TRUE(sim_->backlight_on());
  table_->Stop(/*emergency=*/true);
  table_->WaitUntilStopped(kMoveTimeout);
  EXPECT_TRUE(sim_->backlight_on());
  table_->SetBacklight(false);
  EXPECT_FALSE(sim_->backlight_on());
  EXPECT_FALSE(table_->Status().backlight);
  std::vector<sim::OutputPulse> light;
  for (const auto& p : sim_->output_pulses())
    if (p.output == sim::kBacklightOutput) light.push_back(p);
  ASSERT_EQ(light.size(), 1u);  // one on-time: no glitch while moving or stopping
  EXPECT_GT(light[0].start_cycle, before_on);
  EXPECT_GT(light[0].end_cycle, light[0].start_cycle);
  // Switching twice is idempotent: no second edge.
  table_->SetBacklight(false);
  const std::vector<sim::OutputPulse> after = sim_->output_pulses();
  EXPECT_EQ(std::count_if(after.begin(), after.end(),
                          [](const auto& p) { return p.output == sim::kBacklightOutput; }),
            1);
  // A reset (DTR) turns it off: the pin is an input until the firmware drives it low again.
  table_->SetBacklight(true);
  ASSERT_TRUE(sim_->backlight_on());
  sim_->Reset(/*mcusr=*/2);
  EXPECT_FALSE(sim_->backlight_on());
  EXPECT_FALSE(table_->Status().backlight);  // the host shook hands again
  EXPECT_FALSE(sim_->backlight_on());
  table_->SetBacklight(true);
  EXPECT_TRUE(sim_->backlight_on());
  table_->SetBacklight(false);
}

TEST_F(TurntableHil, ConfigurationIsValidatedAndApplied) {
  cp_config c = config_;
  c.max_speed = 2000;
  c.acceleration = 3000;
  c.backlash = 100;
  const cp_config stored = table_->SetConfig(c);
  EXPECT_EQ(stored.max_speed, 2000);
  EXPECT_EQ(table_->Config().backlash, 100);
  sim_->ClearLogs();
  MoveAndWait(3000);
  MoveAndWait(1000);
  const auto runs = Runs(sim_->steps());
  ASSERT_EQ(runs.size(), 3u);
  EXPECT_EQ(runs[1].cycles.size(), 2100u);
  EXPECT_EQ(runs[2].cycles.size(), 100u);
  for (const StepRun& run : runs)
    EXPECT_EQ(ProfileViolation(run, sim_->frequency_hz(), 2000, 3000), "");
  c.acceleration = 10;
  EXPECT_THROW(table_->SetConfig(c), InvalidArgument);
  // Refused while moving.
  table_->StartMoveToSteps(20000);
  c.acceleration = 3000;
  EXPECT_THROW(table_->SetConfig(c), DeviceError);
  table_->Stop(true);
}

TEST_F(TurntableHil, ConfigurationSurvivesAResetAndTheHostShakesHandsAgain) {
  cp_config c = config_;
  c.backlash = 77;
  c.max_speed = 3000;
  table_->SetConfig(c);
  MoveAndWait(1500);
  table_->Home(kMoveTimeout);
  ASSERT_TRUE(table_->Status().homed);
  // A reset, as DTR gives an Arduino: RAM is gone, EEPROM is not.
  sim_->Reset(/*mcusr=*/2);
  const cp_config after = table_->Config();
  EXPECT_EQ(after.backlash, 77);
  EXPECT_EQ(after.max_speed, 3000);
  const cp_status status = table_->RawStatus();
  EXPECT_FALSE(status.flags & CP_FLAG_HOMED);  // the position is no longer known
  EXPECT_EQ(status.position, 0);
  EXPECT_EQ(status.fault, CP_FAULT_NONE);
  // The reset went without a glitch on /ENABLE and without a step.
  const auto changes = sim_->enable_changes();
  ASSERT_FALSE(changes.empty());
  EXPECT_FALSE(changes.back().enabled);
  // Moves work again after the new handshake.
  sim_->ClearLogs();
  MoveAndWait(500);
  EXPECT_EQ(sim_->steps().size(), 500u);
}

TEST_F(TurntableHil, WatchdogIsArmedKickedAndReported) {
  // WDTCSR (0x60): WDE with the 500 ms prescaler (WDP2 | WDP0).
  EXPECT_EQ(sim_->ReadData(0x60) & 0x2Fu, 0x08u | 0x05u);
  table_->RawStatus();
  // The power-on BOOT event may arrive after the port opened; count restarts from here.
  const std::uint64_t boots = table_->counters().resets_seen;
  // Kicked while idle and while moving: 2 s idle (simulated) and a long move, no restart.
  const std::uint64_t start = sim_->cycle();
  while (sim_->cycle() - start < static_cast<std::uint64_t>(2.0 * sim_->frequency_hz()))
    std::this_thread::sleep_for(milliseconds(10));
  MoveAndWait(9600);
  table_->RawStatus();
  EXPECT_EQ(table_->counters().resets_seen, boots);
  EXPECT_EQ(table_->RawStatus().position, 9600);
  // A watchdog reset is reported as a fault after the restart.
  sim_->Reset(/*mcusr=*/8);
  EXPECT_EQ(table_->RawStatus().fault, CP_FAULT_WATCHDOG);
  EXPECT_EQ(table_->Status().fault, "controller restarted by its watchdog");
  EXPECT_GT(table_->counters().resets_seen, boots);
}

// Raw frames to the firmware, bypassing the backend.
class RawLink {
 public:
  explicit RawLink(const std::string& path) : port_(path, 115200) { cp_decoder_init(&decoder_); }
  // Sends `f` and returns the next reply (events skipped); fails the test after 2 s.
  cp_frame Exchange(const cp_frame& f) {
    std::uint8_t wire[CP_MAX_WIRE];
    const int n = cp_encode(&f, wire, sizeof wire);
    port_.Write(std::span(wire, static_cast<std::size_t>(n)), milliseconds(500));
    std::uint8_t buffer[64];
    for (int i = 0; i < 40; ++i) {
      const std::size_t got = port_.Read(buffer, milliseconds(50));
      for (std::size_t k = 0; k < got; ++k) {
        cp_frame reply{};
        if (cp_decoder_push(&decoder_, buffer[k], &reply) != 1) continue;
        if (reply.type >= CP_EVENT_BOOT && reply.type < CP_NAK) continue;
        return reply;
      }
    }
    ADD_FAILURE() << "no reply to " << cp_type_name(f.type);
    return {};
  }

 private:
  rig::SerialPort port_;
  cp_decoder decoder_{};
};

cp_frame Frame(std::uint8_t type, std::uint8_t seq, std::initializer_list<std::uint8_t> payload) {
  cp_frame f{};
  cp_make_frame(&f, type, seq, std::data(payload), payload.size());
  return f;
}

TEST(TurntableFirmware, VersionHandshakeAndIdempotentReplays) {
  testing::TempDir dir;
  sim::AvrTurntableOptions o;
  o.firmware = CAROUSEL_FIRMWARE_ELF;
  o.time_scale = 20.0;
  sim::AvrTurntable sim(o);
  RawLink link(sim.port());
  // Before HELLO: identify works, moves are refused.
  cp_frame reply = link.Exchange(Frame(CP_IDENTIFY, 1, {}));
  EXPECT_EQ(reply.type, CP_IDENTIFY | CP_ACK_FLAG);
  cp_frame move = Frame(CP_MOVE_REL, 2, {0xE8, 0x03, 0, 0});  // +1000
  reply = link.Exchange(move);
  ASSERT_EQ(reply.type, CP_NAK);
  EXPECT_EQ(-static_cast<int>(reply.payload[1]), CP_ERR_VERSION);
  // An incompatible major version is refused.
  reply = link.Exchange(Frame(CP_HELLO, 3, {CP_VERSION_MAJOR + 1, 0}));
  ASSERT_EQ(reply.type, CP_NAK);
  EXPECT_EQ(-static_cast<int>(reply.payload[1]), CP_ERR_VERSION);
  reply = link.Exchange(Frame(CP_HELLO, 4, {CP_VERSION_MAJOR, 7}));
  ASSERT_EQ(reply.type, CP_HELLO | CP_ACK_FLAG);
  EXPECT_EQ(reply.payload[2] & 1u, 1u);  // power-on reset
  // A relative move sent three times with the same sequence number moves once; the same
  // reply comes back each time.
  move.seq = 5;
  const cp_frame first = link.Exchange(move);
  ASSERT_EQ(first.type, CP_MOVE_REL | CP_ACK_FLAG);
  for (int i = 0; i < 2; ++i) {
    const cp_frame again = link.Exchange(move);
    EXPECT_EQ(again.type, first.type);
    EXPECT_EQ(again.seq, 5);
    EXPECT_TRUE(std::equal(first.payload, first.payload + first.len, again.payload));
  }
  cp_status status{};
  for (std::uint8_t seq = 6; seq < 250; ++seq) {
    cp_get_status(&(reply = link.Exchange(Frame(CP_STATUS, seq, {}))), &status);
    if (!(status.flags & CP_FLAG_MOVING)) break;
    std::this_thread::sleep_for(milliseconds(20));
  }
  EXPECT_EQ(status.position, 1000);
  EXPECT_EQ(sim.motor_steps(), 1000);
  // The same sequence number with another command is a new command.
  move.type = CP_MOVE_ABS;
  reply = link.Exchange(move);
  EXPECT_EQ(reply.type, CP_MOVE_ABS | CP_ACK_FLAG);
  // Unknown commands and short payloads are refused with their reason.
  reply = link.Exchange(Frame(0x3E, 9, {}));
  ASSERT_EQ(reply.type, CP_NAK);
  EXPECT_EQ(-static_cast<int>(reply.payload[1]), CP_ERR_UNKNOWN);
  // LIGHT (1.1): lights the firmware does not have, and no payload, are refused; the pin
  // stays as it was.
  reply = link.Exchange(Frame(CP_LIGHT, 10, {0x02}));
  ASSERT_EQ(reply.type, CP_NAK);
  EXPECT_EQ(-static_cast<int>(reply.payload[1]), CP_ERR_RANGE);
  reply = link.Exchange(Frame(CP_LIGHT, 11, {}));
  ASSERT_EQ(reply.type, CP_NAK);
  EXPECT_EQ(-static_cast<int>(reply.payload[1]), CP_ERR_LENGTH);
  EXPECT_FALSE(sim.backlight_on());
  reply = link.Exchange(Frame(CP_LIGHT, 12, {CP_LIGHT_BACKLIGHT}));
  ASSERT_EQ(reply.type, CP_LIGHT | CP_ACK_FLAG);
  ASSERT_EQ(cp_get_status(&reply, &status), CP_OK);
  EXPECT_TRUE(status.flags & CP_FLAG_BACKLIGHT);
  EXPECT_TRUE(sim.backlight_on());
}

TEST_F(TurntableHil, CorruptedAndLossyLineNeverMovesWrongOrTwice) {
  // 1 % of the bytes corrupted and 1 % dropped, both directions, for >= 10,000 frames.
  table_.reset();
  rig::SerialTurntableOptions t;
  t.port = sim_->port();
  t.reply_timeout_ms = 10;
  t.max_retries = 3;  // few enough that some commands are reported failed
  table_ = std::make_unique<rig::SerialTurntable>(t);
  sim::LineFaults faults;
  faults.corrupt_probability = 0.01;
  faults.drop_probability = 0.01;
  faults.seed = 5;
  sim_->SetLineFaults(faults);
  std::mt19937 random(9);
  std::int64_t expected = 0;
  int acknowledged = 0, failed = 0, moves = 0;
  // Resolves a failed command: asks the controller (retrying) where it is.
  auto settle = [&]() -> cp_status {
    for (int i = 0; i < 50; ++i) {
      try {
        const cp_status s = table_->RawStatus();
        if (!(s.flags & CP_FLAG_MOVING)) return s;
      } catch (const DeviceError&) {
      }
      std::this_thread::sleep_for(milliseconds(5));
    }
    ADD_FAILURE() << "the controller never settled";
    return {};
  };
  while (true) {
    const rig::LinkCounters c = table_->counters();
    // Frames on the line: the host's (each attempt) and the controller's (a status reply is
    // 19 bytes, the longest; counting by it underestimates).
    if (c.commands + c.retransmissions + sim_->line_counters().bytes_from_controller / 19 >= 10500)
      break;
    const bool move = random() % 8 == 0;
    try {
      if (move) {
        const auto delta = static_cast<std::int32_t>(random() % 200) - 100;
        table_->StartMoveBySteps(delta);
        expected += delta;
        ++moves;
        const cp_status s = settle();
        ASSERT_EQ(s.position, expected) << "after move " << moves;
      } else {
        const cp_status s = table_->RawStatus();
        ASSERT_EQ(s.position, expected);
      }
      ++acknowledged;
    } catch (const DeviceError& e) {
      // Reported failed to the caller: it may or may not have executed; the controller says.
      ++failed;
      const cp_status s = settle();
      ASSERT_TRUE(s.position == expected || move) << e.what();
      expected = s.position;
    }
    ASSERT_EQ(sim_->motor_steps(), expected) << "the motor moved without a command";
  }
  sim_->SetLineFaults({});
  const rig::LinkCounters c = table_->counters();
  const sim::LineCounters line = sim_->line_counters();
  std::printf(
      "line: %llu commands, %llu retransmissions, %llu failed, %d moves; %llu bytes corrupted, "
      "%llu dropped\n",
      static_cast<unsigned long long>(c.commands),
      static_cast<unsigned long long>(c.retransmissions), static_cast<unsigned long long>(c.failed),
      moves, static_cast<unsigned long long>(line.corrupted),
      static_cast<unsigned long long>(line.dropped));
  EXPECT_GT(line.corrupted, 600u);
  EXPECT_GT(line.dropped, 600u);
  EXPECT_GT(c.retransmissions, 200u);
  EXPECT_GT(failed, 20);  // the failure path was exercised, moves included
  EXPECT_GT(moves, 200);
  EXPECT_GT(acknowledged, 2000);
  EXPECT_EQ(table_->RawStatus().position, sim_->motor_steps());
}

TEST_F(TurntableHil, SlowLineCausesRetransmissionsButEveryMoveHappensOnce) {
  // Commands arrive 2.5 s (simulated; 125 ms of wall time at this time scale) late: longer
  // than the host's 100 ms reply timeout, so commands are sent again and replies replayed.
  sim::LineFaults faults;
  faults.delay_cycles = static_cast<std::uint64_t>(2.5 * sim_->frequency_hz());
  sim_->SetLineFaults(faults);
  for (int i = 0; i < 5; ++i) {
    table_->StartMoveBySteps(300);
    table_->WaitUntilStopped(kMoveTimeout);
  }
  EXPECT_GT(table_->counters().retransmissions, 5u);
  EXPECT_GT(table_->counters().stale_replies, 0u);
  EXPECT_EQ(table_->RawStatus().position, 1500);
  EXPECT_EQ(sim_->motor_steps(), 1500);
}

TEST_F(TurntableHil, UnplugMidMoveIsADeviceErrorAndReconnectReportsTheTruePosition) {
  table_->StartMoveToSteps(20000);
  while (sim_->motor_steps() < 2000) std::this_thread::sleep_for(milliseconds(1));
  sim_->Unplug();
  const auto start = std::chrono::steady_clock::now();
  try {
    table_->WaitUntilStopped(kMoveTimeout);
    FAIL() << "no error after unplugging";
  } catch (const DeviceError& e) {
    EXPECT_EQ(e.device(), sim_->port());
    EXPECT_NE(std::string(e.what()).find("disconnected"), std::string::npos) << e.what();
  }
  // Within the reply timeout and its retries, not the move's timeout.
  EXPECT_LT(std::chrono::steady_clock::now() - start, milliseconds(1000));
  // The controller kept moving while unplugged.
  const std::int64_t before = sim_->motor_steps();
  std::this_thread::sleep_for(milliseconds(50));
  sim_->Replug();
  table_->Reconnect();
  table_->WaitUntilStopped(kMoveTimeout);
  EXPECT_GE(sim_->motor_steps(), before);
  const cp_status status = table_->RawStatus();
  EXPECT_EQ(status.position, 20000);
  EXPECT_EQ(status.position, sim_->motor_steps());
}

}  // namespace
}  // namespace carousel
