// calib: camera intrinsics from photos of a chessboard or a ChArUco board (board.h).
//
//   BoardSpec board = BoardSpec::Parse("charuco:5x7:0.04:0.03:DICT_6X6_250");
//   IntrinsicsResult r = CalibrateIntrinsics(image_paths, board, IntrinsicsOptions{}, progress);
//   WriteIntrinsics("left.yml", r, board);   // the YAML of OpenCV's calibration sample
//   WriteIntrinsics("left.json", r, board);  // or JSON: the camera as session.json has it
//
// Every photo is either used or rejected with a reason (unreadable, no board, too few corners,
// board too small, blurred, reprojection outlier); the result says how well the views cover the
// image, since a board never seen near the corners leaves the distortion there unconstrained.
// Lens model: OpenCV's (k1, k2, p1, p2, k3), as CameraModel. With few views the terms the
// photos cannot constrain are held at zero (k3 below 10 views; k2 too when the corners stay
// near the image centre), and the result gives each of fx, fy, cx, cy with its standard
// deviation, warning when the calibration is weak.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/calib/board.h"
#include "carousel/core/camera_model.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::calib {

struct IntrinsicsOptions {
  DetectOptions detect;
  int min_views = 3;              // fewer usable views is an error (>= 1)
  bool fix_aspect_ratio = false;  // fx == fy (square pixels)
  bool zero_tangential = false;   // p1 = p2 = 0
  bool fix_k3 = false;            // k3 = 0 (narrow lenses; avoids over-fitting)
  // Hold what few views cannot constrain: k3 = 0 with fewer than kFewViews usable views, and
  // k2 = 0 as well when the corners reach less than kNearCentreReach of the way from the image
  // centre to its corners.
  bool hold_weak_terms = true;
  static constexpr int kFewViews = 10;
  static constexpr double kNearCentreReach = 0.5;
  // Weak: a standard deviation of fx or fy above this fraction of it, or of cx or cy above
  // this fraction of the image's width or height.
  double weak_fraction = 0.01;
  // After a first calibration, a view whose reprojection RMS exceeds
  // max(outlier_factor * median view RMS, outlier_floor_px) is rejected and the calibration
  // repeated without it (a moved board, a wrong corner order). outlier_factor <= 0: never.
  double outlier_factor = 4.0;
  double outlier_floor_px = 0.5;
  // The description of the fields a person sets (core/options.h).
  static const OptionTable<IntrinsicsOptions>& Fields();
  void Validate() const;
};

struct ViewReport {
  std::string name;  // the file (or the name given with the image)
  bool used = false;
  std::string reason;   // why it was rejected, when !used
  double rms_px = 0.0;  // its reprojection RMS, when used
  int corners = 0;
};

struct IntrinsicsResult {
  CameraModel camera;   // intrinsics and distortion; cam_from_world is the identity
  double rms_px = 0.0;  // overall reprojection RMS of the used views
  std::vector<ViewReport> views;
  // Coverage: the image divided into 3 x 3 cells, the fraction of cells holding at least one
  // detected corner, and whether all four corner cells do.
  double cell_coverage = 0.0;
  bool corners_covered = false;
  // The farthest corner's distance from the image centre / half the image diagonal.
  double corner_reach = 0.0;
  // The lens terms held at zero, by the options or because the views cannot constrain them
  // ("k3", "k2", "p1 p2").
  std::vector<std::string> held;
  // One standard deviation of fx, fy, cx, cy (px), from the Jacobian at the solution.
  double std_fx = 0.0, std_fy = 0.0, std_cx = 0.0, std_cy = 0.0;
  bool weak = false;  // a standard deviation beyond IntrinsicsOptions::weak_fraction
  std::vector<std::string> warnings;  // e.g. the image corners were never seen
  int UsedViews() const;
};

// A photo in memory, with the name its reports use.
struct NamedImage {
  std::string name;
  cv::Mat image;
};

// Calibrates from photos in memory. All images must have the same size.
// \throw InvalidArgument when fewer than options.min_views views are usable; the message lists
// every view's reason.
IntrinsicsResult CalibrateIntrinsics(const std::vector<NamedImage>& images, const BoardSpec& board,
                                     const IntrinsicsOptions& options, Progress& progress);
// Calibrates from image files; a file that cannot be read is a rejected view (named, with the
// reason), not an error, as long as enough other views remain.
IntrinsicsResult CalibrateIntrinsics(const std::vector<std::filesystem::path>& images,
                                     const BoardSpec& board, const IntrinsicsOptions& options,
                                     Progress& progress);

// By the extension of `path`: .json writes {"camera": CameraModelToJson without a pose,
// "rms_px", "std_px": {fx, fy, cx, cy}, "held", "weak", "board", "views": [...], "warnings"};
// .yml, .yaml and .xml write OpenCV's file (WriteOpenCvIntrinsics). Atomically.
// \throw InvalidArgument for another extension.
void WriteIntrinsics(const std::filesystem::path& path, const IntrinsicsResult& result,
                     const BoardSpec& board);
// The check WriteIntrinsics makes of the extension, to fail before calibrating.
// \throw InvalidArgument.
void CheckIntrinsicsPath(const std::filesystem::path& path);
// The camera of a file WriteIntrinsics wrote (.json), or of OpenCV's YAML/XML (any other).
// \throw FormatError naming the file and what is wrong.
CameraModel ReadIntrinsics(const std::filesystem::path& path);

// OpenCV's calibration YAML (image_width, image_height, camera_matrix,
// distortion_coefficients, avg_reprojection_error, ...; XML for a .xml path), written
// atomically.
void WriteOpenCvIntrinsics(const std::filesystem::path& path, const IntrinsicsResult& result,
                           const BoardSpec& board);
// A camera's intrinsics alone in the same YAML (image size, camera_matrix,
// distortion_coefficients, avg_reprojection_error), e.g. a rig calibration's camera.
void WriteOpenCvIntrinsics(const std::filesystem::path& path, const CameraModel& camera,
                           double rms_px);
// Reads camera_matrix, distortion_coefficients (4, 5 or more; only k1 k2 p1 p2 k3 are kept,
// more is an error unless they are zero) and the image size.
// \throw FormatError naming the file and the missing or malformed node.
CameraModel ReadOpenCvIntrinsics(const std::filesystem::path& path);

}  // namespace carousel::calib
