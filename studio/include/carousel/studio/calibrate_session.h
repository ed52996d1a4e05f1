// Calibration in the studio: `carousel calibrate intrinsics IMAGES...`, `carousel calibrate rig
// SESSION` and the calibration stage of a calibration session (`carousel run --calibration`):
// the table turns with a board standing on it, once per board placement, every camera
// photographs it at every stop, and the photos become <session>/calibration/rig_calibration.json
// (calib/rig_calibration.h), which later sessions use for their photos' cameras
// (`carousel run --calibration-file FILE`, or "calibration_file" in rig.json).
//
// A calibration session's views are numbered stop = placement * stops_per_placement + s, the
// table at 360 * s / stops_per_placement degrees.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "carousel/calib/rig_calibration.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::studio {

// How a calibration session is captured (recorded in its run.json).
struct CalibrationPlan {
  // The board on the table (calib::BoardSpec's text).
  std::string board = "charuco:9x7:0.04:0.03:DICT_6X6_250";
  // Passes of the table, the board placed anew before each (1..8): leaning at two angles pins
  // the lens far better than one.
  int placements = 2;
  // The simulated rig: how far the board leans back from vertical in each pass, degrees.
  std::vector<double> sim_leans_deg = {30.0, 60.0};
  // Height of the first placement's board origin above the plate's top surface, metres;
  // < 0: not known yet (the simulated rig knows it; a real rig needs it measured).
  double board_origin_height_m = -1.0;
  // The description of the fields a person sets (core/options.h).
  static const OptionTable<CalibrationPlan>& Fields();
  void Validate() const;
};

struct CalibrateSessionOptions {
  std::string board;                            // empty: the session's plan's
  std::optional<double> board_origin_height_m;  // unset: the session's plan's
  int stops_per_placement = 0;                  // 0: the session's plan's (or one placement)
  // Per camera index, optional: intrinsics calibrated beforehand (calib::ReadIntrinsics: .json
  // or OpenCV YAML/XML; used as the
  // start, held fixed unless rig.refine_intrinsics).
  std::vector<std::filesystem::path> intrinsics;
  calib::RigCalibrationOptions rig;
};

struct CalibrateSessionResult {
  calib::RigCalibrationResult result;
  std::filesystem::path file;  // where the calibration was written
};

// Calibrates the rig from a session's photos and writes `out` (default
// <session>/calibration/rig_calibration.json) atomically, then records the stage
// ("calibrate": "done") in the manifest. \throw InvalidArgument with every refused photo's
// reason (no board, a camera that never sees it, angles that disagree), IoError/FormatError
// naming the file at fault.
CalibrateSessionResult CalibrateSession(const std::filesystem::path& session,
                                        const CalibrateSessionOptions& options,
                                        const std::filesystem::path& out, Progress& progress);

// The plan as run.json stores it, and back. \throw FormatError naming `file`.
nlohmann::json CalibrationPlanToJson(const CalibrationPlan& plan);
CalibrationPlan CalibrationPlanFromJson(const nlohmann::json& value,
                                        const std::filesystem::path& file);

// The plan a calibration session was captured with, from its run.json, and its stops per
// placement; nullopt for a session that is not one. \throw FormatError for a malformed run.json.
std::optional<CalibrationPlan> ReadCalibrationPlan(const std::filesystem::path& session,
                                                   int* stops_per_placement);

}  // namespace carousel::studio
