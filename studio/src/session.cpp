#include "carousel/studio/session.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <ctime>
#include <numbers>
#include <optional>
#include <string_view>

#include <nlohmann/json.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"

namespace carousel::studio {
namespace {

using nlohmann::json;

constexpr std::string_view kFolder = "session folder";

// ".<name><tag><pid>" beside `path` (built by append: GCC 12 warns falsely on "." + string).
std::filesystem::path HiddenSibling(const std::filesystem::path& path, const char* tag) {
  std::string name = ".";
  name.append(path.filename().string()).append(tag).append(std::to_string(::getpid()));
  return path.parent_path() / name;
}

}  // namespace

std::string NowUtc() {
  const std::time_t now = std::time(nullptr);
  std::tm utc{};
  gmtime_r(&now, &utc);
  char text[32];
  std::strftime(text, sizeof text, "%Y-%m-%dT%H:%M:%SZ", &utc);
  return text;
}

void WriteSessionManifest(const std::filesystem::path& folder, const Session& session) {
  json views = json::array();
  for (const SessionView& view : session.views) {
    json entry = {{"image", view.image},
                  {"camera", view.camera},
                  {"stop", view.stop},
                  {"table_angle_deg", view.table_angle_deg},
                  {"camera_model", CameraModelToJson(view.camera_model)}};
    if (!view.mask.empty()) entry["mask"] = view.mask;
    if (!view.mask_sha256.empty()) entry["mask_sha256"] = view.mask_sha256;
    if (!view.sha256.empty()) entry["sha256"] = view.sha256;
    if (!view.mask_shot.empty()) entry["mask_shot"] = view.mask_shot;
    if (!view.mask_shot_sha256.empty()) entry["mask_shot_sha256"] = view.mask_shot_sha256;
    if (!view.given_mask.empty()) entry["given_mask"] = view.given_mask;
    if (!view.given_mask_sha256.empty()) entry["given_mask_sha256"] = view.given_mask_sha256;
    if (view.trigger_offset_ms >= 0) entry["trigger_offset_ms"] = view.trigger_offset_ms;
    if (view.pass != 0) entry["pass"] = view.pass;
    views.push_back(entry);
  }
  json manifest = {{"format", "carousel-session"},
                   {"version", session.version},
                   {"product", session.product},
                   {"created_utc", session.created_utc},
                   {"source", session.source},
                   {"frame", session.frame},
                   {"views", views},
                   {"stages", session.stages}};
  if (session.world_from_dataset)
    manifest["world_from_dataset"] = Rigid3dToJson(*session.world_from_dataset);
  if (!session.passes.empty()) {
    json passes = json::array();
    for (const SessionPass& pass : session.passes) {
      json entry = {{"orientation", pass.orientation}};
      if (!pass.registration.empty()) entry["registration"] = pass.registration;
      if (!pass.registration_note.empty()) entry["registration_note"] = pass.registration_note;
      if (pass.table_from_object)
        entry["table_from_object"] = Rigid3dToJson(*pass.table_from_object);
      if (!pass.pose_choices.empty()) {
        json choices = json::array();
        for (const Rigid3d& pose : pass.pose_choices) choices.push_back(Rigid3dToJson(pose));
        entry["pose_choices"] = choices;
      }
      if (pass.chosen_pose > 0) entry["chosen_pose"] = pass.chosen_pose;
      passes.push_back(entry);
    }
    manifest["passes"] = passes;
  }
  if (!session.stage_inputs.empty()) manifest["stage_inputs"] = session.stage_inputs;
  if (!session.stage_seconds.empty()) manifest["stage_seconds"] = session.stage_seconds;
  if (!session.ground_truth.empty()) {
    manifest["ground_truth"] = {{"mesh", session.ground_truth.mesh},
                                {"masks", session.ground_truth.masks},
                                {"depth", session.ground_truth.depth},
                                {"depth_unit_m", session.ground_truth.depth_unit_m}};
    if (!session.ground_truth.table_from_object.empty()) {
      json poses = json::array();
      for (const Rigid3d& pose : session.ground_truth.table_from_object)
        poses.push_back(Rigid3dToJson(pose));
      manifest["ground_truth"]["table_from_object"] = poses;
    }
    if (!session.ground_truth.eval_views.empty()) {
      json eval = json::array();
      for (const EvalView& view : session.ground_truth.eval_views)
        eval.push_back({{"image", view.image},
                        {"mask", view.mask},
                        {"name", view.name},
                        {"camera_model", CameraModelToJson(view.camera_model)}});
      manifest["ground_truth"]["eval_views"] = eval;
    }
  }
  WriteFileAtomic(folder / kManifestName, manifest.dump(2) + "\n");
}

Session ReadSession(const std::filesystem::path& folder) {
  const std::filesystem::path path = folder / kManifestName;
  const json manifest = ParseJsonFile(path);
  const JsonReader read(manifest, path);
  if (read.String("format") != "carousel-session") {
    read.Fail("not a Carousel session manifest (format is not 'carousel-session')");
  }
  Session session;
  session.version = read.Int("version");
  if (session.version < 1 || session.version > kSessionFormatVersion) {
    read.Fail("session format version " + std::to_string(session.version) +
              " is not supported (this build reads 1.." + std::to_string(kSessionFormatVersion) +
              ")");
  }
  session.product = read.String("product");
  session.created_utc = read.OptionalString("created_utc").value_or("");
  session.source = read.OptionalString("source").value_or("");
  session.frame = read.String("frame");
  if (session.frame != "turntable" && session.frame != "dataset") {
    read.Fail("frame must be 'turntable' or 'dataset', got '" + session.frame + "'");
  }
  if (const auto transform = read.OptionalObject("world_from_dataset"))
    session.world_from_dataset = Rigid3dFromJson(*transform);
  for (const JsonReader& entry : read.Array("views")) {
    SessionView view;
    view.image = entry.RelativePath("image", kFolder);
    view.mask = entry.OptionalRelativePath("mask", kFolder).value_or("");
    view.mask_sha256 = entry.OptionalString("mask_sha256").value_or("");
    view.sha256 = entry.OptionalString("sha256").value_or("");
    view.mask_shot = entry.OptionalRelativePath("mask_shot", kFolder).value_or("");
    view.mask_shot_sha256 = entry.OptionalString("mask_shot_sha256").value_or("");
    view.given_mask = entry.OptionalRelativePath("given_mask", kFolder).value_or("");
    view.given_mask_sha256 = entry.OptionalString("given_mask_sha256").value_or("");
    view.trigger_offset_ms = entry.OptionalNumber("trigger_offset_ms").value_or(-1.0);
    view.camera = entry.Int("camera");
    view.stop = entry.Int("stop");
    view.table_angle_deg = entry.Number("table_angle_deg");
    view.camera_model = CameraModelFromJson(entry.Object("camera_model"));
    view.pass = entry.OptionalInt("pass").value_or(0);
    if (view.pass < 0) entry.Fail("pass must be >= 0, got " + std::to_string(view.pass));
    session.views.push_back(view);
  }
  if (read.Has("passes")) {
    for (const JsonReader& entry : read.Array("passes")) {
      SessionPass pass;
      pass.orientation = entry.String("orientation");
      pass.registration = entry.OptionalString("registration").value_or("");
      pass.registration_note = entry.OptionalString("registration_note").value_or("");
      if (const auto pose = entry.OptionalObject("table_from_object"))
        pass.table_from_object = Rigid3dFromJson(*pose);
      if (entry.Has("pose_choices"))
        for (const JsonReader& pose : entry.Array("pose_choices"))
          pass.pose_choices.push_back(Rigid3dFromJson(pose));
      pass.chosen_pose = entry.OptionalInt("chosen_pose").value_or(0);
      if (pass.chosen_pose < 0 || pass.chosen_pose > static_cast<int>(pass.pose_choices.size()))
        entry.Fail("chosen_pose must be 1.." + std::to_string(pass.pose_choices.size()) +
                   " (a pose of pose_choices) or 0, got " + std::to_string(pass.chosen_pose));
      if (pass.registration != "" && pass.registration != "registered" &&
          pass.registration != "ambiguous" && pass.registration != "failed")
        entry.Fail("registration must be registered, ambiguous or failed, got '" +
                   pass.registration + "'");
      if (pass.registration == "registered" && !pass.table_from_object)
        entry.Fail("a registered pass has no table_from_object");
      session.passes.push_back(pass);
    }
  }
  int last_pass = 0;
  for (std::size_t i = 0; i < session.views.size(); ++i) {
    const int pass = session.views[i].pass;
    if (pass != 0 && pass >= static_cast<int>(session.passes.size()))
      read.Fail("views[" + std::to_string(i) + "] belongs to pass " + std::to_string(pass) +
                " but the session lists " + std::to_string(session.passes.size()) + " passes");
    if (pass < last_pass)
      read.Fail("views[" + std::to_string(i) + "] of pass " + std::to_string(pass) +
                " follows a view of pass " + std::to_string(last_pass) +
                " (each pass's views follow the earlier passes')");
    last_pass = pass;
  }
  session.stages = read.OptionalStringMap("stages").value_or(session.stages);
  session.stage_inputs = read.OptionalStringMap("stage_inputs").value_or(session.stage_inputs);
  if (const std::optional<JsonReader> seconds = read.OptionalObject("stage_seconds")) {
    for (const auto& [stage, value] : seconds->value().items())
      session.stage_seconds[stage] = seconds->Number(stage);
  }
  if (const std::optional<JsonReader> truth = read.OptionalObject("ground_truth")) {
    session.ground_truth.mesh = truth->OptionalRelativePath("mesh", kFolder).value_or("");
    for (const JsonReader& mask : truth->Array("masks")) {
      session.ground_truth.masks.push_back(mask.AsRelativePath(kFolder));
    }
    for (const JsonReader& depth : truth->Array("depth")) {
      session.ground_truth.depth.push_back(depth.AsRelativePath(kFolder));
    }
    session.ground_truth.depth_unit_m = truth->Number("depth_unit_m");
    if (truth->Has("table_from_object")) {
      for (const JsonReader& pose : truth->Array("table_from_object"))
        session.ground_truth.table_from_object.push_back(Rigid3dFromJson(pose));
    }
    if (truth->Has("eval_views")) {
      for (const JsonReader& entry : truth->Array("eval_views")) {
        EvalView view;
        view.image = entry.RelativePath("image", kFolder);
        view.mask = entry.RelativePath("mask", kFolder);
        view.name = entry.OptionalString("name").value_or("");
        view.camera_model = CameraModelFromJson(entry.Object("camera_model"));
        session.ground_truth.eval_views.push_back(view);
      }
    }
  }
  return session;
}

std::string ViewStem(int camera, int stop, int pass) {
  char text[48];
  if (pass > 0)
    std::snprintf(text, sizeof text, "pass%d_cam%d_stop%02d", pass, camera, stop);
  else
    std::snprintf(text, sizeof text, "cam%d_stop%02d", camera, stop);
  return text;
}

bool HasSeveralPasses(const Session& session) {
  return std::any_of(session.views.begin(), session.views.end(),
                     [](const SessionView& view) { return view.pass != 0; });
}

std::vector<View> SessionViews(const std::filesystem::path& folder, const Session& session) {
  std::vector<View> views;
  views.reserve(session.views.size());
  for (const SessionView& entry : session.views) {
    if (entry.pass == 0) {
      views.emplace_back(entry.camera_model, folder / entry.image,
                         entry.mask.empty() ? std::filesystem::path() : folder / entry.mask,
                         entry.table_angle_deg * std::numbers::pi / 180.0);
      continue;
    }
    const SessionPass& pass = session.passes.at(static_cast<std::size_t>(entry.pass));
    if (pass.registration != "registered" || !pass.table_from_object) break;
    CameraModel camera = entry.camera_model;
    camera.cam_from_world = camera.cam_from_world * *pass.table_from_object;
    views.emplace_back(camera, folder / entry.image,
                       entry.mask.empty() ? std::filesystem::path() : folder / entry.mask,
                       entry.table_angle_deg * std::numbers::pi / 180.0);
  }
  return views;
}

std::vector<View> SessionTableViews(const std::filesystem::path& folder, const Session& session) {
  std::vector<View> views;
  views.reserve(session.views.size());
  for (const SessionView& entry : session.views) {
    View view(entry.camera_model, folder / entry.image,
              entry.mask.empty() ? std::filesystem::path() : folder / entry.mask,
              entry.table_angle_deg * std::numbers::pi / 180.0);
    views.push_back(std::move(view));
  }
  return views;
}

std::vector<View> SessionMaskShotViews(const std::filesystem::path& folder,
                                       const Session& session) {
  std::vector<View> views;
  for (const SessionView& entry : session.views) {
    if (entry.mask_shot.empty()) return {};
    views.emplace_back(entry.camera_model, folder / entry.mask_shot, std::filesystem::path(),
                       entry.table_angle_deg * std::numbers::pi / 180.0);
  }
  return views;
}

StagedSessionFolder::StagedSessionFolder(const std::filesystem::path& target, bool overwrite)
    : overwrite_(overwrite) {
  CAROUSEL_THROW_IF(target.empty(), InvalidArgument, "no session folder given");
  std::error_code ec;
  target_ = std::filesystem::absolute(target).lexically_normal();
  if (target_.filename().empty()) target_ = target_.parent_path();
  if (std::filesystem::exists(target_, ec)) {
    if (!overwrite) {
      throw IoError(target_, "exists; choose another folder or pass --force to replace it");
    }
    // --force replaces sessions, never an arbitrary folder.
    if (!std::filesystem::is_regular_file(target_ / kManifestName, ec)) {
      throw IoError(target_,
                    "exists and is not a Carousel session folder (no session.json); "
                    "refusing to replace it");
    }
  }
  const std::filesystem::path parent = target_.parent_path();
  if (!std::filesystem::is_directory(parent, ec)) {
    throw IoError(target_, "parent folder " + parent.string() + " does not exist");
  }
  staging_ = HiddenSibling(target_, ".partial-");
  std::filesystem::remove_all(staging_, ec);
  std::filesystem::create_directory(staging_, ec);
  if (ec) throw IoError(staging_, "cannot create folder: " + ec.message());
}

StagedSessionFolder::~StagedSessionFolder() {
  if (!committed_) {
    std::error_code ec;
    std::filesystem::remove_all(staging_, ec);
  }
}

void StagedSessionFolder::CreateFolder(const std::filesystem::path& relative) const {
  std::error_code ec;
  std::filesystem::create_directories(staging_ / relative, ec);
  if (ec) throw IoError(staging_ / relative, "cannot create folder: " + ec.message());
}

void StagedSessionFolder::Commit() {
  const std::filesystem::path parent = target_.parent_path();
  std::error_code ec;
  std::filesystem::path old;
  if (std::filesystem::exists(target_, ec)) {
    if (!overwrite_) throw IoError(target_, "appeared meanwhile; not replacing it");
    old = HiddenSibling(target_, ".old-");
    std::filesystem::rename(target_, old, ec);
    if (ec) throw IoError(target_, "cannot move the old session aside: " + ec.message());
  }
  std::filesystem::rename(staging_, target_, ec);
  if (ec) {
    const std::string reason = ec.message();
    std::string where;
    if (!old.empty()) {
      std::filesystem::rename(old, target_, ec);
      if (ec) where = "; the previous session is kept at " + old.string();
    }
    throw IoError(target_, "cannot move the new session into place: " + reason + where);
  }
  committed_ = true;
  SyncFolder(parent);
  if (!old.empty()) std::filesystem::remove_all(old, ec);
}

}  // namespace carousel::studio
