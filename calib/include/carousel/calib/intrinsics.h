// calib: camera intrinsics from photos of a chessboard or a ChArUco board (board.h).
//
//   BoardSpec board = BoardSpec::Parse("charuco:5x7:0.04:0.03:DICT_6X6_250");
//   IntrinsicsResult r = CalibrateIntrinsics(image_paths, board, IntrinsicsOptions{}, progress);
//   WriteOpenCvIntrinsics("left.yml", r);   // the YAML of OpenCV's calibration sample
//
// Every photo is either used or rejected with a reason (unreadable, no board, too few corners,
// board too small, blurred, reprojection outlier); the result says how well the views cover the
// image, since a board never seen near the corners leaves the distortion there unconstrained.
// Lens model: OpenCV's (k1, k2, p1, p2, k3), as CameraModel.
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

// OpenCV's calibration YAML (image_width, image_height, camera_matrix,
// distortion_coefficients, avg_reprojection_error, ...), written atomically.
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
