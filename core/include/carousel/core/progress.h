// Progress reporting and cooperative cancellation for every long step (STYLE.md, practice 6).
//
// A stage takes `Progress&`, announces what it does with BeginStage(), reports a fraction in
// [0, 1] with Report() (cheap: callbacks are throttled), and calls CheckCancelled() where it
// can stop safely; Report() checks too. Cancellation throws carousel::Cancelled.
// Slice() hands a sub-step a Progress that maps its [0, 1] onto part of the parent's range.
// Thread-safe: workers of a parallel loop may call Report()/CheckCancelled() concurrently.
//
// There is no process-global cancel flag: each run owns its CancellationToken.
#pragma once

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <string>

namespace carousel {

// Shared, copyable cancellation flag. Copies observe the same flag.
class CancellationToken {
 public:
  CancellationToken() : flag_(std::make_shared<std::atomic<bool>>(false)) {}
  void Cancel() { flag_->store(true); }
  bool IsCancelled() const { return flag_->load(std::memory_order_relaxed); }

 private:
  std::shared_ptr<std::atomic<bool>> flag_;
};

// What a progress listener sees.
struct ProgressUpdate {
  std::string stage;        // e.g. "visual hull"
  double fraction = 0.0;    // of this stage, 0..1
  bool stage_done = false;  // true on the last update of a stage
};

class Progress {
 public:
  using Listener = std::function<void(const ProgressUpdate&)>;

  // A Progress that reports nowhere and is never cancelled.
  Progress();
  explicit Progress(Listener listener, CancellationToken token = {});
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // Starts a named stage at fraction 0 (always delivered to the listener).
  void BeginStage(const std::string& stage);
  // Reports the fraction of the current stage done; clamped to [0, 1], monotone.
  // \throw Cancelled if the token was cancelled.
  void Report(double fraction);
  // Report(done / total).
  void Report(std::size_t done, std::size_t total);
  // Marks the current stage complete (fraction 1, always delivered).
  void EndStage();
  // \throw Cancelled if the token was cancelled.
  void CheckCancelled() const;
  bool IsCancelled() const { return token_.IsCancelled(); }
  const CancellationToken& token() const { return token_; }

  // A child whose fractions [0, 1] map to [begin, end] of this Progress's current stage; its
  // own BeginStage() calls are reported as "<parent stage>: <child stage>". Shares the token.
  // The child must not outlive this Progress.
  std::unique_ptr<Progress> Slice(double begin, double end);

 private:
  void Deliver(const ProgressUpdate& update, bool force);

  Listener listener_;
  CancellationToken token_;
  std::mutex mutex_;
  std::string stage_;
  double fraction_ = 0.0;
  double last_delivered_ = -1.0;
  std::chrono::steady_clock::time_point last_time_{};
};

}  // namespace carousel
