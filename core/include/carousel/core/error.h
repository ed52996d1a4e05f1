// Carousel's one error policy (STYLE.md, practice 7): every failure is an exception from this
// small hierarchy, and every message names the thing that is wrong (a file, a device, an
// option) and what is wrong with it.
//
//   Error                   base of everything Carousel throws
//   ├─ InvalidArgument      a caller passed a value outside its documented range
//   ├─ IoError              a file or folder could not be read or written (path, reason)
//   │  └─ FormatError       a file was read but its content is not what it should be
//   ├─ DeviceError          a camera, turntable or port failed (device, reason)
//   ├─ ProtocolError        a peer broke the firmware or PTP/IP protocol
//   ├─ Cancelled            the user cancelled through a CancellationToken
//   └─ InternalError        a CAROUSEL_CHECK failed: a bug in Carousel, not in the input
//
// The check macros stay on in release builds.
#pragma once

#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>

namespace carousel {

class Error : public std::runtime_error {
 public:
  explicit Error(const std::string& message) : std::runtime_error(message) {}
};

class InvalidArgument : public Error {
 public:
  explicit InvalidArgument(const std::string& message) : Error(message) {}
};

// A file-system failure. what() reads "<path>: <reason>".
class IoError : public Error {
 public:
  IoError(const std::filesystem::path& path, const std::string& reason);
  const std::filesystem::path& path() const { return path_; }
  const std::string& reason() const { return reason_; }

 private:
  std::filesystem::path path_;
  std::string reason_;
};

// The file exists and was read, but its content is malformed, truncated or of the wrong kind.
class FormatError : public IoError {
 public:
  FormatError(const std::filesystem::path& path, const std::string& reason)
      : IoError(path, reason) {}
};

// A device (camera, turntable, serial port) failed. what() reads "<device>: <reason>".
class DeviceError : public Error {
 public:
  DeviceError(const std::string& device, const std::string& reason);
  const std::string& device() const { return device_; }
  const std::string& reason() const { return reason_; }

 private:
  std::string device_;
  std::string reason_;
};

class ProtocolError : public Error {
 public:
  explicit ProtocolError(const std::string& message) : Error(message) {}
};

class Cancelled : public Error {
 public:
  explicit Cancelled(const std::string& message = "cancelled") : Error(message) {}
};

// A broken internal invariant. what() carries the source location and the failed condition.
class InternalError : public Error {
 public:
  explicit InternalError(const std::string& message) : Error(message) {}
};

namespace internal {
[[noreturn]] void ThrowCheckFailure(const char* file, int line, const char* condition,
                                    const std::string& message);
}  // namespace internal

}  // namespace carousel

// CAROUSEL_CHECK(cond, message-stream): throws InternalError when cond is false. For invariants
// that only a bug can break. The message is a stream expression: CAROUSEL_CHECK(n > 0, "n=" << n).
#define CAROUSEL_CHECK(condition, message)                                        \
  do {                                                                            \
    if (!(condition)) {                                                           \
      std::ostringstream carousel_check_stream_;                                  \
      carousel_check_stream_ << message; /* NOLINT(bugprone-macro-parentheses) */ \
      ::carousel::internal::ThrowCheckFailure(__FILE__, __LINE__, #condition,     \
                                              carousel_check_stream_.str());      \
    }                                                                             \
  } while (false)

// CAROUSEL_THROW_IF(cond, ErrorType, args-building-the-message): for input validation, e.g.
//   CAROUSEL_THROW_IF(fx <= 0, InvalidArgument, "CameraModel.fx must be > 0, got " << fx);
// The message is a stream expression; ErrorType must take a single std::string.
#define CAROUSEL_THROW_IF(condition, ErrorType, message)                                      \
  do {                                                                                        \
    if (condition) {                                                                          \
      std::ostringstream carousel_throw_stream_;                                              \
      carousel_throw_stream_ << message;             /* NOLINT(bugprone-macro-parentheses) */ \
      throw ErrorType(carousel_throw_stream_.str()); /* NOLINT(bugprone-macro-parentheses) */ \
    }                                                                                         \
  } while (false)
