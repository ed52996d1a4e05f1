// A serial port through termios: raw 8N1, a standard baud rate, reads and writes with
// timeouts, flush, hang-up detection and reopening (a USB-serial adapter unplugged and
// plugged back under the same path). Part of carousel_rig (termios stays in rig's backends).
//
// The port is opened exclusively (TIOCEXCL), without becoming the controlling terminal, and
// with HUPCL cleared so that closing it does not drop DTR (which resets many Arduino boards).
// Every failure is a DeviceError naming the port.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>

namespace carousel::rig {

class SerialPort {
 public:
  // \throw DeviceError when the port cannot be opened or configured, InvalidArgument for a
  // baud rate termios does not offer.
  SerialPort(std::string path, int baud);
  ~SerialPort();
  SerialPort(const SerialPort&) = delete;
  SerialPort& operator=(const SerialPort&) = delete;

  const std::string& path() const { return path_; }
  bool is_open() const { return fd_ >= 0; }

  // Writes all of `data` within `timeout`. \throw DeviceError (timeout, hang-up, I/O error).
  void Write(std::span<const std::uint8_t> data, std::chrono::milliseconds timeout);
  // Waits up to `timeout` for input and returns what is available (0 bytes: timeout).
  // \throw DeviceError on hang-up (device unplugged) or an I/O error.
  std::size_t Read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout);
  // Discards unread input and unsent output.
  void Flush();
  void Close();
  // Closes and opens the same path again. \throw DeviceError when it is not back.
  void Reopen();

 private:
  void Open();
  [[noreturn]] void Fail(const std::string& what) const;

  std::string path_;
  int baud_;
  int fd_ = -1;
};

}  // namespace carousel::rig
