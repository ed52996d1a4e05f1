#include "carousel/sim/avr_turntable.h"

#include <fcntl.h>
#include <poll.h>
#include <pty.h>
#include <termios.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <mutex>
#include <random>
#include <thread>

extern "C" {
#include <simavr/avr_extint.h>
#include <simavr/avr_ioport.h>
#include <simavr/avr_uart.h>
#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>
#include <simavr/sim_io.h>
#include <simavr/sim_irq.h>
}

#include "carousel/core/error.h"

namespace carousel::sim {
namespace {

// Pins (PROTOCOL.md section 6).
constexpr std::uint8_t kStepBit = 1u << 2;       // PD2
constexpr std::uint8_t kDirBit = 1u << 5;        // PD5
constexpr std::uint8_t kEnableBit = 1u << 0;     // PB0, active low, external pull-up
constexpr int kHomePin = 1;                      // PB1, active low
constexpr std::uint8_t kBacklightBit = 1u << 4;  // PB4, active high, pull-down on the board
// Instructions per batch between looks at the PTY.
constexpr int kBatch = 4000;

// The harness whose thread is running the AVR (simavr's sleep callback has no user pointer).
thread_local AvrTurntable::State* t_running = nullptr;

std::int64_t Modulo(std::int64_t a, std::int64_t n) { return ((a % n) + n) % n; }

}  // namespace

void AvrTurntableOptions::Validate() const {
  auto check = [](bool ok, const char* field, const char* rule) {
    if (!ok)
      throw InvalidArgument(std::string("AvrTurntableOptions.") + field + " must be " + rule);
  };
  check(!firmware.empty(), "firmware", "set");
  check(frequency_hz >= 1000000, "frequency_hz", ">= 1 MHz");
  check(time_scale >= 1.0, "time_scale", ">= 1");
  check(steps_per_rev > 0, "steps_per_rev", "> 0");
  check(sensor_width >= 0 && sensor_width < steps_per_rev, "sensor_width", "in [0, steps_per_rev)");
}

struct AvrTurntable::State {
  AvrTurntableOptions options;
  avr_t* avr = nullptr;
  elf_firmware_t firmware{};

  mutable std::mutex mutex;
  std::thread thread;
  std::atomic<bool> quit{false};

  // Line.
  int master = -1;
  int slave = -1;  // kept open so the master never reads EIO
  std::string slave_path;
  bool plugged = false;
  std::deque<std::pair<std::uint64_t, std::uint8_t>> to_avr;  // (due cycle, byte)
  std::deque<std::uint8_t> to_host;
  bool xoff = true;  // until the UART enables its receiver (XON)
  LineFaults faults;
  std::mt19937_64 random{1};
  LineCounters counters;

  // Pins.
  std::uint8_t port_b = 0, ddr_b = 0, port_c = 0, port_d = 0, ddr_d = 0;
  bool enabled = false;
  bool backlight = false;
  std::int64_t motor_steps = 0;
  bool sensor = false;
  std::vector<StepEdge> steps;
  std::vector<EnableChange> enable_changes;
  std::vector<OutputPulse> pulses;
  std::uint64_t sleep_cycles = 0;

  avr_irq_t* home_irq = nullptr;
  avr_irq_t* uart_input = nullptr;

