#include "carousel/studio/run_session.h"

#include <fstream>
#include <optional>

#include <nlohmann/json.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"
#include "carousel/core/logging.h"
#include "carousel/core/options_json.h"
#include "carousel/core/timer.h"
#include "carousel/studio/capture.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/rig_factory.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

using json = nlohmann::json;

constexpr const char* kRunFile = "run.json";
// The rig calibration a session's photos take their cameras from (a copy of --calibration-file).
constexpr const char* kSessionCalibration = "calibration.json";

// The renderer settings and the capture plan's mask shots, which run.json keeps by their flag
// names.
const OptionTable<SimCaptureOptions>& SimRenderFields() {
  static const OptionTable<SimCaptureOptions> table = SimCaptureOptions::Fields().Only(
      {"material", "exposure", "contact-shadow", "cast-shadow", "backdrop-falloff", "vignetting",
       "mask-shots", "backdrop", "orientations", "second-pose", "pose-seed"});
  return table;
}

// A relative path as seen from here, made absolute: run.json is read again by `run --resume`
// from any working directory and by batch jobs on other nodes.
std::filesystem::path Absolute(const std::filesystem::path& path) {
  return path.empty() ? path : std::filesystem::absolute(path).lexically_normal();
}

json RunToJson(const RunOptions& o) {
  const SimCaptureOptions& s = o.sim;
  json run = {
      {"version", 1},
      {"product", o.product},
      {"backend", o.hardware ? "hardware" : "sim"},
      {"sim",
       {{"scene", s.scene},
        {"data_dir", s.data_dir.string()},
        {"stops", s.stops},
        {"elevations_deg", s.rig.elevations_deg},
        {"width", s.rig.width},
        {"height", s.rig.height},
        {"focal_length_mm", s.rig.focal_length_mm},
        {"distance_m", s.rig.distance_m},
        {"noise_sigma", s.render.noise_sigma},
        {"seed", s.render.seed},
        {"jpeg_quality", s.jpeg_quality},
        {"target_height_m", s.placement.target_height_m},
        {"scale", s.placement.scale},
        {"yaw_rad", s.placement.yaw_rad}}},
      {"texture",
       {{"exclude_views", o.texture.grouping.exclude_views}, {"size", o.texture.atlas.size.size}}},
      {"publish", OptionsToJson(PublishSessionOptions::Fields(), o.publish)},
      {"publish_model", o.publish_model}};
  // The renderer's look (material, exposure, shadows, falloff, vignetting) and the mask shots,
  // by their flag names.
  run["sim"].update(OptionsToJson(SimRenderFields(), s));
  // The rig as it was when the session started: a resume uses the same devices and plan even
  // if the rig file changed meanwhile.
  if (o.hardware) run["rig"] = json::parse(RigConfigToJsonText(*o.hardware));
  if (o.calibration) run["calibration"] = CalibrationPlanToJson(*o.calibration);
  if (!o.calibration_file.empty()) run["calibration_file"] = kSessionCalibration;
  return run;
}

RunOptions RunFromJson(const std::filesystem::path& path) {
  RunOptions o;
  try {
    std::ifstream in(path);
    if (!in) throw IoError(path, "cannot be read (not a session started by `carousel run`?)");
    const json j = json::parse(in);
    if (j.at("version").get<int>() != 1) throw FormatError(path, "unsupported version");
    const std::string backend = j.at("backend").get<std::string>();
    if (backend == "hardware") {
      o.hardware = RigConfigFromJsonText(j.at("rig").dump(), path);
    } else if (backend != "sim") {
      throw FormatError(path, "backend '" + backend + "' is not available in this build");
    }
    o.product = j.at("product").get<std::string>();
    const json& s = j.at("sim");
    o.sim.scene = s.at("scene").get<std::string>();
    o.sim.data_dir = s.at("data_dir").get<std::string>();
    o.sim.stops = s.at("stops").get<int>();
    o.sim.rig.elevations_deg = s.at("elevations_deg").get<std::vector<double>>();
    o.sim.rig.width = s.at("width").get<int>();
    o.sim.rig.height = s.at("height").get<int>();
    o.sim.rig.focal_length_mm = s.at("focal_length_mm").get<double>();
    o.sim.rig.distance_m = s.at("distance_m").get<double>();
    o.sim.render.noise_sigma = s.at("noise_sigma").get<double>();
    o.sim.render.seed = s.at("seed").get<std::uint64_t>();
    o.sim.jpeg_quality = s.at("jpeg_quality").get<int>();
    o.sim.placement.target_height_m = s.at("target_height_m").get<double>();
    o.sim.placement.scale = s.at("scale").get<double>();
    o.sim.placement.yaw_rad = s.at("yaw_rad").get<double>();
    // Sessions from before these were recorded render with today's defaults.
    OptionsFromJson(SimRenderFields(), s, &o.sim, path);
    o.texture.grouping.exclude_views = j.at("texture").at("exclude_views").get<std::vector<int>>();
    o.texture.atlas.size.size = j.at("texture").at("size").get<int>();
    // Sessions started before publish options were recorded publish with today's defaults.
    if (j.contains("publish")) {
      OptionsFromJson(PublishSessionOptions::Fields(), j["publish"], &o.publish, path);
    }
    o.publish_model = j.value("publish_model", true);
    if (j.contains("calibration")) o.calibration = CalibrationPlanFromJson(j["calibration"], path);
    if (j.contains("calibration_file"))
      o.calibration_file = path.parent_path() / j["calibration_file"].get<std::string>();
  } catch (const json::exception& e) {
    throw FormatError(path, std::string("malformed: ") + e.what());
  }
  return o;
}

