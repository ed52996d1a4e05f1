// The turntable controller on a serial port: Carousel's firmware (firmware-protocol/) spoken
// through carousel_protocol. Part of carousel_rig.
//
// One command at a time: each is retransmitted with the same sequence number when its reply
// does not arrive within `reply_timeout_ms` (the firmware replays its reply instead of
// executing twice), up to `max_retries` times; then the command is reported failed
// (DeviceError naming the port and the command). A hang-up (device unplugged) is a
// DeviceError at once; Reconnect() opens the same path again and repeats the handshake, and
// Status() then reports the controller's true position (it kept running).
//
// Angles: radians, counter-clockwise seen from above; microsteps = angle / 2pi x microsteps
// per table revolution (steps x microsteps x gear numerator / denominator, from the
// controller's configuration). Absolute angles are not wrapped: 720 deg is two turns from
// home, and a move goes the way the sign of the difference says.
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <mutex>
#include <string>

#include "carousel/protocol/protocol.h"
#include "carousel/rig/serial_port.h"
#include "carousel/rig/turntable.h"

namespace carousel::rig {

struct SerialTurntableOptions {
  std::string port;  // "/dev/ttyACM0", a /dev/serial/by-id path, a PTY
  int baud = 115200;
  // Wait for a reply before retransmitting, ms (> 0).
  int reply_timeout_ms = 100;
  // Retransmissions before a command is reported failed (0..50).
  int max_retries = 8;
  // How long the handshake keeps trying after the port opens, ms (>= reply_timeout_ms):
  // opening the port resets many Arduino boards (DTR), and their bootloader runs first.
  int connect_timeout_ms = 3000;
  // Status polling period while waiting for a move, ms (> 0).
  int poll_interval_ms = 10;
  void Validate() const;
};

// Counters for tests and diagnostics.
struct LinkCounters {
  std::uint64_t commands = 0;
  std::uint64_t retransmissions = 0;
  std::uint64_t failed = 0;         // commands reported failed after every retry
  std::uint64_t bad_frames = 0;     // frames the host's decoder dropped
  std::uint64_t stale_replies = 0;  // replies to earlier attempts or commands
  std::uint64_t events = 0;
  std::uint64_t resets_seen = 0;  // BOOT events (controller restarted)
};

class SerialTurntable : public Turntable {
 public:
  // Opens the port and performs the version handshake. \throw DeviceError (port, no reply),
  // ProtocolError (incompatible firmware).
  explicit SerialTurntable(const SerialTurntableOptions& options);
  ~SerialTurntable() override;

  TurntableInfo Identify() override;
  void Home(std::chrono::milliseconds timeout) override;
  void StartMoveTo(double angle_rad) override;
  void WaitUntilStopped(std::chrono::milliseconds timeout) override;
  TurntableStatus Status() override;
  void Stop(bool emergency) override;
  // LIGHT (protocol 1.1): \throw DeviceError when the controller's firmware speaks 1.0.
  void SetBacklight(bool on) override;

  // Protocol-level access (microsteps).
  cp_status RawStatus();
  void StartMoveToSteps(std::int32_t target);
  void StartMoveBySteps(std::int32_t delta);
  cp_config Config();
  // Validates, sends and persists; the controller's stored copy is returned.
  cp_config SetConfig(const cp_config& config);
  // Drives the outputs (CP_OUTPUT_SHUTTER / CP_OUTPUT_FOCUS) of `cameras` (bit i = camera i).
  void Trigger(std::uint8_t cameras, std::uint8_t outputs, std::uint16_t duration_ms);
  void SetHold(bool hold);
  // Reopens the port and repeats the handshake.
  void Reconnect();

  std::int32_t StepsFromAngle(double angle_rad) const;
  double AngleFromSteps(std::int32_t steps) const;
  LinkCounters counters() const;
  const std::string& port() const { return options_.port; }

 private:
  // Sends `command` and returns its ACK; NAKs become DeviceError / ProtocolError.
  cp_frame Exchange(const cp_frame& command);
  // `attempts` = 0: 1 + max_retries.
  cp_frame ExchangeLocked(const cp_frame& command, int attempts = 0);
  void Handshake();
  void HandleEvent(const cp_frame& frame);

  SerialTurntableOptions options_;
  std::unique_ptr<SerialPort> port_;
  mutable std::mutex mutex_;
  cp_decoder decoder_{};
  std::uint8_t next_seq_ = 1;
  std::uint8_t controller_minor_ = 0;  // the protocol minor version the controller speaks
  cp_config config_{};
  std::uint32_t steps_per_rev_ = 0;
  bool needs_hello_ = true;
  LinkCounters counters_;
};

}  // namespace carousel::rig