  // ---- pins -------------------------------------------------------------------------------
  bool EffectiveEnable() const {
    // Input: the pull-up holds /ENABLE high (disabled).
    const bool level = (ddr_b & kEnableBit) ? (port_b & kEnableBit) != 0 : true;
    return !level;
  }
  void UpdateEnable() {
    const bool now = EffectiveEnable();
    if (now != enabled) {
      enabled = now;
      enable_changes.push_back({avr->cycle, now});
    }
  }
  // The backlight's driver: an input pin leaves it to the board's pull-down (off).
  void UpdateBacklight() {
    const bool now = (ddr_b & kBacklightBit) != 0 && (port_b & kBacklightBit) != 0;
    RecordOutput(kBacklightOutput, backlight, now);
    backlight = now;
  }
  void UpdateSensor() {
    const std::int64_t at = Modulo(options.start_position + motor_steps, options.steps_per_rev);
    const bool active = at < options.sensor_width;
    if (active == sensor && home_irq->value == (active ? 0u : 1u)) return;
    sensor = active;
    avr_ioport_external_t external{};
    external.name = 'B';
    external.mask = 1u << kHomePin;
    external.value = active ? 0 : (1u << kHomePin);
    avr_ioctl(avr, AVR_IOCTL_IOPORT_SET_EXTERNAL('B'), &external);
    avr_raise_irq(home_irq, active ? 0 : 1);
  }
  void OnPortD(std::uint8_t value) {
    const std::uint8_t before = port_d;
    port_d = value;
    if ((ddr_d & kStepBit) && !(before & kStepBit) && (value & kStepBit)) {
      const bool positive = (value & kDirBit) != 0;
      steps.push_back({avr->cycle, positive, enabled});
      motor_steps += positive ? 1 : -1;
      UpdateSensor();
    }
    for (int bit = 6; bit < 8; ++bit)  // focus 2, 3 on PD6, PD7
      RecordOutput(bit, ((before >> bit) & 1u) != 0, ((value >> bit) & 1u) != 0);
  }
  void OnPortC(std::uint8_t value) {
    const std::uint8_t before = port_c;
    port_c = value;
    // Shutter 0..3 on PC0..PC3, focus 0, 1 on PC4, PC5: outputs 0..5.
    for (int bit = 0; bit < 6; ++bit)
      RecordOutput(bit, ((before >> bit) & 1u) != 0, ((value >> bit) & 1u) != 0);
  }
  void RecordOutput(int output, bool before, bool after) {
    if (before == after) return;
    if (after) {
      pulses.push_back({output, avr->cycle, 0});
    } else {
      for (auto it = pulses.rbegin(); it != pulses.rend(); ++it)
        if (it->output == output && it->end_cycle == 0) {
          it->end_cycle = avr->cycle;
          break;
        }
    }
  }

  // ---- line -------------------------------------------------------------------------------
  // Applies the faults to one byte; false when it is dropped.
  bool Mangle(std::uint8_t* byte) {
    std::uniform_real_distribution<double> uniform(0.0, 1.0);
    if (faults.drop_probability > 0.0 && uniform(random) < faults.drop_probability) {
      ++counters.dropped;
      return false;
    }
    if (faults.corrupt_probability > 0.0 && uniform(random) < faults.corrupt_probability) {
      std::uniform_int_distribution<int> flip(1, 255);
      *byte = static_cast<std::uint8_t>(*byte ^ flip(random));
      ++counters.corrupted;
    }
    return true;
  }
  void FeedAvr() {
    while (!xoff && !to_avr.empty() && to_avr.front().first <= avr->cycle) {
      const std::uint8_t byte = to_avr.front().second;
      to_avr.pop_front();
      avr_raise_irq(uart_input, byte);
    }
  }
  void OpenPty() {
    int m = -1, s = -1;
    char name[256] = {};
    if (openpty(&m, &s, name, nullptr, nullptr) != 0)
      throw DeviceError("simavr turntable", std::string("openpty failed: ") + std::strerror(errno));
    termios tio{};
    tcgetattr(s, &tio);
    cfmakeraw(&tio);
    tcsetattr(s, TCSANOW, &tio);
    tcgetattr(m, &tio);
    cfmakeraw(&tio);
    tcsetattr(m, TCSANOW, &tio);
    fcntl(m, F_SETFL, fcntl(m, F_GETFL) | O_NONBLOCK);
    master = m;
    slave = s;
    slave_path = name;
    plugged = true;
    if (!options.link.empty()) {
      std::error_code ec;
      std::filesystem::remove(options.link, ec);
      std::filesystem::create_symlink(slave_path, options.link, ec);
      if (ec) throw DeviceError(options.link.string(), "cannot link the PTY: " + ec.message());
    }
  }
  void ClosePty() {
    if (master >= 0) close(master);
    if (slave >= 0) close(slave);
    master = slave = -1;
    plugged = false;
    to_avr.clear();
    to_host.clear();
  }
  // Moves bytes between the PTY and the UART queues (non-blocking).
  void ServiceLine() {
    if (!plugged) {
      to_host.clear();
      return;
    }
    std::uint8_t buffer[256];
    while (true) {
      const ssize_t n = read(master, buffer, sizeof buffer);
      if (n <= 0) break;
      for (ssize_t i = 0; i < n; ++i) {
        std::uint8_t byte = buffer[i];
        ++counters.bytes_to_controller;
        if (Mangle(&byte)) to_avr.emplace_back(avr->cycle + faults.delay_cycles, byte);
      }
    }
    while (!to_host.empty()) {
      std::uint8_t out[256];
      std::size_t n = 0;
      while (n < sizeof out && n < to_host.size()) {
        out[n] = to_host[n];
        ++n;
      }
      const ssize_t written = write(master, out, n);
      if (written <= 0) break;
      to_host.erase(to_host.begin(), to_host.begin() + written);
    }
    FeedAvr();
  }

