#include "carousel/recon/reprojection.h"

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/rigid3.h"
#include "carousel/recon/visual_hull.h"
#include "carousel/testing/testing.h"
#include "recon_fixtures.h"

namespace carousel::recon {
namespace {

// A square pinhole camera at the origin looking along +z.
CameraModel PinholeCamera() {
  CameraModel camera;
  camera.width = 100;
  camera.height = 100;
  camera.fx = camera.fy = 100.0;
  camera.cx = camera.cy = 50.0;
  return camera;
}

// A rectangle facing the camera at depth 1 m, corners (+-hx, +-hy).
Mesh Rectangle(double hx, double hy) {
  Mesh mesh;
  const auto a = mesh.add_vertex({-hx, -hy, 1.0});
  const auto b = mesh.add_vertex({hx, -hy, 1.0});
  const auto c = mesh.add_vertex({hx, hy, 1.0});
  const auto d = mesh.add_vertex({-hx, hy, 1.0});
  mesh.add_face(a, b, c);
  mesh.add_face(a, c, d);
  return mesh;
}

// Pixels whose centres the triangles cover, and only those: x in [37.5, 62.5] covers the
// centres 38..62, y in [25, 75] the centres 25..75 (edges inclusive).
TEST(SilhouetteAgreementTest, RasterizesPixelCentres) {
  const cv::Mat silhouette = RasterizeSilhouette(Rectangle(0.125, 0.25), PinholeCamera());
  EXPECT_EQ(cv::countNonZero(silhouette), 25 * 51);
  EXPECT_EQ(silhouette.at<std::uint8_t>(25, 38), 255);
  EXPECT_EQ(silhouette.at<std::uint8_t>(75, 62), 255);
  EXPECT_EQ(silhouette.at<std::uint8_t>(50, 37), 0);
  EXPECT_EQ(silhouette.at<std::uint8_t>(50, 63), 0);
  EXPECT_EQ(silhouette.at<std::uint8_t>(24, 50), 0);
}

// A mask one pixel wider on each side than the mesh's silhouette: the outlines are a pixel
// apart, and the farthest disagreeing pixel is a pixel from the mask's outline.
TEST(SilhouetteAgreementTest, MeasuresTheOutlineDeviation) {
  const CameraModel camera = PinholeCamera();
  const Mesh mesh = Rectangle(0.125, 0.25);  // pixels x 38..62, y 25..75
  cv::Mat mask = cv::Mat::zeros(100, 100, CV_8UC1);
  mask(cv::Rect(37, 25, 27, 51)).setTo(255);  // x 37..63
  const SilhouetteAgreement a = CompareSilhouette(mesh, camera, mask);
  EXPECT_NEAR(a.iou, 25.0 / 27.0, 1e-9);
  // 2 x 51 disagreeing pixels over an outline of 2 x 27 + 2 x 49 pixels.
  EXPECT_NEAR(a.mean_deviation_px, 102.0 / 152.0, 1e-9);
  EXPECT_NEAR(a.max_deviation_px, 1.0, 1e-6);
  CAROUSEL_EXPECT_THROW_WITH(
      CompareSilhouette(mesh, camera, cv::Mat(50, 50, CV_8UC1, cv::Scalar(0))), InvalidArgument,
      "100x100");
}

// The hull of exact masks reproduces them to a fraction of a pixel; a camera a degree off
// shows at once.
TEST(SilhouetteAgreementTest, HullReproducesItsSilhouettesAndAWrongCameraShows) {
  const sim::SimViews& capture = testing::SimulatedCapture("sphere");
  std::vector<View> views;
  for (std::size_t i = 0; i < capture.views.size(); ++i) {
    View view(capture.views[i].camera(), {}, {}, capture.views[i].table_angle_rad());
    view.set_name(capture.views[i].name());
    view.SetMask(capture.truth_masks[i]);
    views.push_back(view);
  }
  VisualHullOptions options;
  options.resolution = 96;
  Progress progress;
  const VisualHullResult hull = ComputeVisualHull(views, options, progress);
  const std::vector<SilhouetteAgreement> agreement = MeasureSilhouetteAgreement(hull.mesh, views);
  ASSERT_EQ(agreement.size(), views.size());
  for (const SilhouetteAgreement& a : agreement) {
    EXPECT_GE(a.iou, 0.99) << a.view;
    EXPECT_LE(a.mean_deviation_px, 0.5) << a.view;
    EXPECT_LE(a.max_deviation_px, 3.0) << a.view;
  }
  CameraModel wrong = views[3].camera();
  // Panned by a degree: the image moves by fx * tan(1 deg), about 20 pixels.
  const Eigen::Matrix3d pan =
      Eigen::AngleAxisd(0.0175, Eigen::Vector3d::UnitY()).toRotationMatrix();
  wrong.cam_from_world = Rigid3d(pan, Eigen::Vector3d::Zero()) * wrong.cam_from_world;
  const SilhouetteAgreement off = CompareSilhouette(hull.mesh, wrong, capture.truth_masks[3]);
  EXPECT_GE(off.mean_deviation_px, 3.0);
  EXPECT_LT(off.iou, 0.97);
}

}  // namespace
}  // namespace carousel::recon
