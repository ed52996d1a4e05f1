#include "carousel/recon/reprojection.h"

#include <algorithm>
#include <cmath>
#include <optional>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/parallel.h"
#include "carousel/core/raster.h"

namespace carousel::recon {

cv::Mat RasterizeSilhouette(const Mesh& mesh, const CameraModel& camera) {
  cv::Mat silhouette = cv::Mat::zeros(camera.height, camera.width, CV_8UC1);
  std::vector<std::optional<Eigen::Vector2d>> pixels(mesh.n_vertices());
  for (const auto v : mesh.vertices()) {
    const auto& p = mesh.point(v);
    pixels[v.idx()] = camera.Project(Eigen::Vector3d(p[0], p[1], p[2]));
  }
  for (const auto f : mesh.faces()) {
    std::array<Eigen::Vector2d, 3> t;
    int k = 0;
    bool visible = true;
    for (const auto v : mesh.fv_range(f)) {
      if (k == 3 || !pixels[v.idx()]) {
        visible = false;
        break;
      }
      t[k++] = *pixels[v.idx()];
    }
    if (!visible || k != 3) continue;
    const double area =
        (t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x();
    if (std::abs(area) < 1e-12) continue;
    ForEachPixelCentreIn(t, camera.width, camera.height,
                         [&](int x, int y) { silhouette.at<std::uint8_t>(y, x) = 255; });
  }
  return silhouette;
}

SilhouetteAgreement CompareSilhouette(const Mesh& mesh, const CameraModel& camera,
                                      const cv::Mat& mask) {
  CAROUSEL_THROW_IF(
      mask.type() != CV_8UC1 || mask.cols != camera.width || mask.rows != camera.height,
      InvalidArgument,
      "silhouette agreement: the mask is " << mask.cols << "x" << mask.rows
                                           << " (8-bit expected) but the camera is " << camera.width
                                           << "x" << camera.height);
  SilhouetteAgreement agreement;
  const cv::Mat full_projected = RasterizeSilhouette(mesh, camera);
  const cv::Mat full_object = mask >= 128;
  // Everything happens inside the union's bounding box, grown by a pixel of background.
  const cv::Rect roi =
      (cv::boundingRect(full_object | full_projected) + cv::Size(2, 2) - cv::Point(1, 1)) &
      cv::Rect(0, 0, mask.cols, mask.rows);
  if (roi.area() == 0) return agreement;  // both empty: they agree
  cv::Mat object = cv::Mat::zeros(roi.height + 2, roi.width + 2, CV_8UC1);
  cv::Mat projected = cv::Mat::zeros(object.size(), CV_8UC1);
  full_object(roi).copyTo(object(cv::Rect(1, 1, roi.width, roi.height)));
  full_projected(roi).copyTo(projected(cv::Rect(1, 1, roi.width, roi.height)));
  const double united = cv::countNonZero(object | projected);
  const double disagree_area = cv::countNonZero(object ^ projected);
  agreement.iou = united > 0.0 ? (united - disagree_area) / united : 1.0;
  if (disagree_area == 0.0) return agreement;

  // Outline of the mask: object pixels with a 4-neighbour outside it (the image border counts
  // as outside).
  cv::Mat eroded;
  const cv::Mat cross = cv::getStructuringElement(cv::MORPH_CROSS, cv::Size(3, 3));
  cv::erode(object, eroded, cross, cv::Point(-1, -1), 1, cv::BORDER_CONSTANT, cv::Scalar(0));
  const double outline = cv::countNonZero(object & ~eroded);
  agreement.mean_deviation_px = disagree_area / std::max(outline, 1.0);

  // Distances of the disagreeing pixels from the outline: inside the mask, to the nearest
  // background pixel; outside, to the nearest object pixel.
  cv::Mat to_background, to_object;
  cv::distanceTransform(object, to_background, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  double farthest = 0.0;
  if (cv::countNonZero(object) > 0) {
    cv::distanceTransform(~object, to_object, cv::DIST_L2, cv::DIST_MASK_PRECISE, CV_32F);
  }
  for (int y = 0; y < object.rows; ++y) {
    const auto* o = object.ptr<std::uint8_t>(y);
    const auto* p = projected.ptr<std::uint8_t>(y);
    const auto* db = to_background.ptr<float>(y);
    const auto* dobj = to_object.empty() ? nullptr : to_object.ptr<float>(y);
    for (int x = 0; x < object.cols; ++x) {
      if ((o[x] != 0) == (p[x] != 0)) continue;
      const double d = o[x] ? db[x] : (dobj != nullptr ? dobj[x] : 0.0);
      farthest = std::max(farthest, d);
    }
  }
  agreement.max_deviation_px = farthest;
  return agreement;
}

std::vector<SilhouetteAgreement> MeasureSilhouetteAgreement(const Mesh& mesh,
                                                            const std::vector<View>& views,
                                                            int threads) {
  std::vector<SilhouetteAgreement> result(views.size());
  ParallelFor(views.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      result[i] = CompareSilhouette(mesh, views[i].camera(), views[i].Mask());
      result[i].view = views[i].name();
    }
  });
  return result;
}

}  // namespace carousel::recon
