// The window's decisions, without a window (STYLE.md §14, DESIGN.md "front ends over one
// pipeline"): carousel-studio draws what this holds and calls what it offers; the tests drive it
// with no window at all.
//
// One job at a time (a one-button session, a resume, a reprocess) runs on a worker thread
// through studio's pipeline with a core Progress; the UI thread only reads snapshots
// (Status()), so it never blocks on the pipeline. The progress updates become a bar per
// pipeline stage (capture, reconstruct, texture, publish) with the step running in it and the
// time left. A failure becomes the message the pipeline threw (it names the file or device)
// and what the photographer can do about it; a session that failed or was cancelled is left as
// `carousel run --resume` continues it (every verified photo kept).
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <exception>
#include <filesystem>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "carousel/core/progress.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/run_session.h"

namespace carousel::gui {

// The stages of a session, one progress bar each, in the order they run.
enum class PipelineStage { kCapture = 0, kReconstruct, kTexture, kPublish };
inline constexpr int kPipelineStages = 4;
const char* PipelineStageName(PipelineStage stage);  // "capture", "reconstruct", ...

// The pipeline stage a Progress stage belongs to ("visual hull: carving" -> reconstruct,
// "atlas: packing" -> texture), and where in that stage's bar the step runs ([begin, end] of
// 0..1); nullopt for a step no stage owns (a calibration's "bundle adjustment").
struct StageStep {
  PipelineStage stage;
  double begin = 0.0, end = 1.0;
};
std::optional<StageStep> StepOf(const std::string& progress_stage);

struct StageBar {
  enum class State { kWaiting, kRunning, kDone };
  State state = State::kWaiting;
  std::string step;            // the Progress stage running in it now ("atlas: packing")
  double fraction = 0.0;       // of the whole pipeline stage, 0..1, never going back
  double seconds = 0.0;        // spent in it so far
  double seconds_left = -1.0;  // estimate from its own pace; < 0 while unknown
};

// Turns Progress updates into the bars. A stage reached means every stage before it is done
// (a resumed session skips what is current). Not thread-safe (the controller locks).
class StageTracker {
 public:
  using Clock = std::chrono::steady_clock;
  void Reset();
  void Update(const ProgressUpdate& update, Clock::time_point now);
  // The job ended: running bars are done when it succeeded, else stay where they stopped.
  void Finish(bool succeeded, Clock::time_point now);
  // Seconds left in the running stage (its own pace); < 0 when unknown.
  void Tick(Clock::time_point now);
  const std::array<StageBar, kPipelineStages>& bars() const { return bars_; }
  // Counts stage starts and ends (a screenshot is taken whenever it changes).
  int changes() const { return changes_; }

 private:
  std::array<StageBar, kPipelineStages> bars_{};
  std::array<Clock::time_point, kPipelineStages> started_{};
  int running_ = -1;
  int changes_ = 0;
};

// What the photographer reads about a failure: what to do, for the kind of error thrown.
std::string AdviceFor(const std::exception& error, bool session_resumable);

enum class JobKind { kNone, kRun, kResume, kReprocess };
enum class JobState { kIdle, kRunning, kSucceeded, kFailed, kCancelled };
const char* JobStateName(JobState state);  // "idle", "running", ...

// A calibration session on hardware waits for the board: placement `index` (0-based) of
// `placements`; a product session of several orientations waits for the product to be laid
// down for pass `index` of `placements` (`product`). ConfirmBoardPlaced() continues.
struct BoardPrompt {
  int index = 0, placements = 0;
  bool product = false;
};

// A snapshot of the job, for drawing.
struct JobStatus {
  JobKind kind = JobKind::kNone;
  JobState state = JobState::kIdle;
  int id = 0;                     // counts jobs started (0: none yet)
  std::string product;            // the SKU
  bool calibration = false;       // a calibration session (the wizard's)
  std::filesystem::path session;  // the session folder (known from the start)
  std::array<StageBar, kPipelineStages> bars{};
  int stage_changes = 0;
  bool cancelling = false;
  std::string error;       // what failed, naming the file or device (empty unless kFailed)
  std::string advice;      // what to do about it (kFailed and kCancelled)
  bool resumable = false;  // the session folder can be continued (Resume)
  std::optional<studio::RunResult> run;          // kRun / kResume succeeded
  std::optional<studio::ProcessResult> process;  // kReprocess succeeded
  std::optional<BoardPrompt> board_prompt;
  double seconds = 0.0;  // since the job started (to its end once ended)
};

class StudioController {
 public:
  StudioController() = default;
  ~StudioController();  // cancels a running job and waits for it
  StudioController(const StudioController&) = delete;
  StudioController& operator=(const StudioController&) = delete;

  // The one-button session (studio::RunSession) on a worker thread. \throw InvalidArgument
  // when a job is running or the options are invalid (nothing started then).
  void StartRun(studio::RunOptions options);
  // Continues a session (studio::ResumeSession). \throw InvalidArgument when busy, IoError
  // when `session` holds no run.json (not a session `carousel run` started).
  void StartResume(const std::filesystem::path& session);
  // Runs the processing stages again (studio::ProcessSession, every stage when `force`).
  // \throw InvalidArgument when busy or the options are invalid, IoError without session.json.
  void StartReprocess(const std::filesystem::path& session, studio::ProcessOptions options);
  // Asks the running job to stop at its next safe point (it ends kCancelled, resumable).
  void Cancel();
  // The board stands where the calibration prompt asked.
  void ConfirmBoardPlaced();

  JobStatus Status() const;
  bool Busy() const;
  // Blocks until the job ends (tests, --quit-when-done); returns its final status.
  JobStatus Wait();

 private:
  // On the worker: shows the prompt (the board's placement `index`, or the product's pass
  // when `product`) and waits for ConfirmBoardPlaced(). \throw Cancelled.
  void WaitForOperator(int index, int placements, bool product);
  template <typename Work>
  void Launch(JobKind kind, const std::string& product, const std::filesystem::path& session,
              Work work);
  void OnProgress(const ProgressUpdate& update);
  void Join();

  mutable std::mutex mutex_;
  std::condition_variable board_placed_;
  bool board_confirmed_ = false;
  JobStatus status_;
  StageTracker tracker_;
  int change_base_ = 0;  // stage_changes before this job's tracker counted
  StageTracker::Clock::time_point started_{};
  CancellationToken token_;
  std::thread worker_;
};

// Whether a job's outcome is a finished model ready to show (the operator's green light).
bool ModelReady(const JobStatus& status);

// The calibration wizard's last step: pass or fail, and why. A calibration passes when every
// camera reprojects the board within `max_rms_px` from at least `min_views` photos, and the
// turntable turned as it reported (largest deviation within `max_angle_deg`).
struct CalibrationVerdict {
  bool pass = false;
  std::vector<std::string> reasons;  // what failed (empty when it passed)
  std::vector<std::string> lines;    // the figures, one line per camera and one for the table
};
CalibrationVerdict JudgeCalibration(const studio::CalibrateSessionResult& result,
                                    double max_rms_px = 1.0, double max_angle_deg = 0.25,
                                    int min_views = 6);

}  // namespace carousel::gui
