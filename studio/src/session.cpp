#include "carousel/studio/session.h"

#include <unistd.h>

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
  if (!session.stage_inputs.empty()) manifest["stage_inputs"] = session.stage_inputs;
  if (!session.stage_seconds.empty()) manifest["stage_seconds"] = session.stage_seconds;
  if (!session.ground_truth.empty()) {
    manifest["ground_truth"] = {{"mesh", session.ground_truth.mesh},
                                {"masks", session.ground_truth.masks},
                                {"depth", session.ground_truth.depth},
                                {"depth_unit_m", session.ground_truth.depth_unit_m}};
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
    session.views.push_back(view);
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
  }
  return session;
}

std::string ViewStem(int camera, int stop) {
  char text[32];
  std::snprintf(text, sizeof text, "cam%d_stop%02d", camera, stop);
  return text;
}

std::vector<View> SessionViews(const std::filesystem::path& folder, const Session& session) {
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
