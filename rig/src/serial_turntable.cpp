#include "carousel/rig/serial_turntable.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <numbers>
#include <thread>

#include "carousel/core/error.h"

namespace carousel::rig {
namespace {

using Clock = std::chrono::steady_clock;

cp_frame Command(std::uint8_t type) {
  cp_frame f{};
  f.type = type;
  return f;
}

}  // namespace

void SerialTurntableOptions::Validate() const {
  auto check = [](bool ok, const char* field, const char* rule) {
    if (!ok)
      throw InvalidArgument(std::string("SerialTurntableOptions.") + field + " must be " + rule);
  };
  check(!port.empty(), "port", "set");
  check(reply_timeout_ms > 0, "reply_timeout_ms", "> 0");
  check(max_retries >= 0 && max_retries <= 50, "max_retries", "in [0, 50]");
  check(poll_interval_ms > 0, "poll_interval_ms", "> 0");
  check(connect_timeout_ms >= reply_timeout_ms, "connect_timeout_ms", ">= reply_timeout_ms");
}

SerialTurntable::SerialTurntable(const SerialTurntableOptions& options) : options_(options) {
  options_.Validate();
  cp_decoder_init(&decoder_);
  port_ = std::make_unique<SerialPort>(options_.port, options_.baud);
  std::lock_guard lock(mutex_);
  Handshake();
}

SerialTurntable::~SerialTurntable() = default;

void SerialTurntable::Handshake() {
  needs_hello_ = false;
  cp_frame hello = Command(CP_HELLO);
  hello.payload[0] = CP_VERSION_MAJOR;
  hello.payload[1] = CP_VERSION_MINOR;
  hello.len = 2;
  const cp_frame reply = ExchangeLocked(
      hello,
      std::max(1 + options_.max_retries, options_.connect_timeout_ms / options_.reply_timeout_ms));
  if (reply.len < 2 || reply.payload[0] != CP_VERSION_MAJOR)
    throw ProtocolError(options_.port + ": controller speaks protocol " +
                        std::to_string(reply.len >= 1 ? reply.payload[0] : 0) + ".x, host " +
                        std::to_string(CP_VERSION_MAJOR) + ".x");
  controller_minor_ = reply.payload[1];
  const cp_frame config = ExchangeLocked(Command(CP_GET_CONFIG));
  if (cp_get_config(&config, &config_) != CP_OK)
    throw ProtocolError(options_.port + ": the controller reported an invalid configuration");
  steps_per_rev_ = cp_steps_per_table_rev(&config_);
}

void SerialTurntable::HandleEvent(const cp_frame& frame) {
  ++counters_.events;
  if (frame.type == CP_EVENT_BOOT) {
    ++counters_.resets_seen;
    needs_hello_ = true;
  }
}

cp_frame SerialTurntable::Exchange(const cp_frame& command) {
  std::lock_guard lock(mutex_);
  if (needs_hello_) Handshake();
  try {
    return ExchangeLocked(command);
  } catch (const ProtocolError&) {
    // The controller restarted since the handshake (it refuses commands until HELLO): the
    // command was not executed; shake hands and send it once more.
    if (!needs_hello_) throw;
    Handshake();
    return ExchangeLocked(command);
  }
}

cp_frame SerialTurntable::ExchangeLocked(const cp_frame& original, int attempts) {
  if (attempts <= 0) attempts = 1 + options_.max_retries;
  cp_frame command = original;
  command.seq = next_seq_;
  next_seq_ = next_seq_ == 255 ? 1 : static_cast<std::uint8_t>(next_seq_ + 1);
  std::array<std::uint8_t, CP_MAX_WIRE + 1> wire{};
  wire[0] = 0;  // flushes a partial frame in the controller's receiver
  const int size = cp_encode(&command, wire.data() + 1, wire.size() - 1);
  CAROUSEL_CHECK(size > 0, "encoding a " << cp_type_name(command.type) << " frame");
  ++counters_.commands;
  const auto write_timeout = std::chrono::milliseconds(options_.reply_timeout_ms + 100);
  for (int attempt = 0; attempt < attempts; ++attempt) {
    if (attempt > 0) ++counters_.retransmissions;
    port_->Write(std::span(wire.data(), static_cast<std::size_t>(size) + 1), write_timeout);
    const auto deadline = Clock::now() + std::chrono::milliseconds(options_.reply_timeout_ms);
    std::array<std::uint8_t, 64> buffer{};
    while (true) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(deadline - Clock::now());
      if (left.count() <= 0) break;
      const std::size_t n = port_->Read(buffer, left);
      for (std::size_t i = 0; i < n; ++i) {
        cp_frame frame{};
        const int r = cp_decoder_push(&decoder_, buffer[i], &frame);
        if (r < 0) ++counters_.bad_frames;
        if (r != 1) continue;
        if (frame.type >= CP_EVENT_BOOT && frame.type < CP_NAK) {
          HandleEvent(frame);
          continue;
        }
        const bool ack = frame.type == (command.type | CP_ACK_FLAG);
        const bool nak = frame.type == CP_NAK && frame.len >= 2 && frame.payload[0] == command.type;
        if (frame.seq != command.seq || (!ack && !nak)) {
          ++counters_.stale_replies;
          continue;
        }
        if (ack) return frame;
        const int code = -static_cast<int>(frame.payload[1]);
        if (code == CP_ERR_VERSION) {
          needs_hello_ = true;
          throw ProtocolError(options_.port + ": controller refused " + cp_type_name(command.type) +
                              ": " + cp_error_name(code));
        }
        throw DeviceError(options_.port, std::string("controller refused ") +
                                             cp_type_name(command.type) + ": " +
                                             cp_error_name(code));
      }
    }
  }
  ++counters_.failed;
  throw DeviceError(options_.port, std::string("no reply to ") + cp_type_name(command.type) +
                                       " after " + std::to_string(attempts) + " attempts of " +
                                       std::to_string(options_.reply_timeout_ms) + " ms");
}

