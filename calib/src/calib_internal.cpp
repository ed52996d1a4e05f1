#include "calib_internal.h"

#include <algorithm>
#include <sstream>

#include <opencv2/calib3d.hpp>

namespace carousel::calib::internal {

BoardView MakeBoardView(const BoardSpec& board, const BoardDetection& detection) {
  const std::vector<cv::Point3f> all = board.ObjectPoints();
  BoardView view;
  view.ids = detection.ids;
  view.image = detection.corners;
  view.object.reserve(detection.ids.size());
  for (const int id : detection.ids) view.object.push_back(all[static_cast<std::size_t>(id)]);
  return view;
}

ViewsCalibration CalibrateViews(const std::vector<BoardView>& views, const cv::Size& size,
                                int flags) {
  std::vector<std::vector<cv::Point3f>> object_points;
  std::vector<std::vector<cv::Point2f>> image_points;
  object_points.reserve(views.size());
  image_points.reserve(views.size());
  for (const BoardView& v : views) {
    object_points.push_back(v.object);
    image_points.push_back(v.image);
  }
  ViewsCalibration c;
  c.k = cv::Mat::eye(3, 3, CV_64F);
  c.d = cv::Mat::zeros(5, 1, CV_64F);
  std::vector<cv::Mat> rvecs;
  std::vector<cv::Mat> tvecs;
  cv::Mat std_intrinsics;
  cv::Mat std_extrinsics;
  cv::Mat errors;
  c.rms = cv::calibrateCamera(
      object_points, image_points, size, c.k, c.d, rvecs, tvecs, std_intrinsics, std_extrinsics,
      errors, flags, cv::TermCriteria(cv::TermCriteria::COUNT + cv::TermCriteria::EPS, 100, 1e-12));
  for (std::size_t i = 0; i < c.std_px.size(); ++i) {
    c.std_px[i] = std_intrinsics.at<double>(static_cast<int>(i));
  }
  c.per_view_rms.resize(views.size());
  for (std::size_t i = 0; i < views.size(); ++i) {
    c.per_view_rms[i] = errors.at<double>(static_cast<int>(i));
    c.rvecs.emplace_back(rvecs[i]);
    c.tvecs.emplace_back(tvecs[i]);
  }
  return c;
}

CameraModel CameraFromCv(const cv::Mat& k, const cv::Mat& d, const cv::Size& size) {
  CameraModel camera;
  camera.width = size.width;
  camera.height = size.height;
  camera.fx = k.at<double>(0, 0);
  camera.fy = k.at<double>(1, 1);
  camera.cx = k.at<double>(0, 2);
  camera.cy = k.at<double>(1, 2);
  camera.distortion.k1 = d.at<double>(0);
  camera.distortion.k2 = d.at<double>(1);
  camera.distortion.p1 = d.at<double>(2);
  camera.distortion.p2 = d.at<double>(3);
  if (d.total() > 4) camera.distortion.k3 = d.at<double>(4);
  return camera;
}

double Median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

std::string Fixed(double value, int digits) {
  std::ostringstream out;
  out.setf(std::ios::fixed);
  out.precision(digits);
  out << value;
  return out.str();
}

}  // namespace carousel::calib::internal
