#include "carousel/studio/calibrate_session.h"

#include <fstream>
#include <numbers>

#include <nlohmann/json.hpp>

#include "carousel/calib/intrinsics.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/logging.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

using json = nlohmann::json;

}  // namespace

void CalibrationPlan::Validate() const {
  calib::BoardSpec::Parse(board);
  CAROUSEL_THROW_IF(placements < 1 || placements > 8, InvalidArgument,
                    "a calibration takes 1..8 board placements, not " << placements);
  CAROUSEL_THROW_IF(
      static_cast<int>(sim_leans_deg.size()) < placements, InvalidArgument,
      "the simulated calibration needs a lean for each of its " << placements << " placements");
  for (const double lean : sim_leans_deg) {
    CAROUSEL_THROW_IF(!(lean >= 0 && lean <= 80), InvalidArgument,
                      "a board lean must be 0..80 degrees from vertical, not " << lean);
  }
}

json CalibrationPlanToJson(const CalibrationPlan& plan) {
  return {{"board", plan.board},
          {"placements", plan.placements},
          {"sim_leans_deg", plan.sim_leans_deg},
          {"board_origin_height_m", plan.board_origin_height_m}};
}

CalibrationPlan CalibrationPlanFromJson(const json& value, const std::filesystem::path& file) {
  CalibrationPlan plan;
  try {
    plan.board = value.at("board").get<std::string>();
    plan.placements = value.at("placements").get<int>();
    plan.sim_leans_deg = value.at("sim_leans_deg").get<std::vector<double>>();
    plan.board_origin_height_m = value.at("board_origin_height_m").get<double>();
    plan.Validate();
  } catch (const json::exception& e) {
    throw FormatError(file, std::string("malformed calibration plan: ") + e.what());
  } catch (const InvalidArgument& e) {
    throw FormatError(file, e.what());
  }
  return plan;
}

std::optional<CalibrationPlan> ReadCalibrationPlan(const std::filesystem::path& session,
                                                   int* stops_per_placement) {
  const std::filesystem::path path = session / "run.json";
  if (!std::filesystem::is_regular_file(path)) return std::nullopt;
  json run;
  try {
    std::ifstream in(path);
    run = json::parse(in);
  } catch (const json::exception& e) {
    throw FormatError(path, std::string("not valid JSON: ") + e.what());
  }
  if (!run.contains("calibration")) return std::nullopt;
  CalibrationPlan plan = CalibrationPlanFromJson(run["calibration"], path);
  try {
    *stops_per_placement = run.at("backend") == "hardware"
                               ? run.at("rig").at("capture").at("stops").get<int>()
                               : run.at("sim").at("stops").get<int>();
  } catch (const json::exception& e) {
    throw FormatError(path, std::string("has no stop count: ") + e.what());
  }
  return plan;
}

CalibrateSessionResult CalibrateSession(const std::filesystem::path& folder,
                                        const CalibrateSessionOptions& options,
                                        const std::filesystem::path& out_in, Progress& progress) {
  Session session = ReadSession(folder);
  CAROUSEL_THROW_IF(session.views.empty(), InvalidArgument,
                    folder.string() << ": the session has no photos to calibrate from");
  int planned_stops = 0;
  const std::optional<CalibrationPlan> plan = ReadCalibrationPlan(folder, &planned_stops);
  std::string board_text = options.board;
  if (board_text.empty() && plan) board_text = plan->board;
  CAROUSEL_THROW_IF(board_text.empty(), InvalidArgument,
                    folder.string() << " is not a calibration session: name its board (--board "
                                       "charuco:SXxSY:SQUARE_M:MARKER_M:DICT)");
  const calib::BoardSpec board = calib::BoardSpec::Parse(board_text);
  calib::RigCalibrationOptions rig = options.rig;
  if (options.board_origin_height_m) {
    rig.board_origin_height_m = *options.board_origin_height_m;
  } else if (plan && plan->board_origin_height_m >= 0) {
    rig.board_origin_height_m = plan->board_origin_height_m;
  } else {
    CAROUSEL_LOG_WARN(folder.string() << ": the board's height above the plate is not known; "
                                         "taking 0 (--board-height sets it)");
  }
  int stops = options.stops_per_placement > 0 ? options.stops_per_placement : planned_stops;
  int last_stop = 0;
  for (const SessionView& v : session.views) last_stop = std::max(last_stop, v.stop);
  if (stops <= 0) stops = last_stop + 1;

  std::vector<calib::RigPhoto> photos;
  for (const SessionView& v : session.views) {
    calib::RigPhoto photo;
    photo.name = std::filesystem::path(v.image).filename().string();
    photo.camera = v.camera;
    photo.stop = v.stop;
    photo.placement = v.stop / stops;
    photo.table_angle_rad = v.table_angle_deg * std::numbers::pi / 180.0;
    photo.path = folder / v.image;
    photos.push_back(photo);
  }
  std::vector<std::optional<CameraModel>> intrinsics;
  for (const std::filesystem::path& file : options.intrinsics) {
    if (file.empty()) {
      intrinsics.emplace_back();
    } else {
      intrinsics.emplace_back(calib::ReadOpenCvIntrinsics(file));
    }
  }
  CalibrateSessionResult result;
  result.result = calib::CalibrateRig(photos, board, intrinsics, rig, progress);
  calib::RigCalibration& calibration = result.result.calibration;
  calibration.created_utc = NowUtc();
  result.file = out_in.empty() ? folder / "calibration" / "rig_calibration.json" : out_in;
  std::error_code ec;
  if (!result.file.parent_path().empty()) {
    std::filesystem::create_directories(result.file.parent_path(), ec);
    if (ec) throw IoError(result.file.parent_path(), "cannot create folder: " + ec.message());
  }
  calib::WriteRigCalibration(result.file, calibration);
  // Each camera's intrinsics also as OpenCV's YAML, beside the file.
  for (const calib::RigCameraCalibration& camera : calibration.cameras) {
    calib::WriteOpenCvIntrinsics(result.file.parent_path() / (camera.name + ".yml"), camera.camera,
                                 camera.rms_px);
  }
  session = ReadSession(folder);
  session.stages["calibrate"] = "done";
  WriteSessionManifest(folder, session);
  return result;
}

}  // namespace carousel::studio
