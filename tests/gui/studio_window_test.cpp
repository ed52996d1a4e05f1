// carousel-studio as a photographer and an operator run it: the real window (GLFW, Dear ImGui,
// OpenGL 3.3) under Xvfb with Mesa's llvmpipe, pressed by its --autorun, judged on the session
// folders it leaves and on its screenshots' pixels.
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <map>
#include <set>
#include <thread>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/gui/session_browser.h"
#include "carousel/gui/studio_args.h"
#include "carousel/sim/ptpip_camera.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/session.h"
#include "carousel/studio/simulated_studio.h"
#include "carousel/testing/testing.h"

namespace carousel::gui {
namespace {

// Small photos: 6 stops at 360x240 with view 1 held out; no publish stage (its renders cost
// most under the sanitizers, and app_test covers it), except in the first test, which
// publishes at sizes that suit the photos.
constexpr char kCapture[] = " --size 360x240 --views 6 --exclude-views 1 --no-publish";
constexpr char kCaptureAndPublish[] =
    " --size 360x240 --views 6 --exclude-views 1 --spin-size 240 --hero-size 480"
    " --poster-size 240 --cutout-size 480";

std::string Studio() { return (testing::BinDir() / "carousel-studio").string(); }

// One virtual X server (Xvfb, Mesa's llvmpipe behind GLX) for the test binary: it picks a free
// display number and writes it to a pipe (-displayfd); DISPLAY points the windows at it.
class XvfbDisplay : public ::testing::Environment {
 public:
  void SetUp() override {
    int fds[2];
    ASSERT_EQ(::pipe(fds), 0);
    const std::string fd = std::to_string(fds[1]);
    std::vector<std::string> args = {"Xvfb",        "-displayfd", fd,    "-screen", "0",
                                     "1280x800x24", "-nolisten",  "tcp", "-noreset"};
    std::vector<char*> argv;
    argv.reserve(args.size() + 1);
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    ASSERT_EQ(::posix_spawnp(&pid_, "Xvfb", nullptr, nullptr, argv.data(), environ), 0)
        << "Xvfb is missing (scripts/install-deps installs it)";
    ::close(fds[1]);
    std::string display;
    char c = 0;
    while (::read(fds[0], &c, 1) == 1 && c != '\n') display += c;
    ::close(fds[0]);
    ASSERT_FALSE(display.empty()) << "Xvfb did not start";
    ::setenv("DISPLAY", (":" + display).c_str(), 1);
  }
  void TearDown() override {
    if (pid_ <= 0) return;
    ::kill(pid_, SIGTERM);
    int status = 0;
    ::waitpid(pid_, &status, 0);
  }

