// carousel-studio's window: GLFW + Dear ImGui + OpenGL 3.3 panels over the controller
// (controller.h). Everything here draws or forwards; the decisions are the controller's.
// Private to gui/.
#pragma once

#include <chrono>
#include <filesystem>
#include <fstream>
#include <future>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "carousel/gui/controller.h"
#include "carousel/gui/model_view.h"
#include "carousel/gui/rig_monitor.h"
#include "carousel/gui/session_browser.h"
#include "carousel/gui/studio_args.h"
#include "model_renderer.h"
#include "option_widgets.h"

struct GLFWwindow;

namespace carousel::gui {

class StudioApp {
 public:
  explicit StudioApp(StudioArgs args);
  ~StudioApp();
  StudioApp(const StudioApp&) = delete;
  StudioApp& operator=(const StudioApp&) = delete;
  // Opens the window and runs until it is closed (or the autorun ends with
  // --quit-when-done). Returns the exit code: 0, or 1 when a session of the autorun failed.
  int Run();

 private:
  struct Thumb {
    PhotoThumb info;
    GLuint photo = 0, mask = 0;
  };
  enum class Tab { kModel, kPhotos, kReport };

  bool InitWindow();
  void Frame();
  void Poll();  // job end, loaded model, thumbnails
  void Automate();
  void PressButton(const std::string& sku);
  void StartCalibration();
  void OpenSession(const std::filesystem::path& session);
  void StartModelLoad(const std::filesystem::path& session);
  void StartHeldOutLoad(int view);
  void Screenshot(const std::string& name);
  void ClearThumbs();
  void ForgetSessionView();  // thumbnails and the held-out comparison of the last session

  void DrawStudio();
  void DrawOperator();
  void DrawSessionPanel(const JobStatus& job, float height);
  void DrawPlanPanel();
  void DrawRigPanel();
  void DrawCalibrationPanel(const JobStatus& job);
  void DrawSessionsPanel();
  void DrawStageBars(const JobStatus& job, float bar_height);
  void DrawJobMessage(const JobStatus& job);
  void DrawModelTab();
  void DrawPhotosTab();
  void DrawReportTab();
  // An ambiguous pass's pose, chosen by the photographer: its pictures (recon/pass<N>_pose<K>
  // .jpg) with a button under each, which reprocesses the session with that pose.
  void DrawPoseChoice(const std::filesystem::path& session, int pass);
  void LoadPosePictures(const std::filesystem::path& session, int pass);
  void ClearPosePictures();
  void ChoosePose(const std::filesystem::path& session, int pass, int pose);

  StudioArgs args_;
  GLFWwindow* window_ = nullptr;
  StudioController controller_;
  PhotoWatcher photos_;
  std::unique_ptr<ModelRenderer> renderer_;
  OrbitCamera camera_;
  ModelMode mode_ = ModelMode::kTextured;

  std::filesystem::path session_;  // the session the panels show
  // What the Model and Report panels show of a session, read on a background thread.
  struct LoadedSession {
    std::filesystem::path folder;
    std::optional<ModelMesh> mesh;  // none: the session has no model yet
    nlohmann::json report;          // model/report.json (null when missing)
    std::map<std::string, double> stage_seconds;
    std::vector<int> held_out_views;
    std::string error;  // why the model could not be read (names the file)
  };
  static LoadedSession LoadSession(const std::filesystem::path& folder);
  std::future<LoadedSession> model_loading_;
  std::filesystem::path model_session_;
  std::string model_error_;
  int model_charts_ = 0, model_triangles_ = 0;
  double density_[3] = {0, 0, 0};
  int model_frames_ = 0;  // frames drawn with the current model
  nlohmann::json report_;
  std::map<std::string, double> stage_seconds_;
  std::vector<int> held_out_views_;
  int held_out_index_ = 0;
  std::future<HeldOutComparison> held_out_loading_;
  std::optional<HeldOutComparison> held_out_;
  GLuint held_out_photo_ = 0, held_out_render_ = 0;
  float split_ = 0.5f;
  std::string held_out_error_;
  std::vector<Thumb> thumbs_;
  bool show_masks_ = true;
  std::vector<SessionSummary> sessions_;
  RigMonitor rig_;
  std::unique_ptr<UsbEvents> usb_;  // made when the Rig panel is first opened
  GLuint live_view_ = 0;
  int live_frame_seen_ = 0;
  cv::Size live_size_;
  bool open_rig_panel_ = false;
  std::map<std::string, std::string> setting_edit_;  // camera setting being typed
  studio::RigRequest RigRequestNow() const;

  std::string sku_;
  std::string out_text_;     // the sessions folder as typed
  std::string start_error_;  // a press refused (no SKU, busy, bad setting)
  OptionEditState plan_edit_, calibration_edit_;
  std::string calibration_notice_;  // "sessions now use ..."
  bool show_advanced_ = false;
  std::optional<Tab> select_tab_;
  bool focus_sku_ = true;

  int last_job_id_ = 0;
  int last_stage_changes_ = -1;
  int last_listed_changes_ = -1;
  JobState last_state_ = JobState::kIdle;
  int screenshots_ = 0;
  std::vector<std::string> shots_pending_;  // taken after the frame is drawn
  bool failures_ = false;
  // The autorun: products pressed so far, frames since the last session ended.
  std::size_t autorun_next_ = 0;
  int frame_ = 0, idle_frames_ = 0;
  std::chrono::steady_clock::time_point idle_since_{};
  bool IdleFor(double seconds) const;  // no job for that long (and a few frames drawn)
  bool autorun_waiting_model_ = false;
  // Hardware mode: the autorun first shows the live view, then presses.
  enum class LiveCheck { kNone, kWaiting, kShown } live_check_ = LiveCheck::kNone;
  std::chrono::steady_clock::time_point live_check_start_{};
  bool autorun_done_ = false;
  // --autorun-choose-pose: the pictures shown (a screenshot), then the pose chosen.
  enum class PoseCheck { kNone, kShown, kChosen } pose_check_ = PoseCheck::kNone;
  struct PosePictures {
    std::filesystem::path session;
    int pass = 0;  // 1-based, as the pictures' names
    std::vector<GLuint> textures;
    std::vector<cv::Size> sizes;
    std::string error;  // a picture that could not be read (names it)
  } pose_pictures_;
  bool quit_ = false;
  std::ofstream frame_log_;
};

}  // namespace carousel::gui