// The rig a session's options ask for.
RigRequest RigRequestFor(const RunOptions& options) {
  return {.sim = options.sim,
          .hardware = options.hardware,
          .calibration = options.calibration,
          .place_board = options.place_board,
          .turn_product = options.turn_product,
          .calibration_file = options.calibration_file};
}

// Capture, then calibrate (a calibration session) or reconstruct and texture; the session is
// read once and handed down.
RunResult Continue(const std::filesystem::path& folder, const RunOptions& options, RigBackends& rig,
                   Progress& progress) {
  RunResult result;
  result.session = folder;
  RemoveStaleTemporaries(folder);
  Session session = ReadSession(folder);
  const int placements = options.calibration ? options.calibration->placements : 1;
  const CaptureResult captured = CaptureSession(folder, session, rig, placements, progress);
  result.photos_taken = captured.photos_taken;
  result.photos_kept = captured.photos_kept;
  result.photos_adopted = captured.photos_adopted;
  result.photos_retaken = captured.photos_retaken;
  result.max_trigger_skew_ms = captured.max_trigger_skew_ms;
  result.seconds_capture = captured.seconds;
  Stopwatch watch;

  // ---- a calibration session: calibrate the rig from the photos --------------------------
  if (options.calibration) {
    const auto file = folder / "calibration" / "rig_calibration.json";
    if (session.stages["calibrate"] != "done" || !std::filesystem::is_regular_file(file)) {
      watch = Stopwatch();
      result.calibration = CalibrateSession(folder, {}, file, progress);
      result.seconds_reconstruct = watch.ElapsedSeconds();
    }
    return result;
  }

  // ---- reconstruct, texture: each skipped when current (pipeline.h) ----------------------
  ReconstructOptions reconstruct = options.reconstruct;
  if (options.hardware) {
    reconstruct.silhouettes.method = options.hardware->backdrop == "difference"
                                         ? recon::SilhouetteMethod::kDifference
                                         : recon::SilhouetteMethod::kKey;
  }
  const ProcessResult processed = ProcessSession(folder, session,
                                                 {.reconstruct = reconstruct,
                                                  .texture = options.texture,
                                                  .publish = options.publish,
                                                  .publish_model = options.publish_model},
                                                 progress);
  result.reconstructed = processed.reconstruct.has_value();
  result.reconstruct = processed.reconstruct;
  result.textured = processed.texture.has_value();
  if (processed.texture) result.texture = *processed.texture;
  result.publish = processed.publish;
  result.seconds_reconstruct = processed.seconds_reconstruct;
  result.seconds_texture = processed.seconds_texture;
  return result;
}

}  // namespace

void RunOptions::Validate() const {
  SessionNameForProduct(product);
  if (hardware) {
    hardware->Validate();
  } else {
    sim.Validate();
  }
  reconstruct.Validate();
  texture.Validate();
  publish.Validate();
  if (calibration) calibration->Validate();
  CAROUSEL_THROW_IF(calibration && !calibration_file.empty(), InvalidArgument,
                    "a calibration session does not take a calibration file");
  if (!calibration_file.empty()) RequireReadableFile(calibration_file);
}

namespace {

// The first of `records` (file, JSON pointer) that exists and holds the pointer: the file and the
// value; nothing when none does. \throw FormatError naming a file that is not JSON (IoError:
// unreadable).
std::optional<std::pair<std::filesystem::path, json>> FirstRecord(
    const std::vector<std::pair<std::filesystem::path, std::string>>& records) {
  for (const auto& [file, pointer] : records) {
    if (!std::filesystem::is_regular_file(file)) continue;
    const json j = ParseJsonFile(file);
    const json::json_pointer at(pointer);
    if (j.contains(at)) return std::pair{file, j.at(at)};
  }
  return std::nullopt;
}

}  // namespace

PublishSessionOptions RecordedPublishOptions(const std::filesystem::path& session) {
  PublishSessionOptions options;
  if (const auto record = FirstRecord(
          {{session / "model" / "publish.json", "/options"}, {session / kRunFile, "/publish"}}))
    OptionsFromJson(PublishSessionOptions::Fields(), record->second, &options, record->first);
  return options;
}

std::vector<int> RecordedExcludedViews(const std::filesystem::path& session) {
  const auto record = FirstRecord({{session / "model" / "report.json", "/excluded_views"},
                                   {session / kRunFile, "/texture/exclude_views"}});
  if (!record) return {};
  try {
    return record->second.get<std::vector<int>>();
  } catch (const json::exception& e) {
    throw FormatError(record->first, std::string("excluded views: ") + e.what());
  }
}

