#include "carousel/studio/session.h"

#include <unistd.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <ctime>
#include <limits>
#include <numbers>

#include <nlohmann/json.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel::studio {
namespace {

using nlohmann::json;

}  // namespace

json CameraModelToJson(const CameraModel& camera) {
  const Rigid3d& pose = camera.cam_from_world;
  json rotation = json::array();
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) rotation.push_back(pose.rotation(r, c));
  }
  return {{"width", camera.width},
          {"height", camera.height},
          {"fx", camera.fx},
          {"fy", camera.fy},
          {"cx", camera.cx},
          {"cy", camera.cy},
          {"distortion",
           {camera.distortion.k1, camera.distortion.k2, camera.distortion.p1, camera.distortion.p2,
            camera.distortion.k3}},
          {"cam_from_world",
           {{"rotation_row_major", rotation},
            {"translation", {pose.translation.x(), pose.translation.y(), pose.translation.z()}}}}};
}

namespace {

json CameraToJson(const CameraModel& camera) { return CameraModelToJson(camera); }

// Field access that turns every JSON problem into a FormatError naming the field.
class Reader {
 public:
  explicit Reader(std::filesystem::path path) : path_(std::move(path)) {}

  [[noreturn]] void Fail(const std::string& what) const { throw FormatError(path_, what); }

  const json& Field(const json& object, const std::string& key, const std::string& where) const {
    if (!object.is_object()) Fail(where + " is not an object");
    const auto it = object.find(key);
    if (it == object.end()) Fail(where + " has no field '" + key + "'");
    return *it;
  }
  double Number(const json& object, const std::string& key, const std::string& where) const {
    const json& value = Field(object, key, where);
    if (!value.is_number()) Fail(where + "." + key + " is not a number");
    const double number = value.get<double>();
    if (!std::isfinite(number)) Fail(where + "." + key + " is not finite");
    return number;
  }
  int Integer(const json& object, const std::string& key, const std::string& where) const {
    const json& value = Field(object, key, where);
    if (!value.is_number_integer()) Fail(where + "." + key + " is not an integer");
    const auto wide = value.get<std::int64_t>();
    if (wide < std::numeric_limits<int>::min() || wide > std::numeric_limits<int>::max()) {
      Fail(where + "." + key + " is out of range");
    }
    return static_cast<int>(wide);
  }
  std::string String(const json& object, const std::string& key, const std::string& where,
                     bool required = true) const {
    if (!required && (!object.is_object() || !object.contains(key))) return {};
    const json& value = Field(object, key, where);
    if (!value.is_string()) Fail(where + "." + key + " is not a string");
    return value.get<std::string>();
  }
  std::vector<double> Numbers(const json& value, std::size_t count,
                              const std::string& where) const {
    if (!value.is_array() || value.size() != count) {
      Fail(where + " must be an array of " + std::to_string(count) + " numbers");
    }
    std::vector<double> numbers;
    for (const json& item : value) {
      if (!item.is_number()) Fail(where + " holds a non-number");
      numbers.push_back(item.get<double>());
    }
    return numbers;
  }
  // A relative path that stays inside the session folder.
  std::string RelativePath(const json& object, const std::string& key, const std::string& where,
                           bool required = true) const {
    std::string text = String(object, key, where, required);
    if (text.empty()) {
      if (required) Fail(where + "." + key + " is empty");
      return text;
    }
    std::string field = where;
    field.append(".").append(key);
    const std::filesystem::path path(text);
    if (path.is_absolute()) Fail(field.append(" is an absolute path: ").append(text));
    for (const auto& part : path) {
      if (part == "..") Fail(field.append(" leaves the session folder: ").append(text));
    }
    return text;
  }

  CameraModel Camera(const json& value, const std::string& where) const {
    CameraModel camera;
    camera.width = Integer(value, "width", where);
    camera.height = Integer(value, "height", where);
    camera.fx = Number(value, "fx", where);
    camera.fy = Number(value, "fy", where);
    camera.cx = Number(value, "cx", where);
    camera.cy = Number(value, "cy", where);
    const std::vector<double> d =
        Numbers(Field(value, "distortion", where), 5, where + ".distortion");
    camera.distortion = {d[0], d[1], d[2], d[3], d[4]};
    const json& pose = Field(value, "cam_from_world", where);
    const std::vector<double> r =
        Numbers(Field(pose, "rotation_row_major", where + ".cam_from_world"), 9,
                where + ".cam_from_world.rotation_row_major");
    const std::vector<double> t = Numbers(Field(pose, "translation", where + ".cam_from_world"), 3,
                                          where + ".cam_from_world.translation");
    for (int i = 0; i < 9; ++i) camera.cam_from_world.rotation(i / 3, i % 3) = r[i];
    camera.cam_from_world.translation = Eigen::Vector3d(t[0], t[1], t[2]);
    try {
      camera.Validate();
    } catch (const InvalidArgument& e) {
      Fail(where + ": " + e.what());
    }
    return camera;
  }

