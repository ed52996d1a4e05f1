#include "carousel/core/error.h"

namespace carousel {

namespace {
// "<subject>: <reason>" (appended rather than concatenated: GCC 12 warns falsely on the latter).
std::string Join(const std::string& subject, const std::string& reason) {
  std::string message;
  message.reserve(subject.size() + 2 + reason.size());
  message.append(subject).append(": ").append(reason);
  return message;
}
}  // namespace

IoError::IoError(const std::filesystem::path& path, const std::string& reason)
    : Error(Join(path.string(), reason)), path_(path), reason_(reason) {}

DeviceError::DeviceError(const std::string& device, const std::string& reason)
    : Error(Join(device, reason)), device_(device), reason_(reason) {}

namespace internal {

void ThrowCheckFailure(const char* file, int line, const char* condition,
                       const std::string& message) {
  std::ostringstream out;
  out << "internal check failed at " << std::filesystem::path(file).filename().string() << ":"
      << line << ": " << condition;
  if (!message.empty()) out << " (" << message << ")";
  throw InternalError(out.str());
}

}  // namespace internal
}  // namespace carousel