TurntableInfo SerialTurntable::Identify() {
  const cp_frame reply = Exchange(Command(CP_IDENTIFY));
  TurntableInfo info;
  info.port = options_.port;
  if (reply.len >= 5) {
    info.firmware = std::to_string(reply.payload[2]) + "." + std::to_string(reply.payload[3]) +
                    "." + std::to_string(reply.payload[4]) + " (protocol " +
                    std::to_string(reply.payload[0]) + "." + std::to_string(reply.payload[1]) + ")";
    info.model.assign(reinterpret_cast<const char*>(reply.payload + 5), reply.len - 5u);
  }
  return info;
}

cp_status SerialTurntable::RawStatus() {
  const cp_frame reply = Exchange(Command(CP_STATUS));
  cp_status status{};
  if (cp_get_status(&reply, &status) != CP_OK)
    throw ProtocolError(options_.port + ": short STATUS reply");
  return status;
}

TurntableStatus SerialTurntable::Status() {
  const cp_status raw = RawStatus();
  TurntableStatus status;
  status.angle_rad = AngleFromSteps(raw.position);
  status.target_rad = AngleFromSteps(raw.target);
  status.moving = (raw.flags & CP_FLAG_MOVING) != 0;
  status.homed = (raw.flags & CP_FLAG_HOMED) != 0;
  status.backlight = (raw.flags & CP_FLAG_BACKLIGHT) != 0;
  switch (raw.fault) {
    case CP_FAULT_NONE:
      break;
    case CP_FAULT_HOME_NOT_FOUND:
      status.fault = "home sensor not found";
      break;
    case CP_FAULT_ESTOP:
      status.fault = "emergency stop";
      break;
    case CP_FAULT_WATCHDOG:
      status.fault = "controller restarted by its watchdog";
      break;
    default:
      status.fault = "fault " + std::to_string(raw.fault);
  }
  return status;
}

void SerialTurntable::Home(std::chrono::milliseconds timeout) {
  Exchange(Command(CP_HOME));
  WaitUntilStopped(timeout);
  const cp_status status = RawStatus();
  if (!(status.flags & CP_FLAG_HOMED))
    throw DeviceError(options_.port, status.fault == CP_FAULT_HOME_NOT_FOUND
                                         ? "homing failed: home sensor not found"
                                         : "homing did not complete");
}

void SerialTurntable::StartMoveToSteps(std::int32_t target) {
  cp_frame f = Command(CP_MOVE_ABS);
  cp_put_i32(f.payload, target);
  f.len = 4;
  Exchange(f);
}

void SerialTurntable::StartMoveBySteps(std::int32_t delta) {
  cp_frame f = Command(CP_MOVE_REL);
  cp_put_i32(f.payload, delta);
  f.len = 4;
  Exchange(f);
}

void SerialTurntable::StartMoveTo(double angle_rad) { StartMoveToSteps(StepsFromAngle(angle_rad)); }

