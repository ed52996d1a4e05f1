#include "carousel/studio/calibrate_session.h"

#include <numbers>

#include <nlohmann/json.hpp>

#include "carousel/calib/intrinsics.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"
#include "carousel/core/logging.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

using json = nlohmann::json;

}  // namespace

const OptionTable<CalibrationPlan>& CalibrationPlan::Fields() {
  using O = CalibrationPlan;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::board, {.name = "board",
                      .help = "calibration: the board (chessboard:COLSxROWS:SQUARE_M or "
                              "charuco:SXxSY:SQUARE_M:MARKER_M:DICT)"});
    t.Add(&O::placements,
          {.name = "placements",
           .help = "calibration: passes of the table, the board placed anew for each",
           .min = 1,
           .max = 8});
    t.Add(&O::sim_leans_deg,
          {.name = "leans",
           .help = "calibration, simulated rig: the board's lean back from vertical per pass",
           .unit = "deg",
           .min = 0,
           .max = 80});
    t.Add(&O::board_origin_height_m,
          {.name = "board-height",
           .help = "calibration on hardware: height of the board's origin (first corner) above "
                   "the plate in the first placement",
           .unit = "m",
           .min = 0,
           .max = 1,
           .special = -1,
           .special_meaning = "not known (the simulated rig knows it)"});
    return t;
  }();
  return table;
}

void CalibrationPlan::Validate() const {
  calib::BoardSpec::Parse(board);
  Fields().Check(*this);
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
  // run.json holds the plan as its "calibration".
  const JsonReader read(value, file, "calibration");
  CalibrationPlan plan;
  plan.board = read.String("board");
  plan.placements = read.Int("placements");
  plan.sim_leans_deg = read.Numbers("sim_leans_deg");
  plan.board_origin_height_m = read.Number("board_origin_height_m");
  try {
    plan.Validate();
  } catch (const InvalidArgument& e) {
    read.Fail(read.Name() + ": " + e.what());
  }
  return plan;
}

std::optional<CalibrationPlan> ReadCalibrationPlan(const std::filesystem::path& session,
                                                   int* stops_per_placement) {
  const std::filesystem::path path = session / "run.json";
  if (!std::filesystem::is_regular_file(path)) return std::nullopt;
  const json run = ParseJsonFile(path);
  const JsonReader read(run, path);
  if (!read.Has("calibration")) return std::nullopt;
  CalibrationPlan plan = CalibrationPlanFromJson(run.at("calibration"), path);
  *stops_per_placement = read.String("backend") == "hardware"
                             ? read.Object("rig").Object("capture").Int("stops")
                             : read.Object("sim").Int("stops");
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
      intrinsics.emplace_back(calib::ReadIntrinsics(file));
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