 private:
  pid_t pid_ = -1;
};
const auto* const xvfb_display = ::testing::AddGlobalTestEnvironment(new XvfbDisplay);

// The window on the virtual display.
testing::ShellResult RunWindow(const std::string& args) {
  return testing::RunShell(Studio() + " --data " + testing::SharedDataDir().string() + " " + args +
                           " 2>&1");
}

std::set<std::string> FilesUnder(const std::filesystem::path& folder) {
  std::set<std::string> files;
  for (const auto& e : std::filesystem::recursive_directory_iterator(folder))
    if (e.is_regular_file()) files.insert(std::filesystem::relative(e.path(), folder).string());
  return files;
}

std::vector<std::filesystem::path> Screenshots(const std::filesystem::path& folder) {
  std::vector<std::filesystem::path> shots;
  for (const auto& e : std::filesystem::directory_iterator(folder))
    if (e.path().extension() == ".png") shots.push_back(e.path());
  std::sort(shots.begin(), shots.end());
  return shots;
}

// The model view is the region painted in its clear colour (41, 43, 48) where the model does
// not cover it: its bounding box, and within it the fraction the model covers and how much the
// model's colours vary.
struct ModelViewPixels {
  cv::Rect box;
  double coverage = 0.0;
  double colour_stddev = 0.0;  // mean over the channels, of the covered pixels
};

ModelViewPixels MeasureModelView(const cv::Mat& bgr) {
  cv::Mat background;
  cv::inRange(bgr, cv::Scalar(47, 42, 40), cv::Scalar(50, 45, 42), background);
  ModelViewPixels out;
  std::vector<cv::Point> points;
  cv::findNonZero(background, points);
  if (points.size() < 1000) return out;
  out.box = cv::boundingRect(points);
  const cv::Mat region = bgr(out.box);
  const cv::Mat covered = 255 - background(out.box);
  out.coverage = cv::countNonZero(covered) / static_cast<double>(out.box.area());
  cv::Scalar mean, stddev;
  cv::meanStdDev(region, mean, stddev, covered);
  out.colour_stddev = (stddev[0] + stddev[1] + stddev[2]) / 3.0;
  return out;
}

TEST(StudioWindowTest, AutorunBuildsWhatCarouselRunBuildsAndShowsTheTexturedModel) {
  testing::TempDir dir;
  const testing::ShellResult cli = testing::RunShell(
      testing::CarouselExecutable() + " run --sim --data " + testing::SharedDataDir().string() +
      " --product shoe-1 --out " + (dir / "cli").string() + kCaptureAndPublish + " 2>&1");
  ASSERT_EQ(cli.code, 0) << cli.out;
  const testing::ShellResult window =
      RunWindow("--sim --product shoe-1 --out " + (dir / "gui").string() + kCaptureAndPublish +
                " --autorun --quit-when-done --screenshot-dir " + (dir / "shots").string() +
                " --frame-log " + (dir / "frames.txt").string());
  ASSERT_EQ(window.code, 0) << window.out;

  // The same session folder: the same files, the same photos, the same mesh size.
  const std::filesystem::path a = dir / "cli" / "shoe-1", b = dir / "gui" / "shoe-1";
  EXPECT_EQ(FilesUnder(a), FilesUnder(b));
  const studio::Session sa = studio::ReadSession(a), sb = studio::ReadSession(b);
  ASSERT_EQ(sa.views.size(), 6u);
  ASSERT_EQ(sb.views.size(), sa.views.size());
  for (std::size_t i = 0; i < sa.views.size(); ++i) {
    EXPECT_EQ(sb.views[i].sha256, sa.views[i].sha256) << sa.views[i].image;
    EXPECT_EQ(sb.views[i].mask_sha256, sa.views[i].mask_sha256) << sa.views[i].mask;
    EXPECT_EQ(sb.views[i].sha256, studio::FileSha256(b / sb.views[i].image));
  }
  for (const char* stage : {"capture", "reconstruct", "texture", "publish"})
    EXPECT_EQ(sb.stages.at(stage), "done") << stage;
  // The stages ran on the same inputs (photos, cameras, options).
  EXPECT_EQ(sb.stage_inputs, sa.stage_inputs);
  EXPECT_EQ(sb.stage_inputs.size(), 3u);
  for (const char* file : {"model/model.obj", "model/model.glb", "model/model.web.glb",
                           "model/index.html", "model/report.json", "recon/mesh.ply"})
    EXPECT_TRUE(std::filesystem::is_regular_file(b / file)) << file;

  // A screenshot at each stage change, the last one showing the textured model.
  const std::vector<std::filesystem::path> shots = Screenshots(dir / "shots");
  ASSERT_GE(shots.size(), 6u);
  std::set<std::string> stages_shown;
  for (const auto& s : shots)
    for (const char* stage : {"capture", "reconstruct", "texture", "publish"})
      if (s.filename().string().find(stage) != std::string::npos) stages_shown.insert(stage);
  EXPECT_EQ(stages_shown.size(), 4u);
  EXPECT_NE(shots.back().filename().string().find("final"), std::string::npos);
  const cv::Mat last = cv::imread(shots.back().string());
  ASSERT_EQ(last.size(), cv::Size(1280, 800));
  const ModelViewPixels view = MeasureModelView(last);
  EXPECT_GT(view.box.area(), 1280 * 800 / 5) << "model view " << view.box;
  EXPECT_GT(view.coverage, 0.08) << "model view " << view.box;
  EXPECT_LT(view.coverage, 0.9) << "model view " << view.box;
  EXPECT_GT(view.colour_stddev, 15.0);  // textured, not one flat colour
  // The view before the final one is still the model (an empty view has no covered pixels).
  const ModelViewPixels before_model = MeasureModelView(cv::imread(shots.front().string()));
  EXPECT_LT(before_model.coverage, view.coverage);

  const FrameStats frames = SummarizeFrameTimes(ReadFrameLog(dir / "frames.txt"));
  EXPECT_GT(frames.frames, 30);
  std::printf(
      "frame times while the pipeline ran: %d frames, p50 %.1f ms, p99 %.1f ms, max %.1f ms\n",
      frames.frames, frames.p50_ms, frames.p99_ms, frames.max_ms);
}

// A bottle on its side, without the colours' help: the second pass's pose is ambiguous, and the
// window shows its pictures with a button under each; the autorun presses pose 2's as the
// photographer would, and the session is reprocessed with the pass registered from that pose.
TEST(StudioWindowTest, AnAmbiguousPassIsRegisteredFromThePictureThePhotographerChooses) {
  testing::TempDir dir;
  const testing::ShellResult window = RunWindow(
      "--sim --scene bottle --orientations 2 --no-pose-by-colour --size 360x240 --views 6 "
      "--no-publish --product bottle-1 --out " +
      (dir / "s").string() +
      " --autorun --autorun-choose-pose 2 --quit-when-done --screenshot-dir " +
      (dir / "shots").string());
  ASSERT_EQ(window.code, 0) << window.out;
  const std::filesystem::path folder = dir / "s" / "bottle-1";
  const studio::Session session = studio::ReadSession(folder);
  ASSERT_EQ(session.passes.size(), 2u);
  EXPECT_EQ(session.passes[1].registration, "registered") << session.passes[1].registration_note;
  EXPECT_EQ(session.passes[1].chosen_pose, 2);
  ASSERT_GE(session.passes[1].pose_choices.size(), 2u);
  EXPECT_NE(session.passes[1].registration_note.find("the operator chose (2 of"), std::string::npos)
      << session.passes[1].registration_note;
  EXPECT_EQ(session.stages.at("texture"), "done");

  // The pictures were on screen: the first one, as a button's thumbnail, found in the
  // screenshot taken before the choice.
  const std::filesystem::path shot = [&] {
    for (const auto& s : Screenshots(dir / "shots"))
      if (s.filename().string().find("choose-pose") != std::string::npos) return s;
    return std::filesystem::path();
  }();
  ASSERT_FALSE(shot.empty());
  const cv::Mat screen = cv::imread(shot.string());
  const cv::Mat picture = cv::imread((folder / "recon" / "pass2_pose1.jpg").string());
  ASSERT_FALSE(picture.empty());
  const double scale = 128.0 / std::max(picture.cols, picture.rows);
  cv::Mat thumb;
  cv::resize(picture, thumb, cv::Size(), scale, scale, cv::INTER_AREA);
  cv::Mat match;
  cv::matchTemplate(screen, thumb, match, cv::TM_CCOEFF_NORMED);
  double best = 0.0;
  cv::minMaxLoc(match, nullptr, &best);
  std::printf("pose picture 1 found in the window with a correlation of %.3f\n", best);
  EXPECT_GT(best, 0.8);
}

TEST(StudioWindowTest, OperatorModeBuildsTwoProductsInARowOnePressEach) {
  testing::TempDir dir;
  const testing::ShellResult window = RunWindow(
      "--operator --sim --product op-a --product op-b --out " + (dir / "s").string() + kCapture +
      " --autorun --quit-when-done --screenshot-dir " + (dir / "shots").string());
  ASSERT_EQ(window.code, 0) << window.out;
  for (const char* sku : {"op-a", "op-b"}) {
    const studio::Session session = studio::ReadSession(dir / "s" / sku);
    EXPECT_EQ(session.views.size(), 6u) << sku;
    EXPECT_EQ(session.stages.at("texture"), "done") << sku;
    EXPECT_TRUE(std::filesystem::is_regular_file(dir / "s" / sku / "model" / "model.glb"));
    // Its result screen: a large green verdict.
    const std::filesystem::path shot = [&] {
      for (const auto& s : Screenshots(dir / "shots"))
        if (s.filename().string().find(std::string(sku) + "-result") != std::string::npos) return s;
      return std::filesystem::path();
    }();
    ASSERT_FALSE(shot.empty()) << sku;
    const cv::Mat image = cv::imread(shot.string());
    cv::Mat green;
    cv::inRange(image, cv::Scalar(80, 180, 55), cv::Scalar(100, 200, 75), green);
    EXPECT_GT(cv::countNonZero(green), image.total() / 6) << shot;
  }
}

TEST(StudioWindowTest, TheCalibrationWizardEndsWithAClearVerdict) {
  testing::TempDir dir;
  const testing::ShellResult window =
      RunWindow("--sim --calibration --size 480x320 --views 12 --out " + (dir / "s").string() +
                " --autorun --quit-when-done --screenshot-dir " + (dir / "shots").string());
  ASSERT_EQ(window.code, 0) << window.out;  // 0: the session ran and its verdict was a pass
  std::vector<std::filesystem::path> sessions;
  for (const auto& e : std::filesystem::directory_iterator(dir / "s")) sessions.push_back(e.path());
  ASSERT_EQ(sessions.size(), 1u);
  EXPECT_EQ(sessions[0].filename().string().rfind("rig-calibration-", 0), 0u);
  EXPECT_TRUE(
      std::filesystem::is_regular_file(sessions[0] / "calibration" / "rig_calibration.json"));
  // The wizard's third step shows the verdict in green in the left column.
  const cv::Mat last = cv::imread(Screenshots(dir / "shots").back().string());
  cv::Mat green;
  cv::inRange(last(cv::Rect(0, 0, 440, 800)), cv::Scalar(80, 180, 55), cv::Scalar(100, 200, 75),
              green);
  EXPECT_GT(cv::countNonZero(green), 420 * 40);
}

// A studio in a box (what `carousel sim rig` runs): the firmware in simavr behind a PTY and two
// PTP/IP camera emulators, 6 stops at 360x240; the window drives it through real termios and
// real libgphoto2 from its rig file.
class StudioWindowHardwareTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ::setenv("HOME", home_.path().c_str(), 1);  // libgphoto2's ~/.gphoto/settings
    studio::SimulatedStudioOptions options;
    options.sim.data_dir = testing::SharedDataDir();
    options.sim.rig.width = 360;
    options.sim.rig.height = 240;
    options.sim.stops = 6;
    options.settle_ms = 20;
    options.folder = dir_.path();
    studio_ = std::make_unique<studio::SimulatedStudio>(options);
    studio::WriteRigConfig(dir_ / "rig.json", studio_->Config());
  }

