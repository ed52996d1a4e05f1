#include "carousel/core/logging.h"

#include <memory>
#include <mutex>

#include <spdlog/sinks/basic_file_sink.h>
#include <spdlog/sinks/stdout_color_sinks.h>
#include <spdlog/spdlog.h>

#include "carousel/core/error.h"

namespace carousel {
namespace {

struct LoggerState {
  std::mutex mutex;
  std::shared_ptr<spdlog::logger> logger;
  std::shared_ptr<spdlog::sinks::basic_file_sink_mt> file_sink;
  std::atomic<int> level{static_cast<int>(LogLevel::kInfo)};

  LoggerState() {
    auto console = std::make_shared<spdlog::sinks::stderr_color_sink_mt>();
    console->set_pattern("%^[%L]%$ %v");
    logger = std::make_shared<spdlog::logger>("carousel", console);
    logger->set_level(spdlog::level::trace);
  }
};

LoggerState& State() {
  static LoggerState state;
  return state;
}

spdlog::level::level_enum ToSpdlog(LogLevel level) {
  switch (level) {
    case LogLevel::kDebug:
      return spdlog::level::debug;
    case LogLevel::kInfo:
      return spdlog::level::info;
    case LogLevel::kWarn:
      return spdlog::level::warn;
    case LogLevel::kError:
      return spdlog::level::err;
    case LogLevel::kOff:
      return spdlog::level::off;
  }
  return spdlog::level::info;
}

}  // namespace

void SetLogLevel(LogLevel level) { State().level = static_cast<int>(level); }

LogLevel GetLogLevel() { return static_cast<LogLevel>(State().level.load()); }

bool LogEnabled(LogLevel level) {
  return level != LogLevel::kOff && static_cast<int>(level) >= State().level.load();
}

void SetLogFile(const std::filesystem::path& path) {
  LoggerState& state = State();
  std::lock_guard<std::mutex> lock(state.mutex);
  auto& sinks = state.logger->sinks();
  if (state.file_sink) {
    state.file_sink->flush();
    std::erase(sinks, state.file_sink);
    state.file_sink.reset();
  }
  if (path.empty()) return;
  try {
    state.file_sink = std::make_shared<spdlog::sinks::basic_file_sink_mt>(path.string());
  } catch (const spdlog::spdlog_ex& e) {
    throw IoError(path, std::string("cannot open log file: ") + e.what());
  }
  state.file_sink->set_pattern("%Y-%m-%dT%H:%M:%S.%e [%l] [thread %t] %v");
  sinks.push_back(state.file_sink);
}

void Log(LogLevel level, std::string_view message) {
  if (!LogEnabled(level)) return;
  LoggerState& state = State();
  std::lock_guard<std::mutex> lock(state.mutex);
  state.logger->log(ToSpdlog(level), "{}", message);
  if (state.file_sink) state.file_sink->flush();
}

LogLevel ParseLogLevel(std::string_view name) {
  if (name == "debug") return LogLevel::kDebug;
  if (name == "info") return LogLevel::kInfo;
  if (name == "warn" || name == "warning") return LogLevel::kWarn;
  if (name == "error") return LogLevel::kError;
  if (name == "off") return LogLevel::kOff;
  throw InvalidArgument("unknown log level '" + std::string(name) +
                        "' (expected debug, info, warn, error or off)");
}

}  // namespace carousel
