// calib's private helpers: one board view as point correspondences, OpenCV's calibration over
// such views, and small formatting helpers shared by the calibration stages.
#pragma once

#include <array>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/calib/board.h"
#include "carousel/core/camera_model.h"

namespace carousel::calib::internal {

// A detected board as correspondences: board-frame corners and their image positions.
struct BoardView {
  std::vector<int> ids;
  std::vector<cv::Point3f> object;
  std::vector<cv::Point2f> image;
};
BoardView MakeBoardView(const BoardSpec& board, const BoardDetection& detection);

struct ViewsCalibration {
  cv::Mat k;  // 3x3, CV_64F
  cv::Mat d;  // 5x1: k1 k2 p1 p2 k3
  double rms = 0.0;
  std::vector<double> per_view_rms;
  std::vector<cv::Vec3d> rvecs, tvecs;  // cam_from_board per view (OpenCV's rvec/tvec)
  // One standard deviation of fx, fy, cx, cy (px), from the Jacobian at the solution
  // (OpenCV's stdDeviationsIntrinsics); 0 for a held parameter.
  std::array<double, 4> std_px{};
};
// cv::calibrateCamera over the views (planar boards; OpenCV's flags).
ViewsCalibration CalibrateViews(const std::vector<BoardView>& views, const cv::Size& size,
                                int flags);

// A camera from OpenCV's camera matrix and 4 or 5 distortion coefficients (k3 = 0 when 4).
CameraModel CameraFromCv(const cv::Mat& k, const cv::Mat& d, const cv::Size& size);

double Median(std::vector<double> values);
std::string Fixed(double value, int digits);

}  // namespace carousel::calib::internal
