// The RigCalibration file: versioned JSON, written atomically, read with every problem named.
#include <fstream>

#include <nlohmann/json.hpp>

#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel::calib {
namespace {

using nlohmann::json;

json Vector(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

class Reader {
 public:
  explicit Reader(std::filesystem::path path) : path_(std::move(path)) {}
  [[noreturn]] void Fail(const std::string& what) const { throw FormatError(path_, what); }
  const json& Field(const json& object, const char* key, const std::string& where) const {
    if (!object.is_object() || !object.contains(key)) Fail(where + " has no field '" + key + "'");
    return object.at(key);
  }
  double Number(const json& object, const char* key, const std::string& where) const {
    const json& v = Field(object, key, where);
    if (!v.is_number()) Fail(where + "." + key + " is not a number");
    return v.get<double>();
  }
  int Integer(const json& object, const char* key, const std::string& where) const {
    const json& v = Field(object, key, where);
    if (!v.is_number_integer()) Fail(where + "." + key + " is not a whole number");
    return v.get<int>();
  }
  std::string String(const json& object, const char* key, const std::string& where) const {
    const json& v = Field(object, key, where);
    if (!v.is_string()) Fail(where + "." + key + " is not a string");
    return v.get<std::string>();
  }
  std::vector<double> Numbers(const json& object, const char* key, std::size_t count,
                              const std::string& where) const {
    const json& v = Field(object, key, where);
    if (!v.is_array() || v.size() != count) {
      Fail(where + "." + key + " is not a list of " + std::to_string(count) + " numbers");
    }
    std::vector<double> out;
    for (const json& x : v) {
      if (!x.is_number()) Fail(where + "." + key + " holds something that is not a number");
      out.push_back(x.get<double>());
    }
    return out;
  }

 private:
  std::filesystem::path path_;
};

}  // namespace

std::string RigCalibrationToJsonText(const RigCalibration& calibration) {
  json cameras = json::array();
  for (const RigCameraCalibration& c : calibration.cameras) {
    const CameraModel& m = c.camera;
    json rotation = json::array();
    for (int r = 0; r < 3; ++r) {
      for (int k = 0; k < 3; ++k) rotation.push_back(m.cam_from_world.rotation(r, k));
    }
    cameras.push_back(
        {{"name", c.name},
         {"serial", c.serial},
         {"width", m.width},
         {"height", m.height},
         {"fx", m.fx},
         {"fy", m.fy},
         {"cx", m.cx},
         {"cy", m.cy},
         {"distortion",
          {m.distortion.k1, m.distortion.k2, m.distortion.p1, m.distortion.p2, m.distortion.k3}},
         {"cam_from_table",
          {{"rotation_row_major", rotation},
           {"translation", Vector(m.cam_from_world.translation)}}},
         {"axis_in_camera",
          {{"direction", Vector(c.axis_direction_cam)}, {"point", Vector(c.axis_point_cam)}}},
         {"views", c.views},
         {"rms_px", c.rms_px}});
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
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  json j;
  try {
    j = json::parse(bytes.begin(), bytes.end());
  } catch (const json::parse_error& e) {
    throw FormatError(path, std::string("not valid JSON: ") + e.what());
  }
  const Reader read(path);
  if (!j.is_object() || !j.contains("format") || j["format"] != "carousel-rig-calibration") {
    read.Fail("not a Carousel rig calibration (format is not \"carousel-rig-calibration\")");
  }
  RigCalibration calibration;
  calibration.version = read.Integer(j, "version", "calibration");
  if (calibration.version < 1 || calibration.version > kRigCalibrationVersion) {
    read.Fail("rig calibration version " + std::to_string(calibration.version) +
              " is not supported (this build reads 1.." + std::to_string(kRigCalibrationVersion) +
              ")");
  }
  calibration.created_utc = read.String(j, "created_utc", "calibration");
  calibration.board = read.String(j, "board", "calibration");
  calibration.board_origin_height_m = read.Number(j, "board_origin_height_m", "calibration");
  const json& cameras = read.Field(j, "cameras", "calibration");
  if (!cameras.is_array() || cameras.empty())
    read.Fail("calibration.cameras is not a list of cameras");
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    const std::string where = "cameras[" + std::to_string(i) + "]";
    const json& c = cameras[i];
    RigCameraCalibration camera;
    camera.name = read.String(c, "name", where);
    camera.serial = read.String(c, "serial", where);
    CameraModel& m = camera.camera;
    m.width = read.Integer(c, "width", where);
    m.height = read.Integer(c, "height", where);
    m.fx = read.Number(c, "fx", where);
    m.fy = read.Number(c, "fy", where);
    m.cx = read.Number(c, "cx", where);
    m.cy = read.Number(c, "cy", where);
    const std::vector<double> d = read.Numbers(c, "distortion", 5, where);
    m.distortion = {d[0], d[1], d[2], d[3], d[4]};
    const json& pose = read.Field(c, "cam_from_table", where);
    const std::vector<double> r =
        read.Numbers(pose, "rotation_row_major", 9, where + ".cam_from_table");
    const std::vector<double> t = read.Numbers(pose, "translation", 3, where + ".cam_from_table");
    for (int k = 0; k < 9; ++k) m.cam_from_world.rotation(k / 3, k % 3) = r[k];
    m.cam_from_world.translation = Eigen::Vector3d(t[0], t[1], t[2]);
    const json& axis = read.Field(c, "axis_in_camera", where);
    const std::vector<double> dir = read.Numbers(axis, "direction", 3, where + ".axis_in_camera");
    const std::vector<double> point = read.Numbers(axis, "point", 3, where + ".axis_in_camera");
    camera.axis_direction_cam = Eigen::Vector3d(dir[0], dir[1], dir[2]);
    camera.axis_point_cam = Eigen::Vector3d(point[0], point[1], point[2]);
    camera.views = read.Integer(c, "views", where);
    camera.rms_px = read.Number(c, "rms_px", where);
    try {
      m.Validate();
    } catch (const InvalidArgument& e) {
      read.Fail(where + ": " + e.what());
    }
    calibration.cameras.push_back(camera);
  }
  const json& residuals = read.Field(j, "residuals", "calibration");
  calibration.rms_px = read.Number(residuals, "rms_px", "residuals");
  calibration.corners = read.Integer(residuals, "corners", "residuals");
  calibration.angle_scale = read.Number(residuals, "angle_scale", "residuals");
  calibration.angle_residual_max_deg =
      read.Number(residuals, "angle_residual_max_deg", "residuals");
  const json& angles = read.Field(residuals, "angles", "residuals");
  if (!angles.is_array()) read.Fail("residuals.angles is not a list");
  for (std::size_t i = 0; i < angles.size(); ++i) {
    const std::string where = "residuals.angles[" + std::to_string(i) + "]";
    calibration.angles.push_back({read.Integer(angles[i], "stop", where),
                                  read.Number(angles[i], "reported_deg", where),
                                  read.Number(angles[i], "observed_deg", where)});
  }
  return calibration;
}

}  // namespace carousel::calib
