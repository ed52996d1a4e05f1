#include "carousel/gui/controller.h"

#include <sys/resource.h>
#include <sys/syscall.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <utility>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"

namespace carousel::gui {
namespace {

using Clock = StageTracker::Clock;

constexpr int kWorkerNice = 10;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

bool StartsWith(const std::string& text, const char* prefix) { return text.rfind(prefix, 0) == 0; }

bool SessionResumable(const std::filesystem::path& session) {
  std::error_code ec;
  return !session.empty() && std::filesystem::is_regular_file(session / "run.json", ec);
}

}  // namespace

const char* PipelineStageName(PipelineStage stage) {
  switch (stage) {
    case PipelineStage::kCapture:
      return "capture";
    case PipelineStage::kReconstruct:
      return "reconstruct";
    case PipelineStage::kTexture:
      return "texture";
    case PipelineStage::kPublish:
      return "publish";
  }
  return "?";
}

std::optional<StageStep> StepOf(const std::string& stage) {
  // The steps' shares of their stage's bar, from a simulated shoe session's stage times.
  struct Entry {
    const char* prefix;
    StageStep step;
  };
  static constexpr Entry kSteps[] = {
      {"capture", {PipelineStage::kCapture, 0.0, 1.0}},
      {"load scene", {PipelineStage::kCapture, 0.0, 0.05}},
      {"render views", {PipelineStage::kCapture, 0.05, 1.0}},
      {"silhouettes", {PipelineStage::kReconstruct, 0.0, 0.35}},
      {"visual hull", {PipelineStage::kReconstruct, 0.35, 0.7}},
      {"mesh", {PipelineStage::kReconstruct, 0.7, 1.0}},
      {"texture: grouping", {PipelineStage::kTexture, 0.0, 0.15}},
      {"atlas", {PipelineStage::kTexture, 0.15, 0.35}},
      {"texture: transfer", {PipelineStage::kTexture, 0.35, 0.95}},
      {"texture: export", {PipelineStage::kTexture, 0.95, 1.0}},
      {"publish", {PipelineStage::kPublish, 0.0, 1.0}},
  };
  for (const Entry& e : kSteps)
    if (StartsWith(stage, e.prefix)) return e.step;
  return std::nullopt;
}

void StageTracker::Reset() {
  bars_ = {};
  started_ = {};
  running_ = -1;
  changes_ = 0;
}

void StageTracker::Update(const ProgressUpdate& update, Clock::time_point now) {
  const std::optional<StageStep> step = StepOf(update.stage);
  if (!step) return;
  const int index = static_cast<int>(step->stage);
  if (index != running_) {
    // A later stage started: the ones before it are done (ran, or were current and skipped).
    for (int i = 0; i < index; ++i) {
      if (bars_[i].state != StageBar::State::kDone) {
        if (i == running_) bars_[i].seconds = Seconds(now - started_[i]);
        bars_[i].state = StageBar::State::kDone;
        bars_[i].fraction = 1.0;
        bars_[i].seconds_left = 0.0;
        ++changes_;
      }
    }
    if (index < running_) {
      // A job going back to an earlier stage (a reprocess after a run): start over.
      for (int i = index; i < kPipelineStages; ++i) bars_[i] = {};
    }
    running_ = index;
    started_[index] = now;
    bars_[index].state = StageBar::State::kRunning;
    bars_[index].fraction = 0.0;
    bars_[index].seconds_left = -1.0;
    ++changes_;
  }
  StageBar& bar = bars_[index];
  bar.step = update.stage;
  const double f = step->begin + (step->end - step->begin) * std::clamp(update.fraction, 0.0, 1.0);
  bar.fraction = std::max(bar.fraction, f);
  Tick(now);
}

void StageTracker::Tick(Clock::time_point now) {
  if (running_ < 0) return;
  StageBar& bar = bars_[running_];
  if (bar.state != StageBar::State::kRunning) return;
  bar.seconds = Seconds(now - started_[running_]);
  // Its own pace once a little of it is done (before that, the first step's set-up dominates).
  bar.seconds_left =
      bar.fraction >= 0.03 ? bar.seconds * (1.0 - bar.fraction) / bar.fraction : -1.0;
}

void StageTracker::Finish(bool succeeded, Clock::time_point now) {
  Tick(now);
  if (succeeded) {
    for (int i = 0; i < kPipelineStages; ++i) {
      if (bars_[i].state == StageBar::State::kRunning) {
        bars_[i].state = StageBar::State::kDone;
        bars_[i].fraction = 1.0;
        bars_[i].seconds_left = 0.0;
      }
    }
  }
  running_ = -1;
  ++changes_;
}

std::string AdviceFor(const std::exception& error, bool resumable) {
  const std::string resume =
      resumable ? " Then press Resume: every verified photo is kept, nothing is retaken." : "";
  if (dynamic_cast<const Cancelled*>(&error))
    return resumable ? "Stopped. Resume continues where it stopped; every verified photo is kept."
                     : "Stopped before anything was kept.";
  if (dynamic_cast<const DeviceError*>(&error) || dynamic_cast<const ProtocolError*>(&error))
    return "Check the device named above: its cable, power and that no other program holds "
           "it." +
           resume;
  if (dynamic_cast<const FormatError*>(&error))
    return "The file named above is damaged or not what was expected: replace or remove it." +
           resume;
  if (dynamic_cast<const IoError*>(&error))
    return "Check the file or folder named above: free disk space, permissions, that it "
           "exists." +
           resume;
  if (dynamic_cast<const InvalidArgument*>(&error))
    return "Correct the setting named above and press the button again.";
  return "An internal error: please report it with the session folder." + resume;
}

const char* JobStateName(JobState state) {
  switch (state) {
    case JobState::kIdle:
      return "idle";
    case JobState::kRunning:
      return "running";
    case JobState::kSucceeded:
      return "done";
    case JobState::kFailed:
      return "failed";
    case JobState::kCancelled:
      return "cancelled";
  }
  return "?";
}

StudioController::~StudioController() {
  Cancel();
  Join();
}

void StudioController::Join() {
  if (worker_.joinable()) worker_.join();
}

bool StudioController::Busy() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return status_.state == JobState::kRunning;
}