  std::string WindowArgs(const std::string& product) const {
    return "--rig " + (dir_ / "rig.json").string() + " --product " + product + " --out " +
           (dir_ / "sessions").string() +
           " --exclude-views 1 --no-publish --autorun --quit-when-done --screenshot-dir " +
           (dir_ / "shots").string();
  }

  testing::TempDir home_, dir_;
  std::unique_ptr<studio::SimulatedStudio> studio_;
};

TEST_F(StudioWindowHardwareTest, LiveViewThenAOneButtonSessionThroughFirmwareAndLibgphoto2) {
  const testing::ShellResult window = RunWindow(WindowArgs("hw-shoe"));
  ASSERT_EQ(window.code, 0) << window.out;
  // Live view: preview frames were streamed from the first camera before the session, and the
  // Rig panel showed one (a photo of the product: not one flat colour).
  EXPECT_GE(studio_->camera(0)->Counters().preview_frames, 3);
  const std::vector<std::filesystem::path> shots = Screenshots(dir_ / "shots");
  ASSERT_FALSE(shots.empty());
  EXPECT_NE(shots.front().filename().string().find("live-view"), std::string::npos);
  const cv::Mat live = cv::imread(shots.front().string());
  cv::Scalar mean, stddev;
  cv::meanStdDev(live(cv::Rect(0, 0, 440, 800)), mean, stddev);
  EXPECT_GT(stddev[0], 30.0);  // the left column holds a photo, not only the dark panel
  // The session: every photo came through libgphoto2 from the emulators, in order.
  const std::filesystem::path session = dir_ / "sessions" / "hw-shoe";
  const studio::Session manifest = studio::ReadSession(session);
  ASSERT_EQ(manifest.views.size(), 12u);  // 6 stops x 2 cameras
  for (int c = 0; c < 2; ++c) EXPECT_EQ(studio_->camera(c)->Photos().size(), 6u) << c;
  for (const studio::SessionView& v : manifest.views)
    EXPECT_EQ(studio::FileSha256(session / v.image), v.sha256) << v.image;
  EXPECT_EQ(manifest.stages.at("texture"), "done");
  const ModelViewPixels view = MeasureModelView(cv::imread(shots.back().string()));
  EXPECT_GT(view.coverage, 0.08);
  EXPECT_GT(view.colour_stddev, 15.0);
}