void SerialTurntable::WaitUntilStopped(std::chrono::milliseconds timeout) {
  const auto deadline = Clock::now() + timeout;
  while (true) {
    const cp_status status = RawStatus();
    if (!(status.flags & CP_FLAG_MOVING)) {
      if (status.fault == CP_FAULT_HOME_NOT_FOUND)
        throw DeviceError(options_.port, "homing failed: home sensor not found");
      return;
    }
    if (Clock::now() >= deadline)
      throw DeviceError(options_.port, "still moving after " + std::to_string(timeout.count()) +
                                           " ms (position " + std::to_string(status.position) +
                                           ", target " + std::to_string(status.target) + ")");
    std::this_thread::sleep_for(std::chrono::milliseconds(options_.poll_interval_ms));
  }
}

void SerialTurntable::Stop(bool emergency) { Exchange(Command(emergency ? CP_ESTOP : CP_STOP)); }

cp_config SerialTurntable::Config() {
  const cp_frame reply = Exchange(Command(CP_GET_CONFIG));
  cp_config config{};
  if (cp_get_config(&reply, &config) != CP_OK)
    throw ProtocolError(options_.port + ": the controller reported an invalid configuration");
  return config;
}

cp_config SerialTurntable::SetConfig(const cp_config& config) {
  if (cp_check_config(&config) != CP_OK)
    throw InvalidArgument("turntable configuration out of range (see PROTOCOL.md, Config)");
  cp_frame f = Command(CP_SET_CONFIG);
  cp_put_config(&f, &config);
  const cp_frame reply = Exchange(f);
  cp_config stored{};
  if (cp_get_config(&reply, &stored) != CP_OK)
    throw ProtocolError(options_.port + ": invalid SET_CONFIG reply");
  std::lock_guard lock(mutex_);
  config_ = stored;
  steps_per_rev_ = cp_steps_per_table_rev(&config_);
  return stored;
}

void SerialTurntable::Trigger(std::uint8_t cameras, std::uint8_t outputs,
                              std::uint16_t duration_ms) {
  cp_frame f = Command(CP_TRIGGER);
  const cp_trigger t{cameras, outputs, duration_ms};
  cp_put_trigger(&f, &t);
  cp_trigger check{};
  if (cp_get_trigger(&f, &check) != CP_OK)
    throw InvalidArgument("trigger: cameras 0..3, shutter and/or focus, 1..10000 ms");
  Exchange(f);
}

void SerialTurntable::SetBacklight(bool on) {
  {
    std::lock_guard lock(mutex_);
    if (controller_minor_ < 1)
      throw DeviceError(options_.port, "the controller's firmware speaks protocol 1." +
                                           std::to_string(controller_minor_) +
                                           ", which has no backlight output (LIGHT needs 1.1): "
                                           "update the firmware");
  }
  cp_frame f = Command(CP_LIGHT);
  f.payload[0] = on ? CP_LIGHT_BACKLIGHT : 0;
  f.len = 1;
  const cp_frame reply = Exchange(f);
  cp_status status{};
  if (cp_get_status(&reply, &status) != CP_OK || ((status.flags & CP_FLAG_BACKLIGHT) != 0) != on)
    throw DeviceError(options_.port,
                      std::string("the backlight did not switch ") + (on ? "on" : "off"));
}

void SerialTurntable::SetHold(bool hold) {
  cp_frame f = Command(CP_ENABLE);
  f.payload[0] = hold ? 1 : 0;
  f.len = 1;
  Exchange(f);
}

void SerialTurntable::Reconnect() {
  std::lock_guard lock(mutex_);
  port_->Reopen();
  cp_decoder_init(&decoder_);
  Handshake();
}

std::int32_t SerialTurntable::StepsFromAngle(double angle_rad) const {
  std::lock_guard lock(mutex_);
  const double steps = angle_rad / (2.0 * std::numbers::pi) * steps_per_rev_;
  if (!std::isfinite(steps) || std::abs(steps) > 1e9)
    throw InvalidArgument("turntable angle " + std::to_string(angle_rad) + " rad out of range");
  return static_cast<std::int32_t>(std::llround(steps));
}

double SerialTurntable::AngleFromSteps(std::int32_t steps) const {
  std::lock_guard lock(mutex_);
  return steps_per_rev_ == 0 ? 0.0 : steps * 2.0 * std::numbers::pi / steps_per_rev_;
}

LinkCounters SerialTurntable::counters() const {
  std::lock_guard lock(mutex_);
  return counters_;
}

}  // namespace carousel::rig
