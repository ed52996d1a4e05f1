// The panels of carousel-studio (studio_app.h): immediate-mode drawing of the controller's
// snapshot and of what the background loaders made ready.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <cstdio>

#include <imgui.h>
#include <imgui_stdlib.h>

#include "carousel/core/error.h"
#include "carousel/studio/calibrate_session.h"
#include "carousel/studio/sim_capture.h"
#include "studio_app.h"

namespace carousel::gui {
namespace {

constexpr float kLeftWidth = 440.0f;
// Constants, named as such; ImVec4 has no constexpr constructor, which the naming check needs.
const ImVec4 kGreen(0.25f, 0.75f, 0.35f, 1.0f);  // NOLINT(readability-identifier-naming)
const ImVec4 kRed(0.9f, 0.3f, 0.3f, 1.0f);       // NOLINT(readability-identifier-naming)
const ImVec4 kDim(0.6f, 0.6f, 0.65f, 1.0f);      // NOLINT(readability-identifier-naming)

std::string Duration(double seconds) {
  char text[32];
  if (seconds < 10.0) {
    std::snprintf(text, sizeof(text), "%.1f s", seconds);
  } else if (seconds < 60.0) {
    std::snprintf(text, sizeof(text), "%.0f s", seconds);
  } else {
    std::snprintf(text, sizeof(text), "%d min %02d s", static_cast<int>(seconds) / 60,
                  static_cast<int>(seconds) % 60);
  }
  return text;
}

ImTextureID TextureId(GLuint texture) {
  // ImGui's texture handle is pointer-sized; OpenGL names its textures with integers.
  return reinterpret_cast<ImTextureID>(  // NOLINT(performance-no-int-to-ptr)
      static_cast<std::intptr_t>(texture));
}

// An image fitted into `avail` keeping its aspect ratio.
ImVec2 Fit(float width, float height, ImVec2 avail) {
  const float scale = std::min(avail.x / std::max(width, 1.0f), avail.y / std::max(height, 1.0f));
  return ImVec2(width * scale, height * scale);
}

}  // namespace

void StudioApp::Frame() {
  if (args_.operator_mode) {
    DrawOperator();
  } else {
    DrawStudio();
  }
}

void StudioApp::DrawStageBars(const JobStatus& job, float bar_height) {
  for (int i = 0; i < kPipelineStages; ++i) {
    const StageBar& bar = job.bars[i];
    const char* name = PipelineStageName(static_cast<PipelineStage>(i));
    std::string overlay;
    switch (bar.state) {
      case StageBar::State::kWaiting:
        overlay = std::string(name) + ": waiting";
        break;
      case StageBar::State::kRunning:
        overlay = bar.step + " " + std::to_string(static_cast<int>(bar.fraction * 100.0)) + " %";
        if (bar.seconds_left >= 0.0) overlay += ", " + Duration(bar.seconds_left) + " left";
        break;
      case StageBar::State::kDone:
        overlay = std::string(name) + ": done";
        if (bar.seconds > 0.0) overlay += " in " + Duration(bar.seconds);
        break;
    }
    ImGui::ProgressBar(static_cast<float>(bar.fraction), ImVec2(-1.0f, bar_height),
                       overlay.c_str());
  }
}

void StudioApp::DrawJobMessage(const JobStatus& job) {
  if (!start_error_.empty()) ImGui::TextColored(kRed, "%s", start_error_.c_str());
  switch (job.state) {
    case JobState::kIdle:
      break;
    case JobState::kRunning:
      ImGui::Text("%s: %s, %s", job.product.c_str(), job.cancelling ? "cancelling" : "running",
                  Duration(job.seconds).c_str());
      break;
    case JobState::kSucceeded: {
      ImGui::TextColored(kGreen, "%s: done in %s", job.product.c_str(),
                         Duration(job.seconds).c_str());
      // The later passes (the product laid down another way): registered, or left out and why.
      const std::optional<studio::ReconstructResult>& reconstructed =
          job.run       ? job.run->reconstruct
          : job.process ? job.process->reconstruct
                        : std::optional<studio::ReconstructResult>();
      if (reconstructed) {
        ImGui::PushTextWrapPos(0.0f);
        for (const studio::PassOutcome& pass : reconstructed->passes) {
          ImGui::TextColored(pass.status == "registered" ? kGreen : kRed, "%s%s",
                             pass.status == "registered" ? "" : "not used: ", pass.note.c_str());
          if (pass.status == "ambiguous") DrawPoseChoice(job.session, pass.pass + 1);
        }
        ImGui::PopTextWrapPos();
      }
      break;
    }
    case JobState::kFailed:
      ImGui::PushTextWrapPos(0.0f);
      ImGui::TextColored(kRed, "%s failed: %s", job.product.c_str(), job.error.c_str());
      ImGui::TextUnformatted(job.advice.c_str());
      ImGui::PopTextWrapPos();
      break;
    case JobState::kCancelled:
      ImGui::PushTextWrapPos(0.0f);
      ImGui::TextColored(kDim, "%s cancelled. %s", job.product.c_str(), job.advice.c_str());
      ImGui::PopTextWrapPos();
      break;
  }
}

void StudioApp::DrawPoseChoice(const std::filesystem::path& session, int pass) {
  if (pose_pictures_.session != session || pose_pictures_.pass != pass)
    LoadPosePictures(session, pass);
  if (!pose_pictures_.error.empty()) ImGui::TextColored(kRed, "%s", pose_pictures_.error.c_str());
  if (pose_pictures_.textures.empty()) return;
  ImGui::Text(
      "Choose pass %d's pose: the picture whose two halves look alike (pass 1's photo, "
      "pass %d's colours laid on the shape at that pose).",
      pass, pass);
  const float thumb = 128.0f;
  const float right_edge = ImGui::GetWindowPos().x + ImGui::GetWindowContentRegionMax().x;
  for (std::size_t k = 0; k < pose_pictures_.textures.size(); ++k) {
    const cv::Size size = pose_pictures_.sizes[k];
    const ImVec2 shown =
        Fit(static_cast<float>(size.width), static_cast<float>(size.height), ImVec2(thumb, thumb));
    ImGui::PushID(static_cast<int>(k));
    ImGui::BeginGroup();
    const bool chosen = ImGui::ImageButton(TextureId(pose_pictures_.textures[k]), shown);
    if (ImGui::IsItemHovered()) {
      ImGui::BeginTooltip();
      ImGui::Image(TextureId(pose_pictures_.textures[k]),
                   Fit(static_cast<float>(size.width), static_cast<float>(size.height),
                       ImVec2(480.0f, 480.0f)));
      ImGui::EndTooltip();
    }
    ImGui::Text("pose %zu", k + 1);
    ImGui::EndGroup();
    ImGui::PopID();
    if (chosen) ChoosePose(session, pass, static_cast<int>(k) + 1);
    // The next picture beside this one while it fits, else below.
    const float next_right = ImGui::GetItemRectMax().x + ImGui::GetStyle().ItemSpacing.x + thumb +
                             2.0f * ImGui::GetStyle().FramePadding.x;
    if (k + 1 < pose_pictures_.textures.size() && next_right < right_edge) ImGui::SameLine();
  }
}

void StudioApp::DrawSessionPanel(const JobStatus& job, float) {
  const bool busy = job.state == JobState::kRunning;
  ImGui::SetNextItemWidth(-110.0f);
  if (focus_sku_ && !busy) {
    ImGui::SetKeyboardFocusHere();
    focus_sku_ = false;
  }
  const bool enter = ImGui::InputTextWithHint("SKU", "product SKU (scan or type)", &sku_,
                                              ImGuiInputTextFlags_EnterReturnsTrue);
  if (busy) ImGui::BeginDisabled();
  if (ImGui::Button("Capture and build", ImVec2(-1.0f, 44.0f)) || (enter && !busy))
    PressButton(sku_);
  if (busy) ImGui::EndDisabled();
  if (busy) {
    if (ImGui::Button(job.cancelling ? "Cancelling..." : "Cancel", ImVec2(-1.0f, 0.0f)))
      controller_.Cancel();
  } else if (job.resumable) {
    if (ImGui::Button("Resume", ImVec2(-1.0f, 0.0f))) {
      try {
        rig_.Disconnect();
        controller_.StartResume(job.session);
      } catch (const Error& e) {
        start_error_ = e.what();
      }
    }
  }
  if (job.board_prompt && job.board_prompt->product) {
    ImGui::TextColored(kGreen, "Pass %d of %d: %s", job.board_prompt->index + 1,
                       job.board_prompt->placements,
                       job.board_prompt->index == 0
                           ? "stand the product as it stood in the first pass"
                           : "lay the product down another way (on its side, upside down), "
                             "near the plate's centre");
    if (ImGui::Button("The product lies so", ImVec2(-1.0f, 0.0f))) controller_.ConfirmBoardPlaced();
  } else if (job.board_prompt) {
    ImGui::TextColored(kGreen, "Board placement %d of %d: stand the board on the turntable",
                       job.board_prompt->index + 1, job.board_prompt->placements);
    if (ImGui::Button("The board is in place", ImVec2(-1.0f, 0.0f)))
      controller_.ConfirmBoardPlaced();
  }
  DrawStageBars(job, 0.0f);
  DrawJobMessage(job);
}

void StudioApp::DrawPlanPanel() {
  const bool busy = controller_.Busy();
  ImGui::Checkbox("advanced settings", &show_advanced_);
  if (args_.run.hardware) {
    // The rig file's plan, for the sessions this window starts (the file is not rewritten).
    ImGui::TextColored(kDim, "the plan of %s", args_.rig.string().c_str());
    OptionWidgets("capture", studio::CapturePlan::Fields(), args_.run.hardware->capture, plan_edit_,
                  show_advanced_, busy);
    std::string& backdrop = args_.run.hardware->backdrop;
    if (busy) ImGui::BeginDisabled();
    if (ImGui::BeginCombo("backdrop", backdrop.c_str())) {
      for (const char* method : {"key", "difference"})
        if (ImGui::Selectable(method, backdrop == method)) backdrop = method;
      ImGui::EndCombo();
    }
    if (ImGui::IsItemHovered())
      ImGui::SetTooltip(
          "silhouettes by keying against the backdrop, or by differencing against "
          "photos of the empty turntable (the rig file's backgrounds)");
    if (busy) ImGui::EndDisabled();
  } else {
    static const OptionTable<studio::SimCaptureOptions> sim =
        studio::SimCaptureOptions::Fields().Only(studio::RunSimFieldNames());
    OptionWidgets("sim", sim, args_.run.sim, plan_edit_, show_advanced_, busy);
  }
  static const OptionTable<studio::TextureSessionOptions> texture =
      studio::TextureSessionOptions::Fields().Only({"exclude-views"});
  OptionWidgets("texture", texture, args_.run.texture, plan_edit_, show_advanced_, busy);
  if (ImGui::TreeNode("publish")) {
    OptionWidgets("publish", studio::PublishSessionOptions::Fields(), args_.run.publish, plan_edit_,
                  show_advanced_, busy);
    ImGui::TreePop();
  }
  ImGui::InputText("sessions folder", &out_text_);
  if (ImGui::IsItemDeactivatedAfterEdit()) {
    args_.run.out = out_text_;
    sessions_ = ListSessions(args_.run.out);
  }
}

void StudioApp::DrawRigPanel() {
  const bool busy = controller_.Busy();
  if (args_.run.hardware) {
    const studio::RigConfig& rig = *args_.run.hardware;
    ImGui::TextWrapped("rig file %s: turntable on %s, %zu camera(s)", args_.rig.string().c_str(),
                       rig.turntable.port.c_str(), rig.cameras.size());
  } else {
    const studio::SimCaptureOptions& sim = args_.run.sim;
    ImGui::TextWrapped("simulated rig: %s, %zu camera(s), %d x %d px, %d stops per turn",
                       sim.scene.c_str(), sim.rig.elevations_deg.size(), sim.rig.width,
                       sim.rig.height, sim.stops);
  }
  if (!usb_) usb_ = std::make_unique<UsbEvents>();
  if (ImGui::TreeNode("USB devices")) {
    ImGui::TextColored(kDim, "watching: %s", usb_->Mode().c_str());
    const std::vector<std::string> lines = usb_->Lines();
    if (lines.empty()) ImGui::TextColored(kDim, "no camera or USB-serial adapter");
    for (const std::string& line : lines) ImGui::TextWrapped("%s", line.c_str());
    ImGui::TreePop();
  }
  const RigMonitorStatus status = rig_.Status();
  using State = RigMonitorStatus::State;
  const bool on = status.state == State::kOn || status.state == State::kConnecting;
  if (busy) ImGui::BeginDisabled();
  if (!on) {
    if (ImGui::Button("Connect (live view, turntable)")) rig_.Connect(RigRequestNow());
  } else if (ImGui::Button("Disconnect")) {
    rig_.Disconnect();
  }
  if (busy) ImGui::EndDisabled();
  if (busy) ImGui::TextColored(kDim, "the session holds the devices");
  if (status.state == State::kConnecting) ImGui::TextColored(kDim, "connecting...");
  if (!status.error.empty()) {
    ImGui::PushTextWrapPos(0.0f);
    ImGui::TextColored(kRed, "%s", status.error.c_str());
    ImGui::PopTextWrapPos();
  }
  if (status.state != State::kOn) return;
  ImGui::TextWrapped("turntable: %s", status.turntable.c_str());
  ImGui::Text("angle %.1f deg%s%s", status.angle_deg, status.moving ? ", moving" : "",
              status.homed ? ", homed" : ", not homed");
  if (!status.fault.empty()) ImGui::TextColored(kRed, "fault: %s", status.fault.c_str());
  if (ImGui::SmallButton("Identify")) rig_.Identify();
  ImGui::SameLine();
  if (ImGui::SmallButton("Home")) rig_.Home();
  for (const double step : {-22.5, -5.0, 5.0, 22.5}) {
    ImGui::SameLine();
    char label[16];
    std::snprintf(label, sizeof(label), "%+.1f", step);
    if (ImGui::SmallButton(label)) rig_.Jog(step);
  }
  for (std::size_t c = 0; c < status.cameras.size(); ++c) {
    ImGui::PushID(static_cast<int>(c));
    if (ImGui::RadioButton(status.cameras[c].name.c_str(),
                           status.live_camera == static_cast<int>(c)))
      rig_.SetLiveCamera(static_cast<int>(c));
    if (ImGui::TreeNode("settings")) {
      for (const auto& [name, value] : status.cameras[c].settings) {
        const std::string key = std::to_string(c) + "/" + name;
        auto it = setting_edit_.try_emplace(key, value).first;
        ImGui::SetNextItemWidth(140.0f);
        ImGui::InputText(name.c_str(), &it->second);
        if (ImGui::IsItemDeactivatedAfterEdit())
          rig_.SetCameraSetting(static_cast<int>(c), name, it->second);
        else if (!ImGui::IsItemActive())
          it->second = value;
      }
      ImGui::TreePop();
    }
    ImGui::PopID();
  }
  if (live_view_ != 0) {
    const ImVec2 size =
        Fit(static_cast<float>(live_size_.width), static_cast<float>(live_size_.height),
            ImVec2(ImGui::GetContentRegionAvail().x, 260.0f));
    ImGui::Image(TextureId(live_view_), size);
    ImGui::TextColored(kDim, "live view: %d frames, %.1f per second", status.frames, status.fps);
  }
}

void StudioApp::DrawCalibrationPanel(const JobStatus& job) {
  const bool busy = job.state == JobState::kRunning;
  const bool mine = job.calibration;
  ImGui::TextColored(mine && !busy ? kDim : ImVec4(1, 1, 1, 1),
                     "1. Stand the board on the turntable, facing the cameras");
  OptionWidgets("calibration", studio::CalibrationPlan::Fields(), args_.plan, calibration_edit_,
                show_advanced_, busy);
  if (busy) ImGui::BeginDisabled();
  if (ImGui::Button("Start calibration", ImVec2(-1.0f, 0.0f))) StartCalibration();
  if (busy) ImGui::EndDisabled();
  ImGui::TextColored(mine && busy ? ImVec4(1, 1, 1, 1) : kDim,
                     "2. The table turns with the board on it, once per placement");
  if (mine && job.board_prompt) {
    ImGui::TextColored(
        kGreen, "Placement %d of %d: %s", job.board_prompt->index + 1, job.board_prompt->placements,
        job.board_prompt->index == 0 ? "stand the board on the turntable"
                                     : "lean the board differently without moving the cameras");
    if (ImGui::Button("The board is in place", ImVec2(-1.0f, 0.0f)))
      controller_.ConfirmBoardPlaced();
  }
  if (mine && busy) DrawStageBars(job, 0.0f);
  ImGui::TextColored(mine && !busy ? ImVec4(1, 1, 1, 1) : kDim, "3. The result");
  if (!mine || busy) return;
  if (job.state != JobState::kSucceeded || !job.run || !job.run->calibration) {
    DrawJobMessage(job);
    return;
  }
  const studio::CalibrateSessionResult& result = *job.run->calibration;
  const CalibrationVerdict verdict = JudgeCalibration(result);
  ImGui::PushStyleColor(ImGuiCol_Button, verdict.pass ? kGreen : kRed);
  ImGui::PushStyleColor(ImGuiCol_ButtonHovered, verdict.pass ? kGreen : kRed);
  ImGui::PushStyleColor(ImGuiCol_ButtonActive, verdict.pass ? kGreen : kRed);
  ImGui::Button(verdict.pass ? "PASS: the rig is calibrated" : "FAIL: calibrate again",
                ImVec2(-1.0f, 48.0f));
  ImGui::PopStyleColor(3);
  ImGui::PushTextWrapPos(0.0f);
  for (const std::string& reason : verdict.reasons) ImGui::TextColored(kRed, "%s", reason.c_str());
  for (const std::string& line : verdict.lines) {
    ImGui::Bullet();
    ImGui::TextWrapped("%s", line.c_str());
  }
  ImGui::TextColored(kDim, "%s", result.file.string().c_str());
  ImGui::PopTextWrapPos();
  if (verdict.pass && ImGui::Button("Use it for the next sessions", ImVec2(-1.0f, 0.0f))) {
    args_.run.calibration_file = result.file;
    calibration_notice_ = "sessions now take their cameras from " + result.file.string();
  }
  if (!calibration_notice_.empty()) ImGui::TextColored(kGreen, "%s", calibration_notice_.c_str());
}

void StudioApp::DrawSessionsPanel() {
  const bool busy = controller_.Busy();
  if (ImGui::Button("Refresh")) sessions_ = ListSessions(args_.run.out);
  ImGui::SameLine();
  ImGui::TextColored(kDim, "%s", args_.run.out.string().c_str());
  if (!ImGui::BeginTable("sessions", 4,
                         ImGuiTableFlags_RowBg | ImGuiTableFlags_BordersInnerH |
                             ImGuiTableFlags_SizingStretchProp))
    return;
  ImGui::TableSetupColumn("session");
  ImGui::TableSetupColumn("state");
  ImGui::TableSetupColumn("photos");
  ImGui::TableSetupColumn("");
  ImGui::TableHeadersRow();
  for (const SessionSummary& s : sessions_) {
    ImGui::PushID(s.folder.string().c_str());
    ImGui::TableNextRow();
    ImGui::TableNextColumn();
    const bool shown = s.folder == session_;
    if (ImGui::Selectable(s.folder.filename().string().c_str(), shown, ImGuiSelectableFlags_None))
      OpenSession(s.folder);
    if (!s.problem.empty() && ImGui::IsItemHovered()) ImGui::SetTooltip("%s", s.problem.c_str());
    ImGui::TableNextColumn();
    ImGui::TextColored(s.state == "complete" ? kGreen : (s.state == "unreadable" ? kRed : kDim),
                       "%s", s.state.c_str());
    ImGui::TableNextColumn();
    ImGui::Text("%d", s.photos);
    ImGui::TableNextColumn();
    if (busy) ImGui::BeginDisabled();
    if (s.resumable && s.state != "complete" && s.state != "calibrated" &&
        ImGui::SmallButton("Resume")) {
      try {
        rig_.Disconnect();
        controller_.StartResume(s.folder);
      } catch (const Error& e) {
        start_error_ = e.what();
      }
    }
    if (s.state != "unreadable" && s.state != "capturing" && !s.calibration) {
      ImGui::SameLine();
      if (ImGui::SmallButton("Reprocess")) {
        try {
          studio::ProcessOptions process;
          process.publish = args_.run.publish;
          process.publish_model = args_.run.publish_model;
          process.texture = args_.run.texture;
          process.force = true;
          rig_.Disconnect();
          controller_.StartReprocess(s.folder, process);
        } catch (const Error& e) {
          start_error_ = e.what();
        }
      }
    }
    if (busy) ImGui::EndDisabled();
    ImGui::PopID();
  }
  ImGui::EndTable();
}

void StudioApp::DrawStudio() {
  const ImGuiViewport* viewport = ImGui::GetMainViewport();
  const ImVec2 size = viewport->WorkSize;
  const ImGuiWindowFlags fixed = ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoResize |
                                 ImGuiWindowFlags_NoCollapse | ImGuiWindowFlags_NoSavedSettings;
  const JobStatus job = controller_.Status();

  ImGui::SetNextWindowPos(viewport->WorkPos);
  ImGui::SetNextWindowSize(ImVec2(kLeftWidth, size.y));
  ImGui::Begin("Carousel Studio", nullptr, fixed);
  if (ImGui::CollapsingHeader("Session", ImGuiTreeNodeFlags_DefaultOpen))
    DrawSessionPanel(job, size.y);
  if (ImGui::CollapsingHeader("Capture plan")) DrawPlanPanel();
  if (open_rig_panel_) {
    ImGui::SetNextItemOpen(true);
    open_rig_panel_ = false;
  }
  if (ImGui::CollapsingHeader("Rig")) DrawRigPanel();
  if (args_.calibration || job.calibration) ImGui::SetNextItemOpen(true, ImGuiCond_Once);
  if (ImGui::CollapsingHeader("Calibration")) DrawCalibrationPanel(job);
  if (ImGui::CollapsingHeader("Sessions", ImGuiTreeNodeFlags_DefaultOpen)) DrawSessionsPanel();
  ImGui::End();

  ImGui::SetNextWindowPos(ImVec2(viewport->WorkPos.x + kLeftWidth, viewport->WorkPos.y));
  ImGui::SetNextWindowSize(ImVec2(size.x - kLeftWidth, size.y));
  ImGui::Begin("##views", nullptr, fixed | ImGuiWindowFlags_NoTitleBar);
  if (!session_.empty()) ImGui::TextColored(kDim, "session %s", session_.string().c_str());
  if (ImGui::BeginTabBar("views")) {
    const auto flags = [this](Tab tab) {
      return select_tab_ == tab ? ImGuiTabItemFlags_SetSelected : ImGuiTabItemFlags_None;
    };
    if (ImGui::BeginTabItem("Model", nullptr, flags(Tab::kModel))) {
      DrawModelTab();
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Photos", nullptr, flags(Tab::kPhotos))) {
      DrawPhotosTab();
      ImGui::EndTabItem();
    }
    if (ImGui::BeginTabItem("Report", nullptr, flags(Tab::kReport))) {
      DrawReportTab();
      ImGui::EndTabItem();
    }
    select_tab_.reset();
    ImGui::EndTabBar();
  }
  ImGui::End();
}

void StudioApp::DrawModelTab() {
  for (int m = 0; m < kModelModes; ++m) {
    if (m > 0) ImGui::SameLine();
    if (ImGui::RadioButton(ModelModeName(static_cast<ModelMode>(m)),
                           mode_ == static_cast<ModelMode>(m)))
      mode_ = static_cast<ModelMode>(m);
  }
  if (renderer_->has_model()) {
    ImGui::SameLine();
    ImGui::TextColored(kDim, "  %d triangles, %d charts; drag: orbit, right-drag: pan, wheel: zoom",
                       model_triangles_, model_charts_);
    if (mode_ == ModelMode::kDensity) {
      ImGui::TextColored(kDim,
                         "texels per mm: blue %.1f (10th percentile), median %.1f, red %.1f "
                         "(90th)",
                         density_[0], density_[1], density_[2]);
    }
  }
  if (!model_error_.empty()) ImGui::TextColored(kRed, "%s", model_error_.c_str());
  ImVec2 avail = ImGui::GetContentRegionAvail();
  const bool compare = held_out_.has_value() && held_out_photo_ != 0;
  const float model_width = compare ? std::floor(avail.x * 0.58f) : avail.x;
  const int width = std::max(1, static_cast<int>(model_width));
  const int height = std::max(1, static_cast<int>(avail.y));
  if (!renderer_->has_model()) {
    ImGui::BeginChild("empty", ImVec2(model_width, avail.y));
    ImGui::TextColored(kDim, model_loading_.valid() ? "loading the model..."
                                                    : "no model yet: press Capture and build, "
                                                      "or open a session");
    ImGui::EndChild();
  } else {
    renderer_->Render(camera_, mode_, width, height);
    ImGui::Image(TextureId(renderer_->color_texture()),
                 ImVec2(static_cast<float>(width), static_cast<float>(height)), ImVec2(0, 1),
                 ImVec2(1, 0));
    ++model_frames_;
    if (ImGui::IsItemHovered()) {
      const ImGuiIO& io = ImGui::GetIO();
      if (ImGui::IsMouseDragging(ImGuiMouseButton_Left))
        camera_.Orbit(io.MouseDelta.x, io.MouseDelta.y);
      if (ImGui::IsMouseDragging(ImGuiMouseButton_Right) ||
          ImGui::IsMouseDragging(ImGuiMouseButton_Middle))
        camera_.Pan(io.MouseDelta.x, io.MouseDelta.y, static_cast<float>(height));
      if (io.MouseWheel != 0.0f) camera_.Zoom(io.MouseWheel);
    }
  }
  if (!compare) {
    if (!held_out_error_.empty()) ImGui::TextColored(kRed, "%s", held_out_error_.c_str());
    return;
  }
  ImGui::SameLine();
  ImGui::BeginChild("held-out", ImVec2(0, avail.y));
  const HeldOutComparison& c = *held_out_;
  ImGui::Text("held-out view %d: PSNR %.2f dB, SSIM %.3f", c.view, c.psnr_db, c.ssim);
  if (held_out_views_.size() > 1) {
    ImGui::SetNextItemWidth(120.0f);
    if (ImGui::Combo(
            "view", &held_out_index_,
            [](void* data, int i, const char** text) {
              static char label[16];
              std::snprintf(label, sizeof(label), "view %d",
                            (*static_cast<std::vector<int>*>(data))[static_cast<std::size_t>(i)]);
              *text = label;
              return true;
            },
            &held_out_views_, static_cast<int>(held_out_views_.size())))
      StartHeldOutLoad(held_out_views_[static_cast<std::size_t>(held_out_index_)]);
  }
  ImGui::SetNextItemWidth(-1.0f);
  ImGui::SliderFloat("##split", &split_, 0.0f, 1.0f, "photo | model");
  const ImVec2 box = Fit(static_cast<float>(c.photo_rgba.cols),
                         static_cast<float>(c.photo_rgba.rows), ImGui::GetContentRegionAvail());
  const ImVec2 p0 = ImGui::GetCursorScreenPos();
  ImDrawList* draw = ImGui::GetWindowDrawList();
  const float x_split = p0.x + box.x * split_;
  draw->AddImage(TextureId(held_out_photo_), p0, ImVec2(x_split, p0.y + box.y), ImVec2(0, 0),
                 ImVec2(split_, 1));
  draw->AddImage(TextureId(held_out_render_), ImVec2(x_split, p0.y),
                 ImVec2(p0.x + box.x, p0.y + box.y), ImVec2(split_, 0), ImVec2(1, 1));
  draw->AddLine(ImVec2(x_split, p0.y), ImVec2(x_split, p0.y + box.y), IM_COL32(255, 255, 255, 200),
                2.0f);
  ImGui::Dummy(box);
  ImGui::TextColored(kDim, "left: the photo (%s), right: the model through its camera",
                     c.photo.c_str());
  ImGui::EndChild();
}

void StudioApp::DrawPhotosTab() {
  ImGui::Checkbox("mask overlay", &show_masks_);
  ImGui::SameLine();
  const auto verified =
      std::count_if(thumbs_.begin(), thumbs_.end(), [](const Thumb& t) { return t.info.verified; });
  ImGui::TextColored(kDim, "%zu photos downloaded, %td verified", thumbs_.size(), verified);
  ImGui::BeginChild("thumbs");
  const float cell = 170.0f;
  const int columns = std::max(1, static_cast<int>(ImGui::GetContentRegionAvail().x / cell));
  int column = 0;
  for (const Thumb& t : thumbs_) {
    if (column++ % columns != 0) ImGui::SameLine();
    ImGui::BeginGroup();
    if (t.photo != 0) {
      const ImVec2 size(static_cast<float>(t.info.rgba.cols > 0 ? t.info.rgba.cols : 160), 120.0f);
      const ImVec2 p0 = ImGui::GetCursorScreenPos();
      ImGui::Image(TextureId(t.photo), ImVec2(160.0f, 107.0f));
      if (show_masks_ && t.mask != 0)
        ImGui::GetWindowDrawList()->AddImage(TextureId(t.mask), p0,
                                             ImVec2(p0.x + 160.0f, p0.y + 107.0f));
      (void)size;
    } else {
      ImGui::Dummy(ImVec2(160.0f, 107.0f));
    }
    ImGui::TextColored(t.info.verified ? kGreen : kRed, "%s %s", t.info.stem.c_str(),
                       t.info.verified ? "verified" : "!");
    if (!t.info.problem.empty() && ImGui::IsItemHovered())
      ImGui::SetTooltip("%s", t.info.problem.c_str());
    ImGui::EndGroup();
  }
  ImGui::EndChild();
}

void StudioApp::DrawReportTab() {
  if (report_.is_null() || !report_.is_object()) {
    ImGui::TextColored(kDim, "no report yet (the texture stage writes model/report.json)");
  } else {
    const nlohmann::json& r = report_;
    ImGui::Text("%d faces, %d views, %d charts in a %d x %d atlas", r.value("faces", 0),
                r.value("views", 0), r.value("charts", 0), r.value("atlas_size", 0),
                r.value("atlas_size", 0));
    if (r.contains("held_out")) {
      const nlohmann::json& h = r["held_out"];
      ImGui::Separator();
      ImGui::TextUnformatted("held-out views");
      ImGui::Text("mean PSNR %.2f dB, mean SSIM %.3f", h.value("mean_psnr_db", 0.0),
                  h.value("mean_ssim", 0.0));
      for (const auto& v : h["views"])
        ImGui::BulletText("view %d: PSNR %.2f dB, SSIM %.3f", v.value("view", -1),
                          v.value("psnr_db", 0.0), v.value("ssim", 0.0));
    }
    if (r.contains("histogram")) {
      ImGui::Separator();
      ImGui::TextUnformatted("faces by texels per face");
      const nlohmann::json& hist = r["histogram"];
      std::vector<float> counts;
      for (const auto& c : hist.value("faces", nlohmann::json::array()))
        counts.push_back(c.get<float>());
      const auto starts = hist.value("texels_per_face_bin_starts", nlohmann::json::array());
      ImGui::PlotHistogram("##hist", counts.data(), static_cast<int>(counts.size()), 0, nullptr,
                           0.0f, FLT_MAX, ImVec2(-1.0f, 160.0f));
      std::string bins = "bins start at";
      for (const auto& s : starts) bins += " " + std::to_string(s.get<int>());
      bins += " texels";
      ImGui::TextColored(kDim, "%s", bins.c_str());
    }
  }
  ImGui::Separator();
  ImGui::TextUnformatted("stage times");
  if (stage_seconds_.empty()) ImGui::TextColored(kDim, "none recorded yet");
  for (const auto& [stage, seconds] : stage_seconds_)
    ImGui::BulletText("%s: %.1f s", stage.c_str(), seconds);
  if (report_.is_object() && report_.contains("seconds")) {
    const nlohmann::json& s = report_["seconds"];
    ImGui::TextColored(kDim,
                       "texture: grouping %.2f s, atlas %.2f s, transfer %.2f s, export %.2f s",
                       s.value("grouping", 0.0), s.value("atlas", 0.0), s.value("transfer", 0.0),
                       s.value("export", 0.0));
  }
}

void StudioApp::DrawOperator() {
  const ImGuiViewport* viewport = ImGui::GetMainViewport();
  ImGui::SetNextWindowPos(viewport->WorkPos);
  ImGui::SetNextWindowSize(viewport->WorkSize);
  ImGui::Begin(
      "operator", nullptr,
      ImGuiWindowFlags_NoDecoration | ImGuiWindowFlags_NoMove | ImGuiWindowFlags_NoSavedSettings);
  const JobStatus job = controller_.Status();
  const bool busy = job.state == JobState::kRunning;
  const float width = viewport->WorkSize.x;
  ImGui::Text("Carousel: scan the product's barcode, then press the button");
  ImGui::Spacing();
  ImGui::SetNextItemWidth(width * 0.6f);
  if (focus_sku_ && !busy) {
    ImGui::SetKeyboardFocusHere();
    focus_sku_ = false;
  }
  if (busy) ImGui::BeginDisabled();
  const bool enter =
      ImGui::InputTextWithHint("##sku", "SKU", &sku_, ImGuiInputTextFlags_EnterReturnsTrue);
  ImGui::Spacing();
  if (ImGui::Button(busy ? "Working..." : "Capture and build",
                    ImVec2(-1.0f, viewport->WorkSize.y * 0.2f)) ||
      (enter && !busy)) {
    PressButton(sku_);
  }
  if (busy) ImGui::EndDisabled();
  ImGui::Spacing();
  if (busy) {
    DrawStageBars(job, 0.0f);
  } else if (job.state == JobState::kSucceeded || job.state == JobState::kFailed ||
             job.state == JobState::kCancelled) {
    const bool ok = ModelReady(job);
    ImGui::PushStyleColor(ImGuiCol_Button, ok ? kGreen : kRed);
    ImGui::PushStyleColor(ImGuiCol_ButtonHovered, ok ? kGreen : kRed);
    ImGui::PushStyleColor(ImGuiCol_ButtonActive, ok ? kGreen : kRed);
    const std::string verdict = ok ? job.product + ": DONE, next product please"
                                   : job.product + ": NOT DONE, call the photographer";
    ImGui::Button(verdict.c_str(), ImVec2(-1.0f, viewport->WorkSize.y * 0.25f));
    ImGui::PopStyleColor(3);
    if (!ok) {
      ImGui::PushTextWrapPos(0.0f);
      ImGui::TextColored(kRed, "%s", job.error.c_str());
      ImGui::TextUnformatted(job.advice.c_str());
      ImGui::PopTextWrapPos();
    }
  }
  if (!start_error_.empty()) ImGui::TextColored(kRed, "%s", start_error_.c_str());
  ImGui::End();
}

}  // namespace carousel::gui
