// calib: the rig calibration. A board stands (or lies) on the turntable; every camera
// photographs it at several table angles. From those photos: each camera's intrinsics and its
// pose `cam_from_table`, so that a photo at table angle theta has
//   cam_from_world = cam_from_table * Rz(theta)        (world = turntable frame, DESIGN.md)
// and the turntable axis in every camera. Everything is refined jointly by bundle adjustment
// (Ceres, Huber loss): intrinsics and distortion, camera poses, the board's pose on the table
// and the true table angle of every stop; the table's reported angles are then checked
// against the board's observed rotation (lost steps or a wrong gear ratio show there).
//
// Frames: the table frame's +Z is the rotation axis, its origin on the axis at the plate's top
// surface; its X axis is fixed by the board: the board's x axis at table angle 0, projected
// onto the plate, points along +X (its y axis when x stands upright). The height of the
// board's origin above the plate (`board_origin_height_m`: the board's thickness when it lies
// flat) pins the origin, which no photo of a turning board can tell.
//
// The RigCalibration file is versioned JSON (format "carousel-rig-calibration", version 1):
// per camera its intrinsics, distortion, image size and cam_from_table, the axis in its frame,
// its residuals; the board, the stops' reported and observed angles, the date.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/calib/board.h"
#include "carousel/core/camera_model.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::calib {

inline constexpr int kRigCalibrationVersion = 1;

struct RigCameraCalibration {
  std::string name;    // "cam0", or the rig's name for the camera
  std::string serial;  // the camera body's serial, when known
  CameraModel camera;  // intrinsics, distortion, size; cam_from_world = cam_from_table
  Eigen::Vector3d axis_direction_cam = Eigen::Vector3d::UnitZ();  // table +Z in camera frame
  Eigen::Vector3d axis_point_cam = Eigen::Vector3d::Zero();       // table origin, camera frame
  int views = 0;                                                  // photos used
  double rms_px = 0.0;                                            // reprojection RMS over them
};

struct StopAngle {
  int stop = 0;
  double reported_deg = 0.0;  // what the turntable said
  double observed_deg = 0.0;  // what the board's rotation says (same zero as reported)
};

struct RigCalibration {
  int version = kRigCalibrationVersion;
  std::string created_utc;
  std::string board;  // BoardSpec::ToString()
  double board_origin_height_m = 0.0;
  std::vector<RigCameraCalibration> cameras;
  double rms_px = 0.0;  // over every corner used
  int corners = 0;      // corners used
  std::vector<StopAngle> angles;
  // Observed against reported angle: observed = reported * angle_scale + offset; a scale
  // other than 1 is a wrong gear ratio, a residual a lost step.
  double angle_scale = 1.0;
  double angle_residual_max_deg = 0.0;

  // The camera of a photo by camera `index` at table angle `table_angle_rad`.
  // \throw InvalidArgument for an index out of range.
  CameraModel CameraAt(int index, double table_angle_rad) const;
};

// One photo of the board on the turntable.
struct RigPhoto {
  std::string name;  // in reports: the file name, or "cam0_stop03"
  int camera = 0;    // >= 0
  int stop = 0;      // photos of one stop share its table angle
  // Where the board stood for this photo: a session may turn the table with the board leaning
  // one way, then again with it placed otherwise (more orientations pin the lens better).
  // Stops are numbered across placements. >= 0; placement 0 fixes the table's X axis.
  int placement = 0;
  double table_angle_rad = 0.0;  // as the turntable reported it
  cv::Mat image;                 // 8-bit grey or BGR; empty: read `path`
  std::filesystem::path path;
};

struct RigCalibrationOptions {
  DetectOptions detect;
  // Height of the board frame's origin above the plate's top surface, metres (a board printed
  // and lying flat: its thickness). >= 0 (a board may also stand on a base).
  double board_origin_height_m = 0.0;
  // Intrinsics are estimated from these photos (OpenCV) and refined with the rest; with
  // `refine_intrinsics` false, given intrinsics (CalibrateRig's argument) stay fixed.
  bool refine_intrinsics = true;
  // k3 = 0: a normal lens needs no r^6 term, and boards seen mostly in the middle of the image
  // make k2 and k3 trade off wildly (k2 5, k3 -230 on the simulated rig) when both are free.
  bool fix_k3 = true;
  bool zero_tangential = false;  // p1 = p2 = 0
  int min_views_per_camera = 4;  // usable photos each camera needs (>= 3)
  double huber_px = 1.0;         // robust loss scale, pixels (> 0)
  // A photo whose reprojection RMS after adjustment exceeds
  // max(outlier_factor * median photo RMS, outlier_floor_px) is dropped and the adjustment
  // repeated (a board that slipped, a wrong detection).
  double outlier_factor = 5.0;
  double outlier_floor_px = 1.0;
  // Failures rather than a silently bad calibration: a reported table angle further than this
  // from the board's observed rotation (after the best common offset), degrees, and a final
  // reprojection RMS above max_rms_px.
  double max_angle_error_deg = 0.5;
  double max_rms_px = 1.0;
  int threads = 0;  // 0 = one per hardware thread
  // The description of the fields a person sets (core/options.h).
  static const OptionTable<RigCalibrationOptions>& Fields();
  void Validate() const;
};

struct RigPhotoReport {
  std::string name;
  int camera = 0;
  int stop = 0;
  bool used = false;
  std::string reason;  // why not, when !used
  int corners = 0;
  double rms_px = 0.0;  // after adjustment, when used
};

struct RigCalibrationResult {
  RigCalibration calibration;
  std::vector<RigPhotoReport> photos;     // one per input photo, in input order
  std::vector<Rigid3d> table_from_board;  // where the board stood, per placement
  int iterations = 0;                     // of the final adjustment
  std::vector<std::string> warnings;
};

// \param intrinsics per camera index, optional: a camera calibrated beforehand (its pose is
//        ignored). Cameras without it are calibrated from these photos.
// \throw InvalidArgument when a camera has too few usable photos (naming it, with every
//        photo's reason), when the table's angles disagree with the board's rotation (naming
//        the stops), or when the result reprojects worse than options.max_rms_px.
RigCalibrationResult CalibrateRig(const std::vector<RigPhoto>& photos, const BoardSpec& board,
                                  const std::vector<std::optional<CameraModel>>& intrinsics,
                                  const RigCalibrationOptions& options, Progress& progress);

// Atomic write. \throw IoError.
void WriteRigCalibration(const std::filesystem::path& path, const RigCalibration& calibration);
// \throw IoError (missing) or FormatError naming the file and the field.
RigCalibration ReadRigCalibration(const std::filesystem::path& path);
std::string RigCalibrationToJsonText(const RigCalibration& calibration);

}  // namespace carousel::calib
