#include "carousel/studio/run_session.h"

#include <array>
#include <chrono>
#include <fstream>
#include <future>
#include <memory>
#include <numbers>
#include <optional>
#include <thread>

#include <nlohmann/json.hpp>

#include "carousel/calib/board.h"
#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/timer.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

using json = nlohmann::json;

constexpr const char* kRunFile = "run.json";
// The rig calibration a session's photos take their cameras from (a copy of --calibration-file).
constexpr const char* kSessionCalibration = "calibration.json";
constexpr auto kDeviceTimeout = std::chrono::milliseconds(60000);

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
      {"texture", {{"exclude_views", o.texture.grouping.exclude_views}, {"size", o.texture.size}}}};
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
    o.texture.grouping.exclude_views = j.at("texture").at("exclude_views").get<std::vector<int>>();
    o.texture.size = j.at("texture").at("size").get<int>();
    if (j.contains("calibration")) o.calibration = CalibrationPlanFromJson(j["calibration"], path);
    if (j.contains("calibration_file"))
      o.calibration_file = path.parent_path() / j["calibration_file"].get<std::string>();
  } catch (const json::exception& e) {
    throw FormatError(path, std::string("malformed: ") + e.what());
  }
  return o;
}

// Removes the temporary files atomic writes leave behind when a process is killed.
void RemoveStaleTemporaries(const std::filesystem::path& folder) {
  std::error_code ec;
  for (const char* sub : {"", "images", "masks", "recon", "model"}) {
    const auto dir = folder / sub;
    if (!std::filesystem::is_directory(dir, ec)) continue;
    for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
      const std::string name = entry.path().filename().string();
      if (name.size() > 1 && name[0] == '.' && name.find(".tmp-") != std::string::npos) {
        CAROUSEL_LOG_INFO("removing the stale temporary file " << entry.path().string());
        std::filesystem::remove(entry.path(), ec);
      }
    }
  }
}

// Moves a damaged photo aside into <session>/damaged/ (never deletes captured data).
void MoveAside(const std::filesystem::path& file) {
  const auto folder = file.parent_path().parent_path() / "damaged";
  std::filesystem::create_directories(folder);
  for (int n = 1;; ++n) {
    const auto aside = folder / (file.filename().string() + "." + std::to_string(n));
    if (!std::filesystem::exists(aside)) {
      std::filesystem::rename(file, aside);
      CAROUSEL_LOG_WARN("moved the damaged photo " << file.string() << " aside to " << aside);
      return;
    }
  }
}

// Whether `file` is a complete photo of `camera`'s size.
bool IsCompletePhoto(const std::filesystem::path& file, const CameraModel& camera) {
  try {
    const cv::Mat image = ReadImage(file);
    return image.cols == camera.width && image.rows == camera.height;
  } catch (const Error&) {
    return false;
  }
}

// The board placements of a simulated calibration session: the board drawn, standing on the
// table at each lean; table_from_board per placement.
std::vector<std::pair<std::shared_ptr<sim::Scene>, Rigid3d>> SimBoardPlacements(
    const CalibrationPlan& plan) {
  const calib::BoardImage drawn = calib::DrawBoard(calib::BoardSpec::Parse(plan.board), 100, 50);
  std::vector<std::pair<std::shared_ptr<sim::Scene>, Rigid3d>> placements;
  for (int p = 0; p < plan.placements; ++p) {
    const Rigid3d pose =
        sim::StandCardOnTable(drawn.board_from_pixel, drawn.image.size(),
                              plan.sim_leans_deg[static_cast<std::size_t>(p)], 0.0);
    placements.emplace_back(std::make_shared<sim::Scene>(sim::MakePrintedCardScene(
                                drawn.image, drawn.board_from_pixel, pose)),
                            pose);
  }
  return placements;
}