JobStatus StudioController::Status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  JobStatus status = status_;
  if (status.state == JobState::kRunning) {
    StageTracker tracker = tracker_;
    tracker.Tick(Clock::now());
    status.bars = tracker.bars();
    status.seconds = Seconds(Clock::now() - started_);
  }
  return status;
}

JobStatus StudioController::Wait() {
  Join();
  return Status();
}

void StudioController::Cancel() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (status_.state != JobState::kRunning) return;
  status_.cancelling = true;
  token_.Cancel();
  board_placed_.notify_all();
}

void StudioController::ConfirmBoardPlaced() {
  std::lock_guard<std::mutex> lock(mutex_);
  board_confirmed_ = true;
  status_.board_prompt.reset();
  board_placed_.notify_all();
}

void StudioController::OnProgress(const ProgressUpdate& update) {
  std::lock_guard<std::mutex> lock(mutex_);
  tracker_.Update(update, Clock::now());
  status_.bars = tracker_.bars();
  status_.stage_changes = change_base_ + tracker_.changes();
}

template <typename Work>
void StudioController::Launch(JobKind kind, const std::string& product,
                              const std::filesystem::path& session, Work work) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    CAROUSEL_THROW_IF(status_.state == JobState::kRunning, InvalidArgument,
                      "a session is running: wait for it or cancel it first");
  }
  Join();  // the previous job's thread has ended; reap it
  std::lock_guard<std::mutex> lock(mutex_);
  const int id = status_.id + 1;
  change_base_ = status_.stage_changes + 1;  // a new job is a change too
  JobStatus fresh;
  status_ = std::move(fresh);
  status_.kind = kind;
  status_.state = JobState::kRunning;
  status_.id = id;
  status_.product = product;
  status_.session = session;
  tracker_.Reset();
  status_.stage_changes = change_base_;
  started_ = Clock::now();
  token_ = CancellationToken();
  board_confirmed_ = false;
  worker_ = std::thread([this, work = std::move(work), token = token_]() mutable {
    // The pipeline yields to the window: its thread (and the threads its parallel loops start,
    // which inherit it) runs at a lower priority, so drawing never waits behind it.
    setpriority(PRIO_PROCESS, static_cast<id_t>(syscall(SYS_gettid)), kWorkerNice);
    Progress progress([this](const ProgressUpdate& u) { OnProgress(u); }, token);
    JobState state = JobState::kSucceeded;
    std::string error, advice;
    std::optional<studio::RunResult> run;
    std::optional<studio::ProcessResult> process;
    try {
      work(progress, &run, &process);
    } catch (const std::exception& e) {
      std::filesystem::path folder;
      {
        std::lock_guard<std::mutex> guard(mutex_);
        folder = status_.session;
      }
      const bool resumable = SessionResumable(folder);
      state = dynamic_cast<const Cancelled*>(&e) ? JobState::kCancelled : JobState::kFailed;
      error = state == JobState::kFailed ? e.what() : "";
      advice = AdviceFor(e, resumable);
      if (state == JobState::kFailed) CAROUSEL_LOG_ERROR("carousel-studio: " << e.what());
    }
    std::lock_guard<std::mutex> guard(mutex_);
    tracker_.Finish(state == JobState::kSucceeded, Clock::now());
    status_.bars = tracker_.bars();
    status_.stage_changes = change_base_ + tracker_.changes();
    status_.state = state;
    status_.error = error;
    status_.advice = advice;
    status_.cancelling = false;
    status_.board_prompt.reset();
    status_.resumable = state != JobState::kSucceeded && SessionResumable(status_.session);
    if (run) status_.session = run->session;
    status_.run = std::move(run);
    status_.process = std::move(process);
    status_.seconds = Seconds(Clock::now() - started_);
  });
}

