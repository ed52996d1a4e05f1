#include "carousel/rig/serial_port.h"

#include <fcntl.h>
#include <poll.h>
#include <sys/ioctl.h>
#include <termios.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>

#include "carousel/core/error.h"

namespace carousel::rig {
namespace {

speed_t BaudConstant(int baud) {
  switch (baud) {
    case 9600:
      return B9600;
    case 19200:
      return B19200;
    case 38400:
      return B38400;
    case 57600:
      return B57600;
    case 115200:
      return B115200;
    case 230400:
      return B230400;
    case 460800:
      return B460800;
    case 921600:
      return B921600;
    default:
      throw InvalidArgument("serial: unsupported baud rate " + std::to_string(baud) +
                            " (9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600)");
  }
}

int Milliseconds(std::chrono::steady_clock::duration d) {
  const auto ms = std::chrono::ceil<std::chrono::milliseconds>(d).count();
  return ms <= 0 ? 0 : static_cast<int>(std::min<long long>(ms, 1 << 30));
}

}  // namespace

SerialPort::SerialPort(std::string path, int baud) : path_(std::move(path)), baud_(baud) {
  BaudConstant(baud_);
  Open();
}

SerialPort::~SerialPort() { Close(); }

void SerialPort::Fail(const std::string& what) const {
  throw DeviceError(path_, what + (errno != 0 ? std::string(": ") + std::strerror(errno) : ""));
}

void SerialPort::Open() {
  errno = 0;
  const int fd = ::open(path_.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) Fail("cannot open the serial port");
  fd_ = fd;
  if (::ioctl(fd_, TIOCEXCL) != 0 && errno != ENOTTY) {
    const int saved = errno;
    Close();
    errno = saved;
    Fail("cannot get exclusive access");
  }
  termios tio{};
  if (::tcgetattr(fd_, &tio) != 0) {
    const int saved = errno;
    Close();
    errno = saved;
    Fail("not a serial port (tcgetattr)");
  }
  ::cfmakeraw(&tio);
  tio.c_cflag |= CLOCAL | CREAD;
  tio.c_cflag &= ~static_cast<tcflag_t>(HUPCL | CRTSCTS | CSTOPB | PARENB);
  tio.c_iflag &= ~static_cast<tcflag_t>(IXON | IXOFF | IXANY);
  tio.c_cc[VMIN] = 0;
  tio.c_cc[VTIME] = 0;
  ::cfsetispeed(&tio, BaudConstant(baud_));
  ::cfsetospeed(&tio, BaudConstant(baud_));
  if (::tcsetattr(fd_, TCSANOW, &tio) != 0) {
    const int saved = errno;
    Close();
    errno = saved;
    Fail("cannot configure the serial port");
  }
  ::tcflush(fd_, TCIOFLUSH);
}

void SerialPort::Close() {
  if (fd_ >= 0) ::close(fd_);
  fd_ = -1;
}

void SerialPort::Reopen() {
  Close();
  Open();
}

void SerialPort::Flush() {
  if (fd_ >= 0) ::tcflush(fd_, TCIOFLUSH);
}

void SerialPort::Write(std::span<const std::uint8_t> data, std::chrono::milliseconds timeout) {
  errno = 0;
  if (fd_ < 0) Fail("port closed");
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  std::size_t done = 0;
  while (done < data.size()) {
    const ssize_t n = ::write(fd_, data.data() + done, data.size() - done);
    if (n > 0) {
      done += static_cast<std::size_t>(n);
      continue;
    }
    if (n < 0 && errno != EAGAIN && errno != EINTR)
      Fail(errno == EIO || errno == ENXIO ? "device disconnected" : "write failed");
    pollfd p{fd_, POLLOUT, 0};
    const int left = Milliseconds(deadline - std::chrono::steady_clock::now());
    if (left == 0) {
      errno = 0;
      Fail("write timed out after " + std::to_string(timeout.count()) + " ms");
    }
    const int r = ::poll(&p, 1, left);
    if (r < 0 && errno != EINTR) Fail("poll failed");
    if (r > 0 && (p.revents & (POLLHUP | POLLERR | POLLNVAL))) {
      errno = 0;
      Fail("device disconnected (hang-up)");
    }
  }
}

std::size_t SerialPort::Read(std::span<std::uint8_t> buffer, std::chrono::milliseconds timeout) {
  errno = 0;
  if (fd_ < 0) Fail("port closed");
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  while (true) {
    pollfd p{fd_, POLLIN, 0};
    const int r = ::poll(&p, 1, Milliseconds(deadline - std::chrono::steady_clock::now()));
    if (r < 0) {
      if (errno == EINTR) continue;
      Fail("poll failed");
    }
    if (r == 0) return 0;
    if (p.revents & POLLIN) {
      const ssize_t n = ::read(fd_, buffer.data(), buffer.size());
      if (n > 0) return static_cast<std::size_t>(n);
      if (n < 0 && errno != EAGAIN && errno != EINTR)
        Fail(errno == EIO || errno == ENXIO ? "device disconnected" : "read failed");
      if (n == 0) {
        errno = 0;
        Fail("device disconnected (end of file)");
      }
    }
    if (p.revents & (POLLHUP | POLLERR | POLLNVAL)) {
      errno = 0;
      Fail("device disconnected (hang-up)");
    }
  }
}

}  // namespace carousel::rig