std::string SessionNameForProduct(const std::string& product) {
  std::string name;
  for (const char ch : product) {
    const bool keep = (ch >= 'a' && ch <= 'z') || (ch >= 'A' && ch <= 'Z') ||
                      (ch >= '0' && ch <= '9') || ch == '-' || ch == '_' || ch == '.';
    name.push_back(keep ? ch : '_');
    if (name.size() == 100) break;
  }
  while (!name.empty() && name.front() == '.') name.erase(name.begin());
  const bool meaningful = name.find_first_not_of("_.") != std::string::npos;
  CAROUSEL_THROW_IF(
      !meaningful, InvalidArgument,
      "product '" << product << "' leaves no usable session folder name (use letters or digits)");
  return name;
}

RunResult RunSession(const RunOptions& requested, Progress& progress) {
  requested.Validate();
  RunOptions options = requested;
  options.sim.data_dir = Absolute(options.sim.data_dir);
  if (IsSceneFile(options.sim.scene)) options.sim.scene = Absolute(options.sim.scene).string();
  if (!options.calibration_file.empty())
    options.calibration_file = Absolute(options.calibration_file);
  if (options.calibration && !options.hardware) {
    // The simulated board's height above the plate is known exactly.
    options.calibration->board_origin_height_m = SimBoardOriginHeight(*options.calibration);
  }
  const std::filesystem::path folder = options.out / SessionNameForProduct(options.product);
  std::error_code ec;
  if (std::filesystem::exists(folder, ec) && !options.force) {
    throw IoError(folder,
                  "a session of that product exists; `carousel run --resume` continues it, "
                  "--force starts over (the old folder is kept beside it)");
  }
  // Every device answers before anything is written: a missing camera costs nothing.
  RigBackends rig = OpenRig(RigRequestFor(options));
  if (std::filesystem::exists(folder, ec)) {
    if (!options.force)
      throw IoError(
          folder,
          "a session of that product exists; `carousel run --resume` continues it, --force "
          "starts over (the old folder is kept beside it)");
    const std::string stamp = NowUtc();
    std::string safe;
    for (const char ch : stamp) safe.push_back(ch == ':' ? '-' : ch);
    const auto aside = folder.string() + ".old-" + safe;
    std::filesystem::rename(folder, aside);
    CAROUSEL_LOG_INFO("kept the previous session as " << aside);
  }
  // The folder appears complete with run.json and session.json, or not at all: a kill before
  // the rename leaves only a hidden staging folder, never a session `--resume` cannot read.
  std::filesystem::create_directories(options.out, ec);
  if (ec) throw IoError(options.out, "cannot create the sessions folder: " + ec.message());
  {
    StagedSessionFolder staged(folder, false);
    staged.CreateFolder("images");
    WriteFileAtomic(staged.staging() / kRunFile, RunToJson(options).dump(2));
    if (!options.calibration_file.empty()) {
      // The session keeps the calibration its photos were given, whatever happens to the file.
      WriteFileAtomic(staged.staging() / kSessionCalibration,
                      ReadFileBytes(options.calibration_file));
    }
    Session session;
    session.product = options.product;
    session.created_utc = NowUtc();
    session.source = std::string(options.calibration ? "calibration:" : "") +
                     (options.hardware ? "rig" : "sim:" + options.sim.scene);
    session.frame = "turntable";
    WriteSessionManifest(staged.staging(), session);
    if (options.hardware && options.hardware->backdrop == "difference") {
      // The rig's background plates travel with the session (the difference method reads them).
      staged.CreateFolder("backgrounds");
      for (std::size_t c = 0; c < options.hardware->cameras.size(); ++c) {
        const std::string stem = "cam" + std::to_string(c);
        std::filesystem::path plate = options.hardware->backgrounds / (stem + ".jpg");
        if (!std::filesystem::is_regular_file(plate))
          plate = options.hardware->backgrounds / (stem + ".png");
        if (!std::filesystem::is_regular_file(plate))
          throw IoError(options.hardware->backgrounds / (stem + ".jpg"),
                        "no background plate for camera " + std::to_string(c) +
                            " (the rig's backdrop is \"difference\")");
        const std::vector<std::uint8_t> bytes = ReadFileBytes(plate);
        WriteFileAtomic(staged.staging() / "backgrounds" / (stem + plate.extension().string()),
                        bytes);
      }
    }
    staged.Commit();
  }
  return Continue(folder, options, rig, progress);
}

RunResult ResumeSession(const std::filesystem::path& session, Progress& progress,
                        std::function<void(int pass, int passes)> turn_product) {
  if (!std::filesystem::is_directory(session)) throw IoError(session, "is not a session folder");
  RunOptions options = RunFromJson(session / kRunFile);
  options.turn_product = std::move(turn_product);
  options.out = session.parent_path();
  options.Validate();
  RigBackends rig = OpenRig(RigRequestFor(options));
  return Continue(session, options, rig, progress);
}

}  // namespace carousel::studio
