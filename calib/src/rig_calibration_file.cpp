// The RigCalibration file: versioned JSON, written atomically, read with every problem named.
#include <nlohmann/json.hpp>

#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"

namespace carousel::calib {
namespace {

using nlohmann::json;

// The camera's pose field in this file: its cam_from_world is the pose relative to the table.
constexpr const char* kPoseKey = "cam_from_table";

}  // namespace

std::string RigCalibrationToJsonText(const RigCalibration& calibration) {
  json cameras = json::array();
  for (const RigCameraCalibration& c : calibration.cameras) {
    json camera = CameraModelToJson(c.camera, kPoseKey);
    camera["name"] = c.name;
    camera["serial"] = c.serial;
    camera["axis_in_camera"] = {{"direction", Vector3dToJson(c.axis_direction_cam)},
                                {"point", Vector3dToJson(c.axis_point_cam)}};
    camera["views"] = c.views;
    camera["rms_px"] = c.rms_px;
    cameras.push_back(camera);
  }
  json angles = json::array();
  for (const StopAngle& a : calibration.angles) {
    angles.push_back(
        {{"stop", a.stop}, {"reported_deg", a.reported_deg}, {"observed_deg", a.observed_deg}});
  }
  const json j = {{"format", "carousel-rig-calibration"},
                  {"version", calibration.version},
                  {"created_utc", calibration.created_utc},
                  {"board", calibration.board},
                  {"board_origin_height_m", calibration.board_origin_height_m},
                  {"cameras", cameras},
                  {"residuals",
                   {{"rms_px", calibration.rms_px},
                    {"corners", calibration.corners},
                    {"angle_scale", calibration.angle_scale},
                    {"angle_residual_max_deg", calibration.angle_residual_max_deg},
                    {"angles", angles}}}};
  return j.dump(2) + "\n";
}

void WriteRigCalibration(const std::filesystem::path& path, const RigCalibration& calibration) {
  WriteFileAtomic(path, RigCalibrationToJsonText(calibration));
}

RigCalibration ReadRigCalibration(const std::filesystem::path& path) {
  const json j = ParseJsonFile(path);
  const JsonReader read(j, path);
  if (!j.is_object() || read.OptionalString("format") != "carousel-rig-calibration") {
    read.Fail("not a Carousel rig calibration (format is not \"carousel-rig-calibration\")");
  }
  RigCalibration calibration;
  calibration.version = read.Int("version");
  if (calibration.version < 1 || calibration.version > kRigCalibrationVersion) {
    read.Fail("rig calibration version " + std::to_string(calibration.version) +
              " is not supported (this build reads 1.." + std::to_string(kRigCalibrationVersion) +
              ")");
  }
  calibration.created_utc = read.String("created_utc");
  calibration.board = read.String("board");
  calibration.board_origin_height_m = read.Number("board_origin_height_m");
  const std::vector<JsonReader> cameras = read.Array("cameras");
  if (cameras.empty()) read.Fail("cameras is empty: the file calibrates no camera");
  for (const JsonReader& c : cameras) {
    RigCameraCalibration camera;
    camera.name = c.String("name");
    camera.serial = c.String("serial");
    camera.camera = CameraModelFromJson(c, kPoseKey);
    const JsonReader axis = c.Object("axis_in_camera");
    camera.axis_direction_cam = axis.Vector3("direction");
    camera.axis_point_cam = axis.Vector3("point");
    camera.views = c.Int("views");
    camera.rms_px = c.Number("rms_px");
    calibration.cameras.push_back(camera);
  }
  const JsonReader residuals = read.Object("residuals");
  calibration.rms_px = residuals.Number("rms_px");
  calibration.corners = residuals.Int("corners");
  calibration.angle_scale = residuals.Number("angle_scale");
  calibration.angle_residual_max_deg = residuals.Number("angle_residual_max_deg");
  for (const JsonReader& a : residuals.Array("angles")) {
    calibration.angles.push_back(
        {a.Int("stop"), a.Number("reported_deg"), a.Number("observed_deg")});
  }
  return calibration;
}

}  // namespace carousel::calib