 private:
  std::filesystem::path path_;
};

// ".<name><tag><pid>" beside `path` (built by append: GCC 12 warns falsely on "." + string).
std::filesystem::path HiddenSibling(const std::filesystem::path& path, const char* tag) {
  std::string name = ".";
  name.append(path.filename().string()).append(tag).append(std::to_string(::getpid()));
  return path.parent_path() / name;
}

}  // namespace

CameraModel CameraModelFromJson(const json& value, const std::filesystem::path& file,
                                const std::string& where) {
  return Reader(file).Camera(value, where);
}

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
                  {"camera_model", CameraToJson(view.camera_model)}};
    if (!view.mask.empty()) entry["mask"] = view.mask;
    if (!view.sha256.empty()) entry["sha256"] = view.sha256;
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
  if (!session.stage_inputs.empty()) manifest["stage_inputs"] = session.stage_inputs;
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
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  json manifest;
  try {
    manifest = json::parse(bytes.begin(), bytes.end());
  } catch (const json::parse_error& e) {
    throw FormatError(path, std::string("not valid JSON: ") + e.what());
  }
  const Reader read(path);
  if (read.String(manifest, "format", "manifest") != "carousel-session") {
    read.Fail("not a Carousel session manifest (format is not 'carousel-session')");
  }
  Session session;
  session.version = read.Integer(manifest, "version", "manifest");
  if (session.version < 1 || session.version > kSessionFormatVersion) {
    read.Fail("session format version " + std::to_string(session.version) +
              " is not supported (this build reads 1.." + std::to_string(kSessionFormatVersion) +
              ")");
  }
  session.product = read.String(manifest, "product", "manifest");
  session.created_utc = read.String(manifest, "created_utc", "manifest", false);
  session.source = read.String(manifest, "source", "manifest", false);
  session.frame = read.String(manifest, "frame", "manifest");
  if (session.frame != "turntable" && session.frame != "dataset") {
    read.Fail("manifest.frame must be 'turntable' or 'dataset', got '" + session.frame + "'");
  }
  const json& views = read.Field(manifest, "views", "manifest");
  if (!views.is_array()) read.Fail("manifest.views is not an array");
  for (std::size_t i = 0; i < views.size(); ++i) {
    const std::string where = "views[" + std::to_string(i) + "]";
    SessionView view;
    view.image = read.RelativePath(views[i], "image", where);
    view.mask = read.RelativePath(views[i], "mask", where, false);
    if (views[i].contains("sha256") && views[i]["sha256"].is_string())
      view.sha256 = views[i]["sha256"].get<std::string>();
    if (views[i].contains("trigger_offset_ms"))
      view.trigger_offset_ms = read.Number(views[i], "trigger_offset_ms", where);
    view.camera = read.Integer(views[i], "camera", where);
    view.stop = read.Integer(views[i], "stop", where);
    view.table_angle_deg = read.Number(views[i], "table_angle_deg", where);
    view.camera_model =
        read.Camera(read.Field(views[i], "camera_model", where), where + ".camera_model");
    session.views.push_back(view);
  }
  if (manifest.contains("stages")) {
    const json& stages = manifest["stages"];
    if (!stages.is_object()) read.Fail("manifest.stages is not an object");
    for (const auto& [name, state] : stages.items()) {
      if (!state.is_string()) read.Fail("manifest.stages." + name + " is not a string");
      session.stages[name] = state.get<std::string>();
    }
  }
  if (manifest.contains("stage_inputs")) {
    const json& inputs = manifest["stage_inputs"];
    if (!inputs.is_object()) read.Fail("manifest.stage_inputs is not an object");
    for (const auto& [name, fingerprint] : inputs.items()) {
      if (!fingerprint.is_string()) read.Fail("manifest.stage_inputs." + name + " is not a string");
      session.stage_inputs[name] = fingerprint.get<std::string>();
    }
  }
  if (manifest.contains("ground_truth")) {
    const json& truth = manifest["ground_truth"];
    session.ground_truth.mesh = read.RelativePath(truth, "mesh", "ground_truth", false);
    for (const char* key : {"masks", "depth"}) {
      const json& list = read.Field(truth, key, "ground_truth");
      if (!list.is_array()) read.Fail(std::string("ground_truth.") + key + " is not an array");
      auto& out =
          std::string(key) == "masks" ? session.ground_truth.masks : session.ground_truth.depth;
      for (std::size_t i = 0; i < list.size(); ++i) {
        const json wrapper = {{"path", list[i]}};
        out.push_back(read.RelativePath(
            wrapper, "path", std::string("ground_truth.") + key + "[" + std::to_string(i) + "]"));
      }
    }
    session.ground_truth.depth_unit_m = read.Number(truth, "depth_unit_m", "ground_truth");
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