void StudioController::WaitForOperator(int index, int placements, bool product) {
  std::unique_lock<std::mutex> lock(mutex_);
  status_.board_prompt = BoardPrompt{index, placements, product};
  board_confirmed_ = false;
  status_.stage_changes = ++change_base_ + tracker_.changes();
  board_placed_.wait(lock, [this] { return board_confirmed_ || token_.IsCancelled(); });
  status_.board_prompt.reset();
  if (token_.IsCancelled())
    throw Cancelled(product ? "laying the product down cancelled" : "board placement cancelled");
}

void StudioController::StartRun(studio::RunOptions options) {
  CAROUSEL_THROW_IF(options.product.empty(), InvalidArgument, "enter the product's SKU");
  options.Validate();
  const std::filesystem::path session =
      options.out / studio::SessionNameForProduct(options.product);
  // On hardware the operator places the board, or lays the product down for a later pass,
  // and confirms in the window.
  if (options.calibration && options.hardware) {
    options.place_board = [this](int index, int placements) {
      WaitForOperator(index, placements, false);
    };
  } else if (options.hardware && options.hardware->capture.orientations > 1) {
    options.turn_product = [this](int pass, int passes) { WaitForOperator(pass, passes, true); };
  }
  const std::string product = options.product;
  const bool calibration = options.calibration.has_value();
  Launch(JobKind::kRun, product, session,
         [options = std::move(options)](Progress& progress, std::optional<studio::RunResult>* run,
                                        std::optional<studio::ProcessResult>*) {
           *run = studio::RunSession(options, progress);
         });
  std::lock_guard<std::mutex> lock(mutex_);
  status_.calibration = calibration;
}

