#include "studio_app.h"

#include <algorithm>
#include <cctype>
#include <cstdio>
#include <thread>
#include <tuple>

#include <dlfcn.h>
#include <link.h>

#define GLFW_INCLUDE_NONE
#include <GLFW/glfw3.h>
#include <imgui.h>
#include <imgui_impl_glfw.h>
#include <imgui_impl_opengl3.h>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/json.h"
#include "carousel/core/logging.h"
#include "carousel/studio/calibrate_session.h"
#include "carousel/studio/session.h"

namespace carousel::gui {
namespace {

using Clock = std::chrono::steady_clock;

constexpr auto kFramePeriod = std::chrono::microseconds(16667);  // 60 frames per second

template <typename T>
bool Ready(const std::future<T>& future) {
  return future.valid() && future.wait_for(std::chrono::seconds(0)) == std::future_status::ready;
}

void DeleteTexture(GLuint* texture) {
  if (*texture != 0) glDeleteTextures(1, texture);
  *texture = 0;
}

// The first pass of the job's reconstruction whose pose was ambiguous (1-based; 0: none).
int AmbiguousPass(const JobStatus& job) {
  if (job.state != JobState::kSucceeded) return 0;
  const std::optional<studio::ReconstructResult>& reconstructed =
      job.run       ? job.run->reconstruct
      : job.process ? job.process->reconstruct
                    : std::optional<studio::ReconstructResult>();
  if (!reconstructed) return 0;
  for (const studio::PassOutcome& pass : reconstructed->passes)
    if (pass.status == "ambiguous") return pass.pass + 1;
  return 0;
}

std::string StageLabel(const JobStatus& job) {
  if (job.state != JobState::kRunning) return JobStateName(job.state);
  for (int i = kPipelineStages - 1; i >= 0; --i)
    if (job.bars[i].state == StageBar::State::kRunning)
      return PipelineStageName(static_cast<PipelineStage>(i));
  return "starting";
}

void OnGlfwError(int code, const char* text) {
  CAROUSEL_LOG_ERROR("GLFW error " << code << ": " << text);
}

}  // namespace

StudioApp::StudioApp(StudioArgs args) : args_(std::move(args)) {
  if (!args_.frame_log.empty()) {
    frame_log_.open(args_.frame_log, std::ios::trunc);
    if (!frame_log_) throw IoError(args_.frame_log, "cannot write the frame log");
  }
  if (!args_.screenshot_dir.empty()) {
    std::error_code ec;
    std::filesystem::create_directories(args_.screenshot_dir, ec);
    if (ec)
      throw IoError(args_.screenshot_dir, "cannot create the screenshot folder: " + ec.message());
  }
  if (!args_.products.empty()) sku_ = args_.operator_mode ? "" : args_.products.front();
  out_text_ = args_.run.out.string();
  sessions_ = ListSessions(args_.run.out);
}

StudioApp::~StudioApp() {
  controller_.Cancel();
  controller_.Wait();
  rig_.Disconnect();
  if (window_ != nullptr) {
    ClearThumbs();
    ClearPosePictures();
    DeleteTexture(&live_view_);
    DeleteTexture(&held_out_photo_);
    DeleteTexture(&held_out_render_);
    renderer_.reset();
    ImGui_ImplOpenGL3_Shutdown();
    ImGui_ImplGlfw_Shutdown();
    ImGui::DestroyContext();
    glfwDestroyWindow(window_);
    glfwTerminate();
  }
}

namespace {

#ifdef CAROUSEL_SANITIZE_BUILD
// LeakSanitizer reports at exit, after GLFW has unloaded the GL vendor libraries (Mesa's GLX
// vendor and its DRI driver, dlopen'ed by libglvnd): their allocations would show from an
// "<unknown module>" that tests/lsan.supp cannot name. Pinning every library loaded now
// keeps them mapped, so their frames are named and suppressed there.
int PinLoaded(dl_phdr_info* info, std::size_t, void*) {
  if (info->dlpi_name != nullptr && info->dlpi_name[0] != '\0')
    dlopen(info->dlpi_name, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
  return 0;
}
#endif

void PinGlLibraries() {
#ifdef CAROUSEL_SANITIZE_BUILD
  dl_iterate_phdr(PinLoaded, nullptr);
#endif
}

}  // namespace

bool StudioApp::InitWindow() {
  glfwSetErrorCallback(OnGlfwError);
  if (glfwInit() == GLFW_FALSE) {
    CAROUSEL_LOG_ERROR("carousel-studio: no display (is DISPLAY set? under CI: xvfb-run)");
    return false;
  }
  glfwWindowHint(GLFW_CONTEXT_VERSION_MAJOR, 3);
  glfwWindowHint(GLFW_CONTEXT_VERSION_MINOR, 3);
  glfwWindowHint(GLFW_OPENGL_PROFILE, GLFW_OPENGL_CORE_PROFILE);
  glfwWindowHint(GLFW_OPENGL_FORWARD_COMPAT, GLFW_TRUE);
  int width = args_.width, height = args_.height;
  if (args_.operator_mode) {
    // Full screen without decorations: the whole monitor is the operator's station.
    if (const GLFWvidmode* mode = glfwGetVideoMode(glfwGetPrimaryMonitor())) {
      width = mode->width;
      height = mode->height;
    }
    glfwWindowHint(GLFW_DECORATED, GLFW_FALSE);
  }
  window_ = glfwCreateWindow(width, height,
                             args_.operator_mode ? "Carousel: operator" : "Carousel Studio",
                             nullptr, nullptr);
  if (window_ == nullptr) {
    CAROUSEL_LOG_ERROR("carousel-studio: cannot open an OpenGL 3.3 window");
    glfwTerminate();
    return false;
  }
  if (args_.operator_mode) glfwSetWindowPos(window_, 0, 0);
  glfwMakeContextCurrent(window_);
  PinGlLibraries();
  glfwSwapInterval(0);  // paced by the loop (60 Hz), so frame times are the window's own
  IMGUI_CHECKVERSION();
  ImGui::CreateContext();
  ImGuiIO& io = ImGui::GetIO();
  io.IniFilename = nullptr;  // the layout is fixed; nothing to restore
  ImGui::StyleColorsDark();
  ImGuiStyle& style = ImGui::GetStyle();
  style.FrameRounding = 3.0f;
  style.Colors[ImGuiCol_PlotHistogram] = ImVec4(0.26f, 0.59f, 0.98f, 0.85f);  // progress bars
  if (args_.operator_mode) io.FontGlobalScale = 2.0f;
  ImGui_ImplGlfw_InitForOpenGL(window_, true);
  ImGui_ImplOpenGL3_Init("#version 330 core");
  renderer_ = std::make_unique<ModelRenderer>();
  std::string error;
  if (!renderer_->Init(&error)) {
    CAROUSEL_LOG_ERROR("carousel-studio: " << error);
    return false;
  }
  return true;
}

int StudioApp::Run() {
  if (!InitWindow()) return 2;
  Clock::time_point last_start = Clock::now();
  int input_frames = 0;  // frames still drawn at the full rate after an input event
  while (glfwWindowShouldClose(window_) == GLFW_FALSE && !quit_) {
    // The window draws only as often as what it shows changes: at 60 Hz while the user
    // interacts, 30 Hz while a session runs or something loads, 15 Hz with live view on, and
    // 4 Hz otherwise; an input event wakes it at once. The pipeline keeps the CPU.
    const bool busy = last_state_ == JobState::kRunning || model_loading_.valid() ||
                      held_out_loading_.valid() || !shots_pending_.empty() ||
                      (args_.autorun && !autorun_done_);
    double wait_s = busy ? 1.0 / 30.0 : 0.25;
    if (rig_.Status().state != RigMonitorStatus::State::kOff) wait_s = std::min(wait_s, 1.0 / 15.0);
    if (input_frames > 0) {
      std::this_thread::sleep_until(last_start + kFramePeriod);
      glfwPollEvents();
      --input_frames;
    } else {
      const Clock::time_point before = Clock::now();
      const Clock::time_point deadline = last_start + std::chrono::duration_cast<Clock::duration>(
                                                          std::chrono::duration<double>(wait_s));
      if (deadline > before)
        glfwWaitEventsTimeout(std::chrono::duration<double>(deadline - before).count());
      else
        glfwPollEvents();
      if (Clock::now() < deadline - std::chrono::milliseconds(1)) input_frames = 3;  // an event
    }
    const Clock::time_point start = Clock::now();
    last_start = start;
    Poll();
    Automate();
    ImGui_ImplOpenGL3_NewFrame();
    ImGui_ImplGlfw_NewFrame();
    ImGui::NewFrame();
    Frame();
    ImGui::Render();
    int fb_width = 0, fb_height = 0;
    glfwGetFramebufferSize(window_, &fb_width, &fb_height);
    glViewport(0, 0, fb_width, fb_height);
    glClearColor(0.1f, 0.1f, 0.11f, 1.0f);
    glClear(GL_COLOR_BUFFER_BIT);
    ImGui_ImplOpenGL3_RenderDrawData(ImGui::GetDrawData());

    // Screenshots of what was just drawn: at each stage change and at the autorun's end.
    const JobStatus job = controller_.Status();
    if (!args_.screenshot_dir.empty() && job.stage_changes != last_stage_changes_ && job.id > 0) {
      Screenshot(job.product + "-" + StageLabel(job));
    }
    last_stage_changes_ = job.stage_changes;
    for (const std::string& name : shots_pending_) Screenshot(name);
    shots_pending_.clear();
    if (autorun_waiting_model_ && model_frames_ >= 3) autorun_waiting_model_ = false;
    // The autorun is over once every product was pressed, the last session ended and its
    // model (or result) has been on screen for half a second.
    // With --autorun-choose-pose, an ambiguous pass's pose is chosen first (Automate).
    const bool pose_to_choose =
        args_.autorun_pose > 0 && pose_check_ != PoseCheck::kChosen && AmbiguousPass(job) > 0;
    if (args_.autorun && !autorun_done_ && !pose_to_choose &&
        autorun_next_ >= (args_.calibration ? 1 : args_.products.size()) &&
        !autorun_waiting_model_ && IdleFor(0.5)) {
      autorun_done_ = true;
      Screenshot("final");
      if (args_.quit_when_done) quit_ = true;
    }
    glfwSwapBuffers(window_);
    // The frame time: how long the window was busy with this frame (input to swap), the time
    // it could not answer; the first two frames open the window (fonts, shaders).
    if (frame_log_.is_open() && frame_ > 1)
      frame_log_ << std::chrono::duration<double, std::milli>(Clock::now() - start).count() << '\n';
    ++frame_;
  }
  if (frame_log_.is_open()) frame_log_.flush();
  return failures_ ? 1 : 0;
}

void StudioApp::Screenshot(const std::string& name) {
  if (args_.screenshot_dir.empty()) return;
  int width = 0, height = 0;
  glfwGetFramebufferSize(window_, &width, &height);
  cv::Mat rgba(height, width, CV_8UC4);
  glPixelStorei(GL_PACK_ALIGNMENT, 4);
  glReadBuffer(GL_BACK);
  glReadPixels(0, 0, width, height, GL_RGBA, GL_UNSIGNED_BYTE, rgba.data);
  cv::Mat flipped, bgr;
  cv::flip(rgba, flipped, 0);
  cv::cvtColor(flipped, bgr, cv::COLOR_RGBA2BGR);
  std::string safe = name;
  for (char& c : safe)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) c = '_';
  char prefix[16];
  std::snprintf(prefix, sizeof(prefix), "%03d-", screenshots_++);
  const std::filesystem::path file = args_.screenshot_dir / (prefix + safe + ".png");
  if (!cv::imwrite(file.string(), bgr))
    CAROUSEL_LOG_ERROR("carousel-studio: cannot write the screenshot " << file.string());
}

void StudioApp::ForgetSessionView() {
  ClearThumbs();
  held_out_.reset();
  DeleteTexture(&held_out_photo_);
  DeleteTexture(&held_out_render_);
}

void StudioApp::ClearPosePictures() {
  for (GLuint& texture : pose_pictures_.textures) DeleteTexture(&texture);
  pose_pictures_ = {};
}

void StudioApp::LoadPosePictures(const std::filesystem::path& session, int pass) {
  ClearPosePictures();
  pose_pictures_.session = session;
  pose_pictures_.pass = pass;
  for (int pose = 1;; ++pose) {
    const std::filesystem::path file =
        session / "recon" /
        ("pass" + std::to_string(pass) + "_pose" + std::to_string(pose) + ".jpg");
    if (!std::filesystem::is_regular_file(file)) break;
    try {
      const cv::Mat bgr = ReadImage(file);
      cv::Mat rgba;
      cv::cvtColor(bgr, rgba, cv::COLOR_BGR2RGBA);
      pose_pictures_.textures.push_back(UploadTexture(rgba, false));
      pose_pictures_.sizes.push_back(rgba.size());
    } catch (const Error& e) {
      pose_pictures_.error = e.what();
      break;
    }
  }
}

void StudioApp::ChoosePose(const std::filesystem::path& session, int pass, int pose) {
  studio::ProcessOptions process;
  process.reconstruct = args_.run.reconstruct;
  process.reconstruct.choose_pose = std::to_string(pass) + ":" + std::to_string(pose);
  process.texture = args_.run.texture;
  process.publish = args_.run.publish;
  process.publish_model = args_.run.publish_model;
  start_error_.clear();
  idle_frames_ = 0;
  idle_since_ = Clock::now();
  try {
    rig_.Disconnect();
    controller_.StartReprocess(session, process);
  } catch (const Error& e) {
    start_error_ = e.what();
  }
}

void StudioApp::ClearThumbs() {
  for (Thumb& t : thumbs_) {
    DeleteTexture(&t.photo);
    DeleteTexture(&t.mask);
  }
  thumbs_.clear();
}

StudioApp::LoadedSession StudioApp::LoadSession(const std::filesystem::path& folder) {
  LoadedSession out;
  out.folder = folder;
  try {
    const studio::Session session = studio::ReadSession(folder);
    out.stage_seconds = session.stage_seconds;
    std::error_code ec;
    if (std::filesystem::is_regular_file(folder / "model" / "report.json", ec))
      out.report = ParseJsonFile(folder / "model" / "report.json");
    out.held_out_views = HeldOutViews(folder);
    if (std::filesystem::is_regular_file(folder / "model" / "model.glb", ec))
      out.mesh = LoadSessionModel(folder);
  } catch (const std::exception& e) {  // shown in the window: a loader never ends it
    out.error = e.what();
  }
  return out;
}

void StudioApp::OpenSession(const std::filesystem::path& session) {
  if (session != session_) {
    ForgetSessionView();
  }
  session_ = session;
  photos_.Watch(session);
  StartModelLoad(session);
}

void StudioApp::StartModelLoad(const std::filesystem::path& session) {
  model_session_ = session;
  model_loading_ = std::async(std::launch::async, [session] { return LoadSession(session); });
}

void StudioApp::StartHeldOutLoad(int view) {
  held_out_error_.clear();
  const std::filesystem::path session = session_;
  held_out_loading_ = std::async(
      std::launch::async, [session, view] { return CompareHeldOutView(session, view, 1024); });
}

void StudioApp::Poll() {
  const JobStatus job = controller_.Status();
  if (job.id != last_job_id_) {
    // A new job: the panels follow its session (the pose pictures are its own).
    last_job_id_ = job.id;
    ClearPosePictures();
    if (job.session != session_) {
      ForgetSessionView();
      report_ = nlohmann::json();
      stage_seconds_.clear();
      held_out_views_.clear();
      model_error_.clear();
      renderer_->Upload(ModelMesh{});
      model_frames_ = 0;
    }
    session_ = job.session;
    photos_.Watch(session_);
    if (job.state == JobState::kRunning) select_tab_ = Tab::kPhotos;  // photos as they arrive
  }
  if (job.stage_changes != last_listed_changes_ && job.state == JobState::kRunning) {
    // The Sessions panel follows the running session's state.
    last_listed_changes_ = job.stage_changes;
    sessions_ = ListSessions(args_.run.out);
  }
  if (last_state_ == JobState::kRunning && job.state != JobState::kRunning) {
    // The job ended: show what it made, and what the sessions are now.
    sessions_ = ListSessions(args_.run.out);
    OpenSession(job.session);
    if (job.state == JobState::kSucceeded && !args_.operator_mode && !job.calibration) {
      select_tab_ = Tab::kModel;
      autorun_waiting_model_ = args_.autorun;
    }
    if (job.state != JobState::kSucceeded) failures_ = true;
    if (job.calibration && job.run && job.run->calibration &&
        !JudgeCalibration(*job.run->calibration).pass)
      failures_ = true;
    if (args_.operator_mode) {
      shots_pending_.push_back(job.product + "-result");  // once the verdict is drawn
      sku_.clear();                                       // ready for the next product's barcode
      focus_sku_ = true;
    }
    idle_frames_ = 0;
    idle_since_ = Clock::now();
  }
  last_state_ = job.state;
  // Frames since the last job ended (what the autorun waits on), as Poll has seen it.
  if (job.state == JobState::kRunning) {
    idle_frames_ = 0;
    idle_since_ = Clock::now();
  } else {
    ++idle_frames_;
  }

  if (Ready(model_loading_)) {
    LoadedSession loaded = model_loading_.get();
    if (loaded.folder == session_) {
      report_ = std::move(loaded.report);
      stage_seconds_ = std::move(loaded.stage_seconds);
      held_out_views_ = std::move(loaded.held_out_views);
      held_out_index_ = 0;
      model_error_ = loaded.error;
      if (!loaded.mesh) autorun_waiting_model_ = false;  // nothing to wait for
      if (loaded.mesh) {
        renderer_->Upload(*loaded.mesh);
        camera_.Frame(loaded.mesh->center, loaded.mesh->radius);
        model_charts_ = loaded.mesh->charts;
        model_triangles_ = loaded.mesh->triangles;
        density_[0] = loaded.mesh->density_p10;
        density_[1] = loaded.mesh->density_median;
        density_[2] = loaded.mesh->density_p90;
        model_frames_ = 0;
      }
      if (!held_out_views_.empty()) StartHeldOutLoad(held_out_views_.front());
    }
  }
  if (Ready(held_out_loading_)) {
    try {
      HeldOutComparison comparison = held_out_loading_.get();
      DeleteTexture(&held_out_photo_);
      DeleteTexture(&held_out_render_);
      held_out_photo_ = UploadTexture(comparison.photo_rgba, false);
      held_out_render_ = UploadTexture(comparison.render_rgba, false);
      held_out_ = std::move(comparison);
    } catch (const std::exception& e) {
      held_out_error_ = e.what();
    }
  }
  if (const cv::Mat frame = rig_.TakeFrame(&live_frame_seen_); !frame.empty()) {
    if (live_view_ == 0 || frame.size() != live_size_) {
      DeleteTexture(&live_view_);
      live_view_ = UploadTexture(frame, false);
      live_size_ = frame.size();
    } else {
      glBindTexture(GL_TEXTURE_2D, live_view_);
      glTexSubImage2D(GL_TEXTURE_2D, 0, 0, 0, frame.cols, frame.rows, GL_RGBA, GL_UNSIGNED_BYTE,
                      frame.isContinuous() ? frame.data : frame.clone().data);
      glBindTexture(GL_TEXTURE_2D, 0);
    }
  }
  for (PhotoThumb& ready : photos_.TakeReady()) {
    auto it = std::find_if(thumbs_.begin(), thumbs_.end(),
                           [&ready](const Thumb& t) { return t.info.stem == ready.stem; });
    if (it == thumbs_.end()) {
      thumbs_.push_back({});
      it = thumbs_.end() - 1;
    }
    DeleteTexture(&it->photo);
    DeleteTexture(&it->mask);
    it->photo = UploadTexture(ready.rgba, false);
    it->mask = UploadTexture(ready.mask_rgba, false);
    it->info = std::move(ready);
    it->info.rgba.release();
    it->info.mask_rgba.release();
  }
  std::sort(thumbs_.begin(), thumbs_.end(), [](const Thumb& a, const Thumb& b) {
    return std::tie(a.info.pass, a.info.stop, a.info.camera) <
           std::tie(b.info.pass, b.info.stop, b.info.camera);
  });
}

studio::RigRequest StudioApp::RigRequestNow() const {
  studio::RigRequest request;
  request.sim = args_.run.sim;
  request.hardware = args_.run.hardware;
  return request;
}

bool StudioApp::IdleFor(double seconds) const {
  return last_state_ != JobState::kRunning && idle_frames_ >= 3 &&
         Clock::now() - idle_since_ >= std::chrono::duration<double>(seconds);
}

void StudioApp::PressButton(const std::string& sku) {
  start_error_.clear();
  idle_frames_ = 0;
  idle_since_ = Clock::now();
  rig_.Disconnect();  // the session opens the same devices
  try {
    studio::RunOptions options = args_.run;
    options.product = sku;
    controller_.StartRun(options);
  } catch (const Error& e) {
    start_error_ = e.what();
  }
}

void StudioApp::StartCalibration() {
  start_error_.clear();
  idle_frames_ = 0;
  idle_since_ = Clock::now();
  rig_.Disconnect();
  try {
    studio::RunOptions options = args_.run;
    // A new calibration session each time: rig-calibration-20261206-091500.
    std::string stamp = studio::NowUtc();
    stamp.erase(std::remove_if(stamp.begin(), stamp.end(),
                               [](char c) { return c == '-' || c == ':' || c == 'Z'; }),
                stamp.end());
    std::replace(stamp.begin(), stamp.end(), 'T', '-');
    options.product = "rig-calibration-" + stamp;
    options.calibration = args_.plan;
    options.calibration_file.clear();
    options.texture.grouping.exclude_views.clear();
    controller_.StartRun(options);
  } catch (const Error& e) {
    start_error_ = e.what();
  }
}

void StudioApp::Automate() {
  const std::size_t presses = args_.calibration ? 1 : args_.products.size();
  // The photographer's choice of an ambiguous pass's pose: the pictures on screen a moment
  // (a screenshot), then the button under picture K.
  if (args_.autorun && args_.autorun_pose > 0 && autorun_next_ >= presses &&
      pose_check_ != PoseCheck::kChosen && last_state_ != JobState::kRunning &&
      !autorun_waiting_model_ && IdleFor(0.5)) {
    const JobStatus job = controller_.Status();
    if (const int pass = AmbiguousPass(job); pass > 0) {
      if (pose_check_ == PoseCheck::kNone) {
        shots_pending_.push_back("choose-pose");
        pose_check_ = PoseCheck::kShown;
        return;  // the screenshot is taken at the end of this frame; the choice follows
      }
      pose_check_ = PoseCheck::kChosen;
      ChoosePose(job.session, pass, args_.autorun_pose);
      if (!start_error_.empty()) {
        failures_ = true;
        if (args_.quit_when_done) quit_ = true;
      }
      return;
    }
  }
  if (!args_.autorun || autorun_next_ >= presses) return;
  if (last_state_ == JobState::kRunning || autorun_waiting_model_) return;
  // The first press once the window is up; the next once the last result has shown a while.
  if (frame_ < 5 || (autorun_next_ > 0 && !IdleFor(0.5))) return;
  if (args_.run.hardware && autorun_next_ == 0 && live_check_ != LiveCheck::kShown) {
    // The hardware path's demo: the live view first, then the button.
    if (live_check_ == LiveCheck::kNone) {
      live_check_ = LiveCheck::kWaiting;
      live_check_start_ = Clock::now();
      open_rig_panel_ = true;
      rig_.Connect(RigRequestNow());
      return;
    }
    const RigMonitorStatus rig = rig_.Status();
    const bool timed_out = Clock::now() - live_check_start_ > std::chrono::seconds(60);
    if (rig.state != RigMonitorStatus::State::kFailed && rig.frames < 3 && !timed_out) return;
    shots_pending_.push_back("live-view");
    live_check_ = LiveCheck::kShown;
    return;  // the screenshot is taken at the end of this frame; the press follows
  }
  if (args_.calibration) {
    ++autorun_next_;
    StartCalibration();
    if (!start_error_.empty()) {
      failures_ = true;
      if (args_.quit_when_done) quit_ = true;
    }
    return;
  }
  const std::string sku = args_.products[autorun_next_++];
  sku_ = sku;
  PressButton(sku);
  if (!start_error_.empty()) {
    failures_ = true;
    if (args_.quit_when_done) quit_ = true;
    return;
  }
}

}  // namespace carousel::gui
