// Hardware in the loop: the real turntable firmware (an AVR ELF) running in simavr, its UART
// bridged to a pseudo-terminal that rig's serial backend opens like a USB-serial port.
//
// The harness plays the board around the ATmega328P (pins: firmware-protocol/PROTOCOL.md
// section 6): it logs every STEP rising edge with the simulated cycle, the DIR level and
// whether the driver was enabled (its /ENABLE has a pull-up, so an input pin reads as
// disabled); it logs the /ENABLE level changes from reset, the shutter/focus pulses and the
// backlight's on-times (an output like the others); it
// models the turntable's home sensor (active while the table's position, modulo a
// revolution, is in [0, width) steps); and it can corrupt, drop or delay bytes on the line
// and unplug or re-plug the port. Times are simulated CPU cycles (16 MHz), never wall time.
//
// simavr 1.6 pitfalls handled here (../shared/reference/rig-notes.md section 2): the MCU and
// frequency are set from the options (no .mmcu section needed), the INT0/INT1 level-trigger
// poll is switched off, the PTY's slave stays open in raw mode so reads never fail with EIO,
// and each harness makes its own PTY (no fixed /tmp/simavr-uart0 symlink).
#pragma once

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace carousel::sim {

struct AvrTurntableOptions {
  std::filesystem::path firmware;  // the ELF (build/firmware/turntable.elf)
  std::string mcu = "atmega328p";
  std::uint32_t frequency_hz = 16000000;
  // Simulated seconds per wall second while the firmware sleeps (>= 1; busy code runs as
  // fast as the host allows). 1 = real time.
  double time_scale = 1.0;
  // The home sensor: microsteps per table revolution (the firmware's default configuration
  // makes 9600), the table's position at power-on and the sensor's width, in microsteps.
  std::int64_t steps_per_rev = 9600;
  std::int64_t start_position = 4000;
  std::int64_t sensor_width = 200;  // 0: no sensor (homing must fail)
  // When set, a symlink kept pointing at the current PTY, like a udev by-id name: it stays
  // the same across Unplug()/Replug(); port() returns it.
  std::filesystem::path link;
  void Validate() const;
};

struct StepEdge {
  std::uint64_t cycle = 0;
  bool positive = true;        // DIR high
  bool driver_enabled = true;  // /ENABLE low at the edge
};

struct EnableChange {
  std::uint64_t cycle = 0;
  bool enabled = false;
};

// The output the backlight (PB4) is logged as among the pulses.
inline constexpr int kBacklightOutput = 8;

struct OutputPulse {
  // 0..3 shutter of camera 0..3, 4..7 focus of camera 0..3, kBacklightOutput the backlight
  int output = 0;
  std::uint64_t start_cycle = 0;
  std::uint64_t end_cycle = 0;  // 0 while still high
};

// Faults on the line, applied to each byte in both directions.
struct LineFaults {
  double corrupt_probability = 0.0;  // a byte replaced by a different random byte
  double drop_probability = 0.0;     // a byte lost
  std::uint64_t delay_cycles = 0;    // extra latency of host-to-controller bytes
  std::uint64_t seed = 1;
};

struct LineCounters {
  std::uint64_t bytes_to_controller = 0;
  std::uint64_t bytes_from_controller = 0;
  std::uint64_t corrupted = 0;
  std::uint64_t dropped = 0;
};

class AvrTurntable {
 public:
  // Loads the ELF and starts the simulation thread. \throw IoError (firmware missing or not
  // an ELF), DeviceError (simavr refuses the MCU, no PTY).
  explicit AvrTurntable(const AvrTurntableOptions& options);
  ~AvrTurntable();
  AvrTurntable(const AvrTurntable&) = delete;
  AvrTurntable& operator=(const AvrTurntable&) = delete;

  // The PTY's slave path while plugged in ("/dev/pts/N", a fresh one after Replug()), or the
  // stable `link` when set.
  std::string port() const;
  // Closes the PTY (the host sees the device vanish); the firmware keeps running, its output
  // is lost. Replug() opens a new PTY.
  void Unplug();
  void Replug();

  // Resets the MCU as `mcusr` says (MCUSR bits: 1 power-on, 2 external, e.g. DTR on an
  // Arduino, 8 watchdog). RAM and registers restart; flash and EEPROM keep their content;
  // bytes in flight are lost. The motor and the sensor stay where they are.
  void Reset(std::uint8_t mcusr);
  // A byte of the MCU's data space (registers, I/O, RAM), e.g. WDTCSR at 0x60.
  std::uint8_t ReadData(std::uint16_t address) const;

  void SetLineFaults(const LineFaults& faults);
  LineCounters line_counters() const;

  std::uint64_t cycle() const;
  double frequency_hz() const;
  // The motor's net position in microsteps since power-on (signed STEP edges).
  std::int64_t motor_steps() const;
  // The table position the sensor model sees: start_position + motor_steps().
  std::int64_t table_position() const;
  bool sensor_active() const;
  // The backlight output's level (PB4 driven high; an input pin is off: the board's pull-down).
  bool backlight_on() const;

  std::vector<StepEdge> steps() const;
  std::vector<EnableChange> enable_changes() const;
  std::vector<OutputPulse> output_pulses() const;
  void ClearLogs();

  struct State;  // the simulation's internals (sim/src/avr_turntable.cpp)

 private:
  std::unique_ptr<State> state_;
};

}  // namespace carousel::sim