  void Run() {
    using Clock = std::chrono::steady_clock;
    t_running = this;
    auto wall_start = Clock::now();
    std::uint64_t sim_start = 0;
    {
      std::lock_guard lock(mutex);
      sim_start = avr->cycle;
    }
    while (!quit.load()) {
      bool slept = false;
      {
        std::lock_guard lock(mutex);
        for (int i = 0; i < kBatch; ++i) {
          const int state = avr_run(avr);
          if (state == cpu_Done || state == cpu_Crashed) {
            quit = true;
            break;
          }
          if (sleep_cycles > options.frequency_hz / 2000) break;  // 0.5 ms asleep
        }
        ServiceLine();
        // Pace only an idle line: bytes due are delivered at simulated speed (a delayed byte
        // is not due yet, and its delay is simulated time like the rest).
        slept = sleep_cycles > 0 && to_host.empty() &&
                (to_avr.empty() || to_avr.front().first > avr->cycle);
        sleep_cycles = 0;
      }
      if (slept) {
        // Keep simulated time at most time_scale x wall time while the firmware sleeps.
        std::uint64_t now_cycle;
        {
          std::lock_guard lock(mutex);
          now_cycle = avr->cycle;
        }
        const double sim_s = static_cast<double>(now_cycle - sim_start) / options.frequency_hz;
        const auto due =
            wall_start + std::chrono::duration_cast<Clock::duration>(
                             std::chrono::duration<double>(sim_s / options.time_scale));
        const auto now = Clock::now();
        if (due > now + std::chrono::milliseconds(1)) {
          // Wait, but wake at once when the host sends something.
          int fd = -1;
          {
            std::lock_guard lock(mutex);
            fd = master;
          }
          const auto wait = std::min<Clock::duration>(due - now, std::chrono::milliseconds(5));
          const int wait_ms =
              static_cast<int>(std::chrono::ceil<std::chrono::milliseconds>(wait).count());
          if (fd >= 0) {
            pollfd p{fd, POLLIN, 0};
            poll(&p, 1, wait_ms);
          } else {
            std::this_thread::sleep_for(wait);
          }
        } else if (now - due > std::chrono::milliseconds(50)) {
          // Busy code ran slower than the scale allows: do not catch up in a burst.
          wall_start = now - std::chrono::duration_cast<Clock::duration>(
                                 std::chrono::duration<double>(sim_s / options.time_scale));
        }
      }
    }
  }
};

namespace {

AvrTurntable::State* StateOf(void* param) { return static_cast<AvrTurntable::State*>(param); }

}  // namespace

AvrTurntable::AvrTurntable(const AvrTurntableOptions& options) : state_(std::make_unique<State>()) {
  options.Validate();
  State& s = *state_;
  s.options = options;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(options.firmware, ec))
    throw IoError(options.firmware,
                  "turntable firmware not found (build the target turntable_firmware)");
  std::memset(&s.firmware, 0, sizeof s.firmware);
  if (elf_read_firmware(options.firmware.c_str(), &s.firmware) != 0)
    throw FormatError(options.firmware, "not an AVR ELF simavr can load");
  std::snprintf(s.firmware.mmcu, sizeof s.firmware.mmcu, "%s", options.mcu.c_str());
  s.firmware.frequency = options.frequency_hz;
  s.avr = avr_make_mcu_by_name(s.firmware.mmcu);
  if (s.avr == nullptr) throw DeviceError("simavr", "unknown MCU '" + options.mcu + "'");
  avr_init(s.avr);
  s.avr->log = LOG_NONE;
  avr_load_firmware(s.avr, &s.firmware);
  // simavr 1.6: a low INT0/INT1 pin (our STEP is PD2 = INT0) polls every cycle otherwise.
  avr_extint_set_strict_lvl_trig(s.avr, 0, 0);
  avr_extint_set_strict_lvl_trig(s.avr, 1, 0);
  // Sleep: count the cycles; Run() paces wall time itself.
  s.avr->sleep = [](avr_t*, avr_cycle_count_t how_long) {
    if (t_running != nullptr) t_running->sleep_cycles += how_long;
  };
  // The UART: no console echo; bytes out to the host queue; XON/XOFF pace the input.
  std::uint32_t flags = 0;
  avr_ioctl(s.avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
  flags &= ~static_cast<std::uint32_t>(AVR_UART_FLAG_STDIO);
  avr_ioctl(s.avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
  s.uart_input = avr_io_getirq(s.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
  auto* self = &s;
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT),
      [](avr_irq_t*, std::uint32_t value, void* param) {
        State& st = *StateOf(param);
        ++st.counters.bytes_from_controller;
        auto byte = static_cast<std::uint8_t>(value);
        if (st.plugged && st.Mangle(&byte)) st.to_host.push_back(byte);
      },
      self);
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON),
      [](avr_irq_t*, std::uint32_t, void* param) {
        State& st = *StateOf(param);
        st.xoff = false;
        st.FeedAvr();
      },
      self);
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF),
      [](avr_irq_t*, std::uint32_t, void* param) { StateOf(param)->xoff = true; }, self);
  // Pins.
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ('D'), IOPORT_IRQ_REG_PORT),
      [](avr_irq_t*, std::uint32_t value, void* param) {
        StateOf(param)->OnPortD(static_cast<std::uint8_t>(value));
      },
      self);
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ('D'), IOPORT_IRQ_DIRECTION_ALL),
      [](avr_irq_t*, std::uint32_t value, void* param) {
        StateOf(param)->ddr_d = static_cast<std::uint8_t>(value);
      },
      self);
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_REG_PORT),
      [](avr_irq_t*, std::uint32_t value, void* param) {
        State& st = *StateOf(param);
        st.port_b = static_cast<std::uint8_t>(value);
        st.UpdateEnable();
        st.UpdateBacklight();
      },
      self);
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_DIRECTION_ALL),
      [](avr_irq_t*, std::uint32_t value, void* param) {
        State& st = *StateOf(param);
        st.ddr_b = static_cast<std::uint8_t>(value);
        st.UpdateEnable();
        st.UpdateBacklight();
      },
      self);
  avr_irq_register_notify(
      avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ('C'), IOPORT_IRQ_REG_PORT),
      [](avr_irq_t*, std::uint32_t value, void* param) {
        StateOf(param)->OnPortC(static_cast<std::uint8_t>(value));
      },
      self);
  s.home_irq = avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ('B'), kHomePin);
  s.UpdateSensor();
  s.OpenPty();
  s.thread = std::thread([self] { self->Run(); });
}