// The simulated rig: the product model (or the calibration board) on the simulated turntable,
// one simulated camera per elevation, framed for the product.
RigBackends OpenSimRig(const SimCaptureOptions& sim, const std::optional<CalibrationPlan>& plan) {
  auto scene = std::make_shared<sim::Scene>(sim::LoadScene(ResolveScene(sim.scene, sim.data_dir)));
  sim::PlaceOnTurntable(*scene, sim.placement);
  RigBackends rig;
  rig.cam_from_table = sim::MakeSimRig(sim.rig, scene->Bounds());
  std::vector<std::pair<std::shared_ptr<sim::Scene>, Rigid3d>> boards;
  if (plan) {
    boards = SimBoardPlacements(*plan);
    scene = boards.front().first;
  }
  auto turntable = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
  std::vector<sim::SimCamera*> cameras;
  for (std::size_t c = 0; c < rig.cam_from_table.size(); ++c) {
    sim::SimCameraOptions camera_options;
    camera_options.serial = "SIM" + std::to_string(1000 + c);
    camera_options.jpeg_quality = sim.jpeg_quality;
    camera_options.render = sim.render;
    camera_options.render.seed = sim.render.seed * 1000003ULL + c;
    auto camera =
        std::make_unique<sim::SimCamera>(scene, rig.cam_from_table[c], turntable, camera_options);
    cameras.push_back(camera.get());
    rig.cameras.push_back(std::move(camera));
  }
  if (plan) {
    rig.place_board = [cameras, boards](int index) {
      for (sim::SimCamera* camera : cameras)
        camera->SetScene(boards.at(static_cast<std::size_t>(index)).first);
    };
  }
  rig.turntable = turntable;
  rig.plan.stops = sim.stops;
  rig.plan.settle_ms = 0;
  return rig;
}

// The rig's devices; the photos' cameras from the session's calibration when it has one.
RigBackends OpenRig(const RunOptions& options, const std::filesystem::path& calibration) {
  RigBackends rig = options.hardware ? OpenHardwareRig(*options.hardware)
                                     : OpenSimRig(options.sim, options.calibration);
  if (options.hardware && options.calibration) {
    rig.place_board = [place = options.place_board,
                       count = options.calibration->placements](int index) {
      if (place) place(index, count);
    };
  }
  if (!calibration.empty()) {
    const calib::RigCalibration file = calib::ReadRigCalibration(calibration);
    if (file.cameras.size() != rig.cameras.size()) {
      throw FormatError(calibration, "calibrates " + std::to_string(file.cameras.size()) +
                                         " camera(s), the rig has " +
                                         std::to_string(rig.cameras.size()));
    }
    for (std::size_t c = 0; c < rig.cameras.size(); ++c) {
      const CameraModel& calibrated = file.cameras[c].camera;
      const CameraModel& own = rig.cam_from_table[c];
      if (calibrated.width != own.width || calibrated.height != own.height) {
        throw FormatError(calibration, "camera " + std::to_string(c) + " was calibrated for " +
                                           std::to_string(calibrated.width) + "x" +
                                           std::to_string(calibrated.height) +
                                           " photos, it takes " + std::to_string(own.width) + "x" +
                                           std::to_string(own.height));
      }
      rig.cam_from_table[c] = calibrated;
    }
  }
  return rig;
}

// Waits for every future; returns the results, and rethrows the first error only after all
// have finished (no camera is left mid-operation).
template <typename T>
std::vector<std::optional<T>> JoinAll(std::vector<std::future<T>>& futures,
                                      std::exception_ptr* error) {
  std::vector<std::optional<T>> results(futures.size());
  for (std::size_t i = 0; i < futures.size(); ++i) {
    try {
      results[i] = futures[i].get();
    } catch (...) {
      if (!*error) *error = std::current_exception();
    }
  }
  return results;
}