void StudioController::StartResume(const std::filesystem::path& session) {
  std::error_code ec;
  if (!std::filesystem::is_regular_file(session / "run.json", ec))
    throw IoError(session / "run.json",
                  "no run.json: not a session `carousel run` or the window started; use "
                  "Reprocess to build it again from its photos");
  // A hardware session of several passes asks the operator, in the window, to lay the
  // product as the pass it resumes in needs.
  auto turn_product = [this](int pass, int passes) { WaitForOperator(pass, passes, true); };
  Launch(JobKind::kResume, session.filename().string(), session,
         [session, turn_product](Progress& progress, std::optional<studio::RunResult>* run,
                                 std::optional<studio::ProcessResult>*) {
           *run = studio::ResumeSession(session, progress, turn_product);
         });
}

void StudioController::StartReprocess(const std::filesystem::path& session,
                                      studio::ProcessOptions options) {
  options.Validate();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(session / "session.json", ec))
    throw IoError(session / "session.json", "no session.json: not a session folder");
  Launch(
      JobKind::kReprocess, session.filename().string(), session,
      [session, options = std::move(options)](Progress& progress, std::optional<studio::RunResult>*,
                                              std::optional<studio::ProcessResult>* process) {
        *process = studio::ProcessSession(session, options, progress);
      });
}

CalibrationVerdict JudgeCalibration(const studio::CalibrateSessionResult& result, double max_rms_px,
                                    double max_angle_deg, int min_views) {
  CalibrationVerdict verdict;
  const calib::RigCalibration& c = result.result.calibration;
  char line[256];
  for (const calib::RigCameraCalibration& camera : c.cameras) {
    const CameraModel& m = camera.camera;
    std::snprintf(line, sizeof(line), "%s: fx %.1f fy %.1f cx %.1f cy %.1f, %d photos, %.3f px RMS",
                  camera.name.c_str(), m.fx, m.fy, m.cx, m.cy, camera.views, camera.rms_px);
    verdict.lines.emplace_back(line);
    if (!(camera.rms_px <= max_rms_px)) {
      std::snprintf(line, sizeof(line), "%s reprojects the board at %.2f px RMS (> %.2f px)",
                    camera.name.c_str(), camera.rms_px, max_rms_px);
      verdict.reasons.emplace_back(line);
    }
  }
  std::snprintf(line, sizeof(line),
                "turntable: observed/reported angle %.4f, largest deviation %.3f deg",
                c.angle_scale, c.angle_residual_max_deg);
  verdict.lines.emplace_back(line);
  if (!(c.angle_residual_max_deg <= max_angle_deg)) {
    std::snprintf(line, sizeof(line),
                  "the table turned up to %.2f deg away from where it reported (> %.2f deg)",
                  c.angle_residual_max_deg, max_angle_deg);
    verdict.reasons.emplace_back(line);
  }
  // A turntable shows each camera the board's face for about half a turn per placement: what
  // counts is enough good views per camera, not the share of all photos.
  for (const calib::RigCameraCalibration& camera : c.cameras) {
    if (camera.views < min_views) {
      std::snprintf(line, sizeof(line),
                    "%s saw the board well in %d photos (< %d): place it so that the camera "
                    "sees it whole for longer",
                    camera.name.c_str(), camera.views, min_views);
      verdict.reasons.emplace_back(line);
    }
  }
  if (c.cameras.empty()) verdict.reasons.emplace_back("no camera was calibrated");
  for (const std::string& w : result.result.warnings) verdict.lines.push_back("warning: " + w);
  verdict.pass = verdict.reasons.empty();
  return verdict;
}

bool ModelReady(const JobStatus& status) {
  if (status.state != JobState::kSucceeded) return false;
  std::error_code ec;
  return std::filesystem::is_regular_file(status.session / "model" / "model.obj", ec);
}

}  // namespace carousel::gui