AvrTurntable::~AvrTurntable() {
  State& s = *state_;
  s.quit = true;
  if (s.thread.joinable()) s.thread.join();
  s.ClosePty();
  if (!s.options.link.empty()) {
    std::error_code ec;
    std::filesystem::remove(s.options.link, ec);
  }
  if (s.avr != nullptr) {
    avr_terminate(s.avr);
    std::free(s.avr);
  }
  std::free(s.firmware.flash);
  std::free(s.firmware.eeprom);
}

std::string AvrTurntable::port() const {
  std::lock_guard lock(state_->mutex);
  return state_->options.link.empty() ? state_->slave_path : state_->options.link.string();
}

void AvrTurntable::Unplug() {
  std::lock_guard lock(state_->mutex);
  state_->ClosePty();
}

void AvrTurntable::Replug() {
  std::lock_guard lock(state_->mutex);
  if (!state_->plugged) state_->OpenPty();
}

void AvrTurntable::Reset(std::uint8_t mcusr) {
  std::lock_guard lock(state_->mutex);
  State& s = *state_;
  avr_reset(s.avr);
  constexpr int kMcusrAddress = 0x54;  // MCUSR, I/O 0x34
  s.avr->data[kMcusrAddress] = mcusr;
  // Every pin is an input again: /ENABLE reads high through its pull-up. The port IRQs only
  // report changes, so their remembered values restart at the registers' reset value too.
  s.port_b = s.ddr_b = s.port_c = s.port_d = s.ddr_d = 0;
  for (const char port : {'B', 'C', 'D'})
    for (const int irq : {IOPORT_IRQ_REG_PORT, IOPORT_IRQ_DIRECTION_ALL})
      avr_io_getirq(s.avr, AVR_IOCTL_IOPORT_GETIRQ(port), irq)->value = 0;
  s.UpdateEnable();
  for (auto& p : s.pulses)
    if (p.end_cycle == 0) p.end_cycle = s.avr->cycle;
  s.backlight = false;
  s.to_avr.clear();
  s.xoff = true;
  // The sensor's level is the board's, not the MCU's.
  s.home_irq->value = s.sensor ? 1u : 0u;
  s.UpdateSensor();
}