RunResult Continue(const std::filesystem::path& folder, const RunOptions& options, RigBackends& rig,
                   Progress& progress) {
  RunResult result;
  result.session = folder;
  RemoveStaleTemporaries(folder);
  Session session = ReadSession(folder);

  // ---- capture -------------------------------------------------------------------------------
  Stopwatch watch;
  progress.BeginStage("capture");
  const CapturePlan& plan = rig.plan;
  const auto move_timeout =
      std::chrono::milliseconds(static_cast<long long>(plan.move_timeout_s * 1000));
  const auto camera_timeout =
      std::chrono::milliseconds(static_cast<long long>(plan.camera_timeout_s * 1000));
  std::filesystem::create_directories(folder / "images");
  // What is recorded and verified.
  std::map<std::string, SessionView> recorded;
  for (const SessionView& view : session.views) {
    const auto file = folder / view.image;
    if (!view.sha256.empty() && std::filesystem::is_regular_file(file) &&
        FileSha256(file) == view.sha256) {
      recorded[view.image] = view;
      ++result.photos_kept;
    } else {
      if (std::filesystem::exists(file)) MoveAside(file);
      ++result.photos_retaken;
    }
  }
  session.views.clear();
  for (const auto& [name, view] : recorded) session.views.push_back(view);
  const int cameras = static_cast<int>(rig.cameras.size());
  // A calibration session turns the table once per board placement.
  const int placements = options.calibration ? options.calibration->placements : 1;
  const int total_stops = plan.stops * placements;
  const int total = total_stops * cameras;
  int done = static_cast<int>(recorded.size());
  auto record = [&](SessionView view) {
    view.sha256 = FileSha256(folder / view.image);
    session.views.push_back(view);
    // The manifest names the photo only now that it is on disk.
    WriteSessionManifest(folder, session);
    progress.Report(static_cast<std::size_t>(++done), static_cast<std::size_t>(total));
  };
  auto angle_of = [&](int stop) {
    return 2.0 * std::numbers::pi * (stop % plan.stops) / plan.stops;
  };
  bool homed = false;
  int moving_to = -1;  // the stop the table was last sent to
  int placed = -1;     // the board placement in place
  for (int stop = 0; stop < total_stops; ++stop) {
    progress.CheckCancelled();
    const double angle = angle_of(stop);
    std::vector<SessionView> to_take;
    for (int c = 0; c < cameras; ++c) {
      const std::string image = "images/" + ViewStem(c, stop) + ".jpg";
      if (recorded.count(image) != 0) continue;
      SessionView view;
      view.image = image;
      view.camera = c;
      view.stop = stop;
      view.table_angle_deg = 360.0 * (stop % plan.stops) / plan.stops;
      view.camera_model = sim::CameraAtTableAngle(rig.cam_from_table[c], angle);
      const auto file = folder / image;
      if (std::filesystem::exists(file)) {
        // On disk but not recorded: a kill between the download and the manifest.
        if (IsCompletePhoto(file, view.camera_model)) {
          ++result.photos_adopted;
          record(view);
          continue;
        }
        MoveAside(file);
        ++result.photos_retaken;
      }
      to_take.push_back(view);
    }
    if (to_take.empty()) continue;
    if (rig.place_board && stop / plan.stops != placed) {
      placed = stop / plan.stops;
      CAROUSEL_LOG_INFO("board placement " << placed + 1 << " of " << placements);
      rig.place_board(placed);
    }
    if (!homed) {
      rig.turntable->Home(move_timeout);
      homed = true;
      moving_to = -1;
    }
    if (moving_to != stop) rig.turntable->StartMoveTo(angle);
    rig.turntable->WaitUntilStopped(move_timeout);
    if (plan.settle_ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(plan.settle_ms));
    // Every camera of this stop fires at once: triggered through libgphoto2, or released
    // together by the controller's shutter outputs.
    std::vector<std::future<rig::CapturedPhoto>> shots;
    shots.reserve(to_take.size());
    const bool external = static_cast<bool>(rig.release);
    if (external) {
      std::vector<int> released;
      released.reserve(to_take.size());
      for (const SessionView& view : to_take) {
        rig.cameras[view.camera]->PrepareExternalRelease(camera_timeout);
        released.push_back(view.camera);
      }
      rig.release(released);
    }
    for (const SessionView& view : to_take) {
      rig::Camera* camera = rig.cameras[view.camera].get();
      shots.push_back(std::async(std::launch::async, [camera, camera_timeout, external] {
        return external ? camera->WaitForPhoto(camera_timeout) : camera->Capture(camera_timeout);
      }));
    }
    std::exception_ptr error;
    const std::vector<std::optional<rig::CapturedPhoto>> photos = JoinAll(shots, &error);
    // Trigger skew: each camera's trigger time after the first one's at this stop.
    std::optional<std::chrono::steady_clock::time_point> first_trigger;
    for (const auto& photo : photos) {
      if (photo && photo->triggered_at != std::chrono::steady_clock::time_point{} &&
          (!first_trigger || photo->triggered_at < *first_trigger))
        first_trigger = photo->triggered_at;
    }
    double skew_ms = 0.0;
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!photos[i] || !first_trigger ||
          photos[i]->triggered_at == std::chrono::steady_clock::time_point{})
        continue;
      to_take[i].trigger_offset_ms =
          std::chrono::duration<double, std::milli>(photos[i]->triggered_at - *first_trigger)
              .count();
      skew_ms = std::max(skew_ms, to_take[i].trigger_offset_ms);
    }
    result.max_trigger_skew_ms = std::max(result.max_trigger_skew_ms, skew_ms);
    if (to_take.size() > 1)
      CAROUSEL_LOG_INFO("stop " << stop << ": " << to_take.size() << " cameras triggered within "
                                << skew_ms << " ms");
    // The table turns to the next stop while the photos download.
    if (!error && stop + 1 < total_stops) {
      rig.turntable->StartMoveTo(angle_of(stop + 1));
      moving_to = stop + 1;
    }
    std::vector<std::future<int>> downloads;
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!photos[i]) continue;
      rig::Camera* camera = rig.cameras[to_take[i].camera].get();
      const rig::CapturedPhoto photo = *photos[i];
      const std::filesystem::path file = folder / to_take[i].image;
      const bool remove = plan.delete_from_camera;
      downloads.push_back(
          std::async(std::launch::async, [camera, photo, file, remove, camera_timeout] {
            camera->Download(photo, file, remove, camera_timeout);
            return 0;
          }));
    }
    std::size_t d = 0;
    for (std::size_t i = 0; i < to_take.size(); ++i) {
      if (!photos[i]) continue;
      try {
        downloads[d++].get();
        ++result.photos_taken;
        record(to_take[i]);
      } catch (...) {
        if (!error) error = std::current_exception();
      }
    }
    if (error) std::rethrow_exception(error);
  }
  std::sort(session.views.begin(), session.views.end(),
            [](const SessionView& a, const SessionView& b) {
              return std::tie(a.stop, a.camera) < std::tie(b.stop, b.camera);
            });
  const bool capture_changed =
      result.photos_taken + result.photos_adopted + result.photos_retaken > 0;
  if (capture_changed || session.stages["capture"] != "done") {
    session.stages["capture"] = "done";
    if (capture_changed) {
      // New photos make the later stages stale.
      session.stages.erase("reconstruct");
      session.stages.erase("texture");
      session.stages.erase("calibrate");
    }
    WriteSessionManifest(folder, session);
  }
  progress.EndStage();
  result.seconds_capture = watch.ElapsedSeconds();

  // ---- a calibration session: calibrate the rig from the photos --------------------------
  if (options.calibration) {
    session = ReadSession(folder);
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
  const ProcessResult processed =
      ProcessSession(folder, {.reconstruct = reconstruct, .texture = options.texture}, progress);
  result.reconstructed = processed.reconstruct.has_value();
  result.textured = processed.texture.has_value();
  if (processed.texture) result.texture = *processed.texture;
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
  if (calibration) calibration->Validate();
  CAROUSEL_THROW_IF(calibration && !calibration_file.empty(), InvalidArgument,
                    "a calibration session does not take a calibration file");
  if (!calibration_file.empty()) RequireReadableFile(calibration_file);
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
  if (options.calibration && !options.hardware) {
    // The simulated board's height above the plate is known exactly.
    options.calibration->board_origin_height_m =
        (SimBoardPlacements(*options.calibration).front().second * Eigen::Vector3d::Zero()).z();
  }
  const std::filesystem::path folder = options.out / SessionNameForProduct(options.product);
  std::error_code ec;
  if (std::filesystem::exists(folder, ec) && !options.force) {
    throw IoError(folder,
                  "a session of that product exists; `carousel run --resume` continues it, "
                  "--force starts over (the old folder is kept beside it)");
  }
  // Every device answers before anything is written: a missing camera costs nothing.
  RigBackends rig = OpenRig(options, options.calibration_file);
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

RunResult ResumeSession(const std::filesystem::path& session, Progress& progress) {
  if (!std::filesystem::is_directory(session)) throw IoError(session, "is not a session folder");
  RunOptions options = RunFromJson(session / kRunFile);
  options.out = session.parent_path();
  options.Validate();
  RigBackends rig = OpenRig(options, options.calibration_file);
  return Continue(session, options, rig, progress);
}

}  // namespace carousel::studio
