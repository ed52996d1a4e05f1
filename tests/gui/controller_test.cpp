// The window's decisions without a window: stage bars, the one-button job on a worker thread,
// cancel and resume, errors with what to do, the sessions browser and the photo watcher.
#include "carousel/gui/controller.h"

#include <gtest/gtest.h>

#include <map>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/gui/session_browser.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/session.h"
#include "carousel/testing/testing.h"

namespace carousel::gui {
namespace {

using Clock = StageTracker::Clock;
using State = StageBar::State;

TEST(StageStepTest, ProgressStagesBelongToTheirPipelineStage) {
  EXPECT_EQ(StepOf("capture")->stage, PipelineStage::kCapture);
  EXPECT_EQ(StepOf("render views")->stage, PipelineStage::kCapture);
  EXPECT_EQ(StepOf("silhouettes: multi-view consistency")->stage, PipelineStage::kReconstruct);
  EXPECT_EQ(StepOf("visual hull: carving")->stage, PipelineStage::kReconstruct);
  EXPECT_EQ(StepOf("mesh: decimation")->stage, PipelineStage::kReconstruct);
  EXPECT_EQ(StepOf("atlas: packing")->stage, PipelineStage::kTexture);
  EXPECT_EQ(StepOf("texture: transfer")->stage, PipelineStage::kTexture);
  EXPECT_EQ(StepOf("publish")->stage, PipelineStage::kPublish);
  EXPECT_FALSE(StepOf("bundle adjustment").has_value());
  // Steps of a stage cover its bar in order, without overlap.
  EXPECT_LE(StepOf("silhouettes")->end, StepOf("visual hull")->begin);
  EXPECT_LE(StepOf("atlas")->end, StepOf("texture: transfer")->begin);
}

TEST(StageTrackerTest, BarsFollowTheStepsAndEstimateTheTimeLeft) {
  StageTracker tracker;
  const Clock::time_point t0 = Clock::now();
  tracker.Update({"capture", 0.0, false}, t0);
  EXPECT_EQ(tracker.bars()[0].state, State::kRunning);
  EXPECT_EQ(tracker.bars()[1].state, State::kWaiting);
  tracker.Update({"capture", 0.5, false}, t0 + std::chrono::seconds(10));
  EXPECT_DOUBLE_EQ(tracker.bars()[0].fraction, 0.5);
  // Half done in 10 s at its own pace: 10 s left.
  EXPECT_NEAR(tracker.bars()[0].seconds_left, 10.0, 1e-6);
  // A fraction going back (a sub-step restarting at 0) never moves the bar back.
  tracker.Update({"capture", 0.2, false}, t0 + std::chrono::seconds(11));
  EXPECT_DOUBLE_EQ(tracker.bars()[0].fraction, 0.5);

  tracker.Update({"visual hull: carving", 0.5, false}, t0 + std::chrono::seconds(20));
  EXPECT_EQ(tracker.bars()[0].state, State::kDone);
  EXPECT_DOUBLE_EQ(tracker.bars()[0].fraction, 1.0);
  EXPECT_NEAR(tracker.bars()[0].seconds, 20.0, 1e-6);
  EXPECT_EQ(tracker.bars()[1].state, State::kRunning);
  const auto hull = *StepOf("visual hull");
  EXPECT_DOUBLE_EQ(tracker.bars()[1].fraction, hull.begin + 0.5 * (hull.end - hull.begin));
  EXPECT_EQ(tracker.bars()[1].step, "visual hull: carving");

  // A resumed session whose reconstruction was current starts at texture: the stages before
  // it are done.
  StageTracker resumed;
  resumed.Update({"texture: grouping", 0.0, false}, t0);
  EXPECT_EQ(resumed.bars()[0].state, State::kDone);
  EXPECT_EQ(resumed.bars()[1].state, State::kDone);
  EXPECT_EQ(resumed.bars()[2].state, State::kRunning);
  const int changes = resumed.changes();
  resumed.Finish(false, t0 + std::chrono::seconds(1));  // cancelled: stays where it stopped
  EXPECT_EQ(resumed.bars()[2].state, State::kRunning);
  EXPECT_GT(resumed.changes(), changes);
  resumed.Finish(true, t0 + std::chrono::seconds(2));
  EXPECT_EQ(resumed.bars()[2].state, State::kDone);
  EXPECT_EQ(resumed.bars()[3].state, State::kWaiting);  // never ran (no publish)
}

TEST(AdviceTest, EachKindOfErrorSaysWhatToDo) {
  EXPECT_NE(AdviceFor(DeviceError("/dev/ttyUSB0", "no answer"), true).find("Resume"),
            std::string::npos);
  EXPECT_NE(AdviceFor(DeviceError("/dev/ttyUSB0", "no answer"), true).find("device"),
            std::string::npos);
  EXPECT_EQ(AdviceFor(DeviceError("/dev/ttyUSB0", "x"), false).find("Resume"), std::string::npos);
  EXPECT_NE(AdviceFor(InvalidArgument("--views must be >= 1"), false).find("setting"),
            std::string::npos);
  EXPECT_NE(AdviceFor(Cancelled("stop"), true).find("every verified photo"), std::string::npos);
  EXPECT_NE(AdviceFor(FormatError("a.json", "bad"), true).find("damaged"), std::string::npos);
}

// A small session of the simulated shoe: 6 stops at 360x240, one view held out, publishing at
// sizes that suit the photos.
studio::RunOptions SmallRun(const std::filesystem::path& out, const std::string& product) {
  studio::RunOptions options;
  options.product = product;
  options.out = out;
  options.sim.data_dir = testing::SharedDataDir();
  options.sim.stops = 6;
  options.sim.rig.width = 360;
  options.sim.rig.height = 240;
  options.texture.grouping.exclude_views = {1};
  options.publish.spin_size = 240;
  options.publish.hero_size = 480;
  options.publish.poster_size = 240;
  options.publish.cutout_size = 480;
  return options;
}

std::map<std::string, std::string> PhotoChecksums(const std::filesystem::path& session) {
  std::map<std::string, std::string> sums;
  for (const auto& entry : std::filesystem::directory_iterator(session / "images"))
    sums[entry.path().filename().string()] = studio::FileSha256(entry.path());
  return sums;
}

// Polls the controller until its job ends, keeping every snapshot.
std::vector<JobStatus> Follow(StudioController& controller,
                              const std::function<void(const JobStatus&)>& on_status = {}) {
  std::vector<JobStatus> seen;
  while (true) {
    JobStatus status = controller.Status();
    if (on_status) on_status(status);
    const bool running = status.state == JobState::kRunning;
    seen.push_back(std::move(status));
    if (!running) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return seen;
}

TEST(StudioControllerTest, OneButtonSessionShowsEveryStageAndEndsWithAModel) {
  testing::TempDir dir;
  StudioController controller;
  controller.StartRun(SmallRun(dir.path(), "shoe gui"));
  EXPECT_TRUE(controller.Busy());
  // A second press while it runs is refused, and changes nothing.
  EXPECT_THROW(controller.StartRun(SmallRun(dir.path(), "other")), InvalidArgument);
  const std::vector<JobStatus> seen = Follow(controller);
  const JobStatus& last = seen.back();
  ASSERT_EQ(last.state, JobState::kSucceeded) << last.error;
  EXPECT_EQ(last.session, dir.path() / "shoe_gui");
  EXPECT_TRUE(ModelReady(last));
  ASSERT_TRUE(last.run.has_value());
  EXPECT_EQ(last.run->photos_taken, 6);
  EXPECT_FALSE(last.resumable);
  for (int i = 0; i < kPipelineStages; ++i) {
    EXPECT_EQ(last.bars[i].state, State::kDone) << PipelineStageName(PipelineStage(i));
    EXPECT_GT(last.bars[i].seconds, 0.0) << PipelineStageName(PipelineStage(i));
  }
  // Every bar was seen running, its fraction never went back, and the stages ran in order.
  std::array<bool, kPipelineStages> ran{};
  std::array<double, kPipelineStages> fraction{};
  int highest = -1;
  for (const JobStatus& s : seen) {
    for (int i = 0; i < kPipelineStages; ++i) {
      EXPECT_GE(s.bars[i].fraction, fraction[i] - 1e-12);
      fraction[i] = s.bars[i].fraction;
      if (s.bars[i].state == State::kRunning) {
        ran[i] = true;
        EXPECT_GE(i, highest);
        highest = i;
      }
    }
  }
  for (int i = 0; i < kPipelineStages; ++i)
    EXPECT_TRUE(ran[i]) << PipelineStageName(PipelineStage(i));
  EXPECT_GT(last.stage_changes, 8);

  // The sessions browser lists it as complete; the photo watcher hands out every photo,
  // verified, with its mask.
  const std::vector<SessionSummary> sessions = ListSessions(dir.path());
  ASSERT_EQ(sessions.size(), 1u);
  EXPECT_EQ(sessions[0].state, "complete");
  EXPECT_EQ(sessions[0].photos, 6);
  EXPECT_TRUE(sessions[0].has_model);
  PhotoWatcher watcher(64, 20);
  watcher.Watch(last.session);
  std::vector<PhotoThumb> thumbs;
  for (int i = 0; i < 500 && thumbs.size() < 6; ++i) {
    for (PhotoThumb& t : watcher.TakeReady()) thumbs.push_back(std::move(t));
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_EQ(thumbs.size(), 6u);
  for (const PhotoThumb& t : thumbs) {
    EXPECT_TRUE(t.verified) << t.stem << ": " << t.problem;
    EXPECT_EQ(t.rgba.type(), CV_8UC4);
    EXPECT_EQ(std::max(t.rgba.cols, t.rgba.rows), 64);
    EXPECT_EQ(t.mask_rgba.size(), t.rgba.size()) << t.stem;
  }
}

TEST(StudioControllerTest, CancelledMidTextureResumesWithoutLosingOrRetakingAPhoto) {
  testing::TempDir dir;
  StudioController controller;
  controller.StartRun(SmallRun(dir.path(), "cancel-me"));
  bool cancelled = false;
  const std::vector<JobStatus> seen = Follow(controller, [&](const JobStatus& s) {
    if (!cancelled && s.bars[2].state == State::kRunning) {
      controller.Cancel();
      cancelled = true;
    }
  });
  ASSERT_TRUE(cancelled);
  const JobStatus& stopped = seen.back();
  ASSERT_EQ(stopped.state, JobState::kCancelled);
  EXPECT_TRUE(stopped.resumable);
  EXPECT_TRUE(stopped.error.empty());
  EXPECT_NE(stopped.advice.find("Resume"), std::string::npos);
  EXPECT_EQ(stopped.bars[1].state, State::kDone);
  EXPECT_NE(stopped.bars[2].state, State::kDone);
  const std::filesystem::path session = stopped.session;
  const auto before = PhotoChecksums(session);
  ASSERT_EQ(before.size(), 6u);

  // The Sessions panel offers it for resuming.
  const std::vector<SessionSummary> sessions = ListSessions(dir.path());
  ASSERT_EQ(sessions.size(), 1u);
  EXPECT_TRUE(sessions[0].resumable);
  EXPECT_EQ(sessions[0].state, "reconstructed");
  EXPECT_FALSE(sessions[0].has_model);

  controller.StartResume(sessions[0].folder);
  const JobStatus resumed = controller.Wait();
  ASSERT_EQ(resumed.state, JobState::kSucceeded) << resumed.error;
  ASSERT_TRUE(resumed.run.has_value());
  EXPECT_EQ(resumed.run->photos_taken, 0);
  EXPECT_EQ(resumed.run->photos_kept, 6);
  EXPECT_EQ(resumed.run->photos_retaken, 0);
  EXPECT_FALSE(resumed.run->reconstructed);  // current: not run again
  EXPECT_TRUE(resumed.run->textured);
  EXPECT_EQ(PhotoChecksums(session), before);
  EXPECT_TRUE(ModelReady(resumed));
  EXPECT_EQ(ListSessions(dir.path())[0].state, "complete");
}

TEST(StudioControllerTest, AFailureNamesWhatFailedAndWhatToDo) {
  testing::TempDir dir;
  // The sessions folder is a file: the run cannot create its session there.
  testing::WriteBytes(dir / "not-a-folder", "x");
  StudioController controller;
  EXPECT_THROW(controller.StartRun(SmallRun(dir.path(), "")), InvalidArgument);  // no SKU
  controller.StartRun(SmallRun(dir / "not-a-folder", "shoe"));
  const JobStatus failed = controller.Wait();
  ASSERT_EQ(failed.state, JobState::kFailed);
  EXPECT_NE(failed.error.find("not-a-folder"), std::string::npos) << failed.error;
  EXPECT_FALSE(failed.advice.empty());
  EXPECT_FALSE(failed.resumable);
  EXPECT_FALSE(ModelReady(failed));
  // Resume of a folder that is no session says so, naming the file.
  try {
    controller.StartResume(dir.path());
    FAIL() << "resumed a folder without run.json";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("run.json"), std::string::npos);
  }
}

TEST(CalibrationVerdictTest, PassesOnlyAGoodCalibrationAndSaysWhatFailed) {
  studio::CalibrateSessionResult good;
  calib::RigCameraCalibration camera;
  camera.name = "cam0";
  camera.views = 10;
  camera.rms_px = 0.3;
  good.result.calibration.cameras = {camera};
  good.result.calibration.angle_residual_max_deg = 0.1;
  const CalibrationVerdict pass = JudgeCalibration(good);
  EXPECT_TRUE(pass.pass);
  EXPECT_TRUE(pass.reasons.empty());
  EXPECT_EQ(pass.lines.size(), 2u);  // the camera and the table

  studio::CalibrateSessionResult blurry = good;
  blurry.result.calibration.cameras[0].rms_px = 1.7;
  const CalibrationVerdict v1 = JudgeCalibration(blurry);
  EXPECT_FALSE(v1.pass);
  ASSERT_EQ(v1.reasons.size(), 1u);
  EXPECT_NE(v1.reasons[0].find("1.70 px"), std::string::npos) << v1.reasons[0];

  studio::CalibrateSessionResult slipping = good;
  slipping.result.calibration.angle_residual_max_deg = 0.8;
  EXPECT_FALSE(JudgeCalibration(slipping).pass);

  studio::CalibrateSessionResult few = good;
  few.result.calibration.cameras[0].views = 3;
  const CalibrationVerdict v3 = JudgeCalibration(few);
  EXPECT_FALSE(v3.pass);
  EXPECT_NE(v3.reasons[0].find("3 photos"), std::string::npos) << v3.reasons[0];

  studio::CalibrateSessionResult none;
  EXPECT_FALSE(JudgeCalibration(none).pass);
}

TEST(SessionBrowserTest, DamagedAndHalfStartedSessionsAreListedWithTheirState) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "broken");
  testing::WriteBytes(dir / "broken" / "session.json", "{ not json");
  std::filesystem::create_directories(dir / "starting");
  testing::WriteBytes(dir / "starting" / "run.json", "{}");
  std::filesystem::create_directories(dir / ".staging-x");
  testing::WriteBytes(dir / ".staging-x" / "run.json", "{}");
  std::filesystem::create_directories(dir / "unrelated");
  const std::vector<SessionSummary> sessions = ListSessions(dir.path());
  ASSERT_EQ(sessions.size(), 2u);
  std::map<std::string, SessionSummary> by_name;
  for (const SessionSummary& s : sessions) by_name[s.folder.filename().string()] = s;
  EXPECT_EQ(by_name["broken"].state, "unreadable");
  EXPECT_NE(by_name["broken"].problem.find("session.json"), std::string::npos);
  EXPECT_EQ(by_name["starting"].state, "capturing");
  EXPECT_TRUE(by_name["starting"].resumable);
  EXPECT_TRUE(ListSessions(dir / "missing").empty());
}

}  // namespace
}  // namespace carousel::gui