std::uint8_t AvrTurntable::ReadData(std::uint16_t address) const {
  std::lock_guard lock(state_->mutex);
  if (address > state_->avr->ramend)
    throw InvalidArgument("AvrTurntable::ReadData: address " + std::to_string(address) +
                          " beyond the data space");
  return state_->avr->data[address];
}

void AvrTurntable::SetLineFaults(const LineFaults& faults) {
  std::lock_guard lock(state_->mutex);
  state_->faults = faults;
  state_->random.seed(faults.seed);
}

LineCounters AvrTurntable::line_counters() const {
  std::lock_guard lock(state_->mutex);
  return state_->counters;
}

std::uint64_t AvrTurntable::cycle() const {
  std::lock_guard lock(state_->mutex);
  return state_->avr->cycle;
}

double AvrTurntable::frequency_hz() const { return state_->options.frequency_hz; }

std::int64_t AvrTurntable::motor_steps() const {
  std::lock_guard lock(state_->mutex);
  return state_->motor_steps;
}

std::int64_t AvrTurntable::table_position() const {
  std::lock_guard lock(state_->mutex);
  return state_->options.start_position + state_->motor_steps;
}

bool AvrTurntable::backlight_on() const {
  std::lock_guard lock(state_->mutex);
  return state_->backlight;
}

bool AvrTurntable::sensor_active() const {
  std::lock_guard lock(state_->mutex);
  return state_->sensor;
}

std::vector<StepEdge> AvrTurntable::steps() const {
  std::lock_guard lock(state_->mutex);
  return state_->steps;
}

std::vector<EnableChange> AvrTurntable::enable_changes() const {
  std::lock_guard lock(state_->mutex);
  return state_->enable_changes;
}

std::vector<OutputPulse> AvrTurntable::output_pulses() const {
  std::lock_guard lock(state_->mutex);
  return state_->pulses;
}

void AvrTurntable::ClearLogs() {
  std::lock_guard lock(state_->mutex);
  state_->steps.clear();
  state_->enable_changes.clear();
  state_->pulses.clear();
}

}  // namespace carousel::sim
