#include "carousel/core/progress.h"

#include <algorithm>

#include "carousel/core/error.h"

namespace carousel {
namespace {
// Updates closer than this in fraction and in time are not delivered (keeps listeners cheap).
constexpr double kMinFractionStep = 0.005;
constexpr auto kMinInterval = std::chrono::milliseconds(50);
}  // namespace

Progress::Progress() = default;

Progress::Progress(Listener listener, CancellationToken token)
    : listener_(std::move(listener)), token_(std::move(token)) {}

void Progress::BeginStage(const std::string& stage) {
  CheckCancelled();
  std::lock_guard<std::mutex> lock(mutex_);
  stage_ = stage;
  fraction_ = 0.0;
  Deliver({stage_, 0.0, false}, true);
}

void Progress::Report(double fraction) {
  CheckCancelled();
  if (!listener_) return;
  std::lock_guard<std::mutex> lock(mutex_);
  fraction = std::clamp(fraction, 0.0, 1.0);
  if (!(fraction > fraction_)) return;  // monotone; also drops NaN
  fraction_ = fraction;
  Deliver({stage_, fraction_, false}, false);
}

void Progress::Report(std::size_t done, std::size_t total) {
  Report(total == 0 ? 1.0 : static_cast<double>(done) / static_cast<double>(total));
}

void Progress::EndStage() {
  std::lock_guard<std::mutex> lock(mutex_);
  fraction_ = 1.0;
  Deliver({stage_, 1.0, true}, true);
}

void Progress::CheckCancelled() const {
  if (token_.IsCancelled()) throw Cancelled("cancelled by the user");
}

void Progress::Deliver(const ProgressUpdate& update, bool force) {
  if (!listener_) return;
  const auto now = std::chrono::steady_clock::now();
  if (!force && update.fraction - last_delivered_ < kMinFractionStep &&
      now - last_time_ < kMinInterval) {
    return;
  }
  last_delivered_ = update.fraction;
  last_time_ = now;
  listener_(update);
}

std::unique_ptr<Progress> Progress::Slice(double begin, double end) {
  begin = std::clamp(begin, 0.0, 1.0);
  end = std::clamp(end, begin, 1.0);
  std::string parent_stage;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    parent_stage = stage_;
  }
  Progress* parent = this;
  auto forward = [parent, parent_stage, begin, end](const ProgressUpdate& update) {
    if (!parent->listener_) return;
    std::lock_guard<std::mutex> lock(parent->mutex_);
    const double mapped = begin + (end - begin) * update.fraction;
    if (mapped > parent->fraction_) parent->fraction_ = mapped;
    const std::string stage =
        update.stage.empty() ? parent_stage : parent_stage + ": " + update.stage;
    parent->Deliver({stage, parent->fraction_, false}, update.stage_done || update.fraction == 0.0);
  };
  return std::make_unique<Progress>(forward, token_);
}

}  // namespace carousel