TEST_F(StudioWindowHardwareTest, ACameraUnpluggedDuringCaptureIsShownAndTheSessionResumes) {
  const std::filesystem::path session = dir_ / "sessions" / "unplug";
  testing::ShellResult window;
  std::thread run([&] { window = RunWindow(WindowArgs("unplug")); });
  // Pull camera 1's plug once four photos are recorded.
  std::size_t recorded = 0;
  for (int i = 0; i < 6000 && recorded < 4; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    try {
      recorded = studio::ReadSession(session).views.size();
    } catch (const Error&) {
      continue;  // not written yet
    }
  }
  studio_->UnplugCamera(1);
  run.join();
  ASSERT_GE(recorded, 4u);
  EXPECT_EQ(window.code, 1) << window.out;  // the autorun's session failed
  // The window said so: red text naming the camera, on its last screenshot.
  const std::vector<std::filesystem::path> shots = Screenshots(dir_ / "shots");
  ASSERT_FALSE(shots.empty());
  const cv::Mat last = cv::imread(shots.back().string());
  cv::Mat red;
  cv::inRange(last(cv::Rect(0, 0, 440, 800)), cv::Scalar(60, 60, 215), cv::Scalar(95, 95, 245),
              red);
  EXPECT_GT(cv::countNonZero(red), 200) << shots.back();
  EXPECT_NE(window.out.find("EMU1"), std::string::npos) << window.out;

  // Nothing captured is lost, and the Sessions panel offers it for resuming.
  const studio::Session before = studio::ReadSession(session);
  ASSERT_LT(before.views.size(), 12u);
  std::map<std::string, std::string> kept;
  for (const studio::SessionView& v : before.views) {
    EXPECT_EQ(studio::FileSha256(session / v.image), v.sha256) << v.image;
    kept[v.image] = v.sha256;
  }
  const std::vector<SessionSummary> sessions = ListSessions(dir_ / "sessions");
  ASSERT_EQ(sessions.size(), 1u);
  EXPECT_TRUE(sessions[0].resumable);
  EXPECT_EQ(sessions[0].state, "capturing");

  // Plugged back in, the session resumes: every photo kept, the rest taken.
  studio_->PlugInCamera(1);
  const testing::ShellResult resumed = testing::RunShell(
      testing::CarouselExecutable() + " run --resume " + session.string() + " 2>&1");
  ASSERT_EQ(resumed.code, 0) << resumed.out;
  const studio::Session after = studio::ReadSession(session);
  EXPECT_EQ(after.views.size(), 12u);
  for (const studio::SessionView& v : after.views) {
    if (kept.count(v.image) != 0) {
      EXPECT_EQ(v.sha256, kept[v.image]) << v.image;
    }
  }
  EXPECT_EQ(after.stages.at("texture"), "done");
}

}  // namespace
}  // namespace carousel::gui
