// Logging: one process-wide logger (spdlog underneath, not exposed), thread-safe, writing to
// stderr and optionally to a session's log file.
//
//   CAROUSEL_LOG_INFO("loaded " << views.size() << " views from " << path);
//
// Levels: debug < info < warn < error. The CLI sets the level (--verbose / --quiet).
#pragma once

#include <filesystem>
#include <sstream>
#include <string>
#include <string_view>

namespace carousel {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3, kOff = 4 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
bool LogEnabled(LogLevel level);
// Also append every message (at any enabled level) to `path`. \throw IoError if it cannot be
// opened. Call again with an empty path to stop.
void SetLogFile(const std::filesystem::path& path);
void Log(LogLevel level, std::string_view message);
// Parses "debug", "info", "warn", "error", "off". \throw InvalidArgument otherwise.
LogLevel ParseLogLevel(std::string_view name);

}  // namespace carousel

#define CAROUSEL_LOG(level, message)                                            \
  do {                                                                          \
    if (::carousel::LogEnabled(level)) {                                        \
      std::ostringstream carousel_log_stream_;                                  \
      carousel_log_stream_ << message; /* NOLINT(bugprone-macro-parentheses) */ \
      ::carousel::Log(level, carousel_log_stream_.str());                       \
    }                                                                           \
  } while (false)
#define CAROUSEL_LOG_DEBUG(message) CAROUSEL_LOG(::carousel::LogLevel::kDebug, message)
#define CAROUSEL_LOG_INFO(message) CAROUSEL_LOG(::carousel::LogLevel::kInfo, message)
#define CAROUSEL_LOG_WARN(message) CAROUSEL_LOG(::carousel::LogLevel::kWarn, message)
#define CAROUSEL_LOG_ERROR(message) CAROUSEL_LOG(::carousel::LogLevel::kError, message)
