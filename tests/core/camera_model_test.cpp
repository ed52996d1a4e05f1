#include "carousel/core/camera_model.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>
#include <opencv2/calib3d.hpp>

#include "carousel/core/error.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using testing::EigenNear;
using testing::RandomCamera;

// Points scattered in the camera's field of view at 0.3 to 3 m depth.
std::vector<Eigen::Vector3d> PointsInView(const CameraModel& camera, std::mt19937& rng, int n) {
  std::uniform_real_distribution<double> u(-0.6, 1.6);
  std::uniform_real_distribution<double> depth(0.3, 3.0);
  std::vector<Eigen::Vector3d> points;
  const Rigid3d world_from_cam = camera.cam_from_world.Inverse();
  while (static_cast<int>(points.size()) < n) {
    // Through a pixel up to 60% outside the image, so distortion is exercised at the corners.
    const double px = u(rng) * camera.width;
    const double py = u(rng) * camera.height;
    const double z = depth(rng);
    const Eigen::Vector3d cam((px - camera.cx) / camera.fx * z, (py - camera.cy) / camera.fy * z,
                              z);
    points.push_back(world_from_cam * cam);
  }
  return points;
}

TEST(CameraModelTest, ProjectAgreesWithOpenCvProjectPoints) {
  std::mt19937 rng(7);
  int compared = 0;
  double max_error = 0.0;
  for (int trial = 0; trial < 40; ++trial) {
    const CameraModel camera = RandomCamera(rng, {.distortion_scale = trial % 4 == 0 ? 0.0 : 1.5});
    camera.Validate();
    const std::vector<Eigen::Vector3d> points = PointsInView(camera, rng, 50);
    std::vector<cv::Point3d> cv_points;
    for (const Eigen::Vector3d& p : points) cv_points.emplace_back(p.x(), p.y(), p.z());
    cv::Vec3d rvec, tvec;
    camera.CvPose(&rvec, &tvec);
    std::vector<cv::Point2d> expected;
    cv::projectPoints(cv_points, rvec, tvec, camera.CvCameraMatrix(), camera.CvDistCoeffs(),
                      expected);
    for (std::size_t i = 0; i < points.size(); ++i) {
      const std::optional<Eigen::Vector2d> pixel = camera.Project(points[i]);
      ASSERT_TRUE(pixel.has_value());
      max_error =
          std::max(max_error, std::hypot(pixel->x() - expected[i].x, pixel->y() - expected[i].y));
      ++compared;
    }
  }
  EXPECT_GE(compared, 1000);
  EXPECT_LT(max_error, 1e-9) << "over " << compared << " points";
}

TEST(CameraModelTest, UnprojectInvertsProjectInsideTheImage) {
  std::mt19937 rng(11);
  double max_error = 0.0;
  int count = 0;
  for (int trial = 0; trial < 30; ++trial) {
    // Up to strong distortion (3x a typical lens).
    const CameraModel camera = RandomCamera(rng, {.distortion_scale = 1.0 + (trial % 3)});
    for (int gy = 0; gy <= 20; ++gy) {
      for (int gx = 0; gx <= 20; ++gx) {
        const Eigen::Vector2d pixel(-0.5 + camera.width * gx / 20.0,
                                    -0.5 + camera.height * gy / 20.0);
        const double depth = 0.5 + 0.1 * gx;
        const std::optional<Eigen::Vector3d> point = camera.Unproject(pixel, depth);
        ASSERT_TRUE(point.has_value()) << "pixel " << pixel.transpose();
        EXPECT_NEAR((camera.cam_from_world * *point).z(), depth, 1e-12);
        const std::optional<Eigen::Vector2d> back = camera.Project(*point);
        ASSERT_TRUE(back.has_value());
        max_error = std::max(max_error, (*back - pixel).norm());
        ++count;
      }
    }
  }
  EXPECT_LT(max_error, 1e-6) << "over " << count << " pixels";
}

TEST(CameraModelTest, RayThroughPixelHitsTheProjectedPoint) {
  std::mt19937 rng(3);
  const CameraModel camera = RandomCamera(rng);
  for (const Eigen::Vector3d& p : PointsInView(camera, rng, 100)) {
    const std::optional<Eigen::Vector2d> pixel = camera.Project(p);
    ASSERT_TRUE(pixel);
    const std::optional<Ray> ray = camera.RayThrough(*pixel);
    ASSERT_TRUE(ray);
    EXPECT_NEAR(ray->direction.norm(), 1.0, 1e-12);
    // p lies on the ray: distance from p to the line is ~0 and it is in front.
    const Eigen::Vector3d to_point = p - ray->origin;
    EXPECT_GT(to_point.dot(ray->direction), 0.0);
    EXPECT_LT((to_point - to_point.dot(ray->direction) * ray->direction).norm(), 1e-9);
  }
}

TEST(CameraModelTest, CentreAndViewingDirectionOfLookAt) {
  CameraModel camera{.width = 640, .height = 480, .fx = 500, .fy = 500, .cx = 319.5, .cy = 239.5};
  const Eigen::Vector3d eye(0.8, -0.4, 0.35);
  const Eigen::Vector3d target(0.0, 0.0, 0.1);
  camera.cam_from_world = Rigid3d::LookAt(eye, target);
  EXPECT_THAT(camera.Centre(), EigenNear(eye, 1e-12));
  EXPECT_THAT(camera.ViewingDirection(),
              EigenNear(Eigen::Vector3d((target - eye).normalized()), 1e-12));
  // The target projects to the principal point; a point above it projects above (smaller y).
  EXPECT_THAT(*camera.Project(target), EigenNear(Eigen::Vector2d(319.5, 239.5), 1e-9));
  EXPECT_LT(camera.Project(target + Eigen::Vector3d(0, 0, 0.05))->y(), 239.5);
  // +Z of the world appears upright: a point to the camera's right has larger x.
  const Eigen::Vector3d right = (target - eye).cross(Eigen::Vector3d::UnitZ()).normalized();
  EXPECT_GT(camera.Project(target + 0.05 * right)->x(), 319.5);
}

TEST(CameraModelTest, PointsBehindTheCameraDoNotProject) {
  CameraModel camera{.width = 640, .height = 480, .fx = 500, .fy = 500, .cx = 320, .cy = 240};
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0, 0, -1)).has_value());
  EXPECT_FALSE(camera.Project(Eigen::Vector3d(0.1, 0, 0)).has_value());
  EXPECT_TRUE(camera.Project(Eigen::Vector3d(0, 0, 1)).has_value());
}

TEST(CameraModelTest, InImageUsesPixelCentreConvention) {
  const CameraModel camera{.width = 10, .height = 8, .fx = 10, .fy = 10, .cx = 4.5, .cy = 3.5};
  EXPECT_TRUE(camera.InImage({-0.5, -0.5}));
  EXPECT_TRUE(camera.InImage({9.5, 7.5}));
  EXPECT_FALSE(camera.InImage({-0.51, 0}));
  EXPECT_FALSE(camera.InImage({0, 7.51}));
  EXPECT_FALSE(camera.InImage({0, 0}, 1.0));
}

TEST(CameraModelTest, DistortionJacobianMatchesFiniteDifferences) {
  const Distortion d{0.12, -0.05, 0.002, -0.001, 0.01};
  for (const Eigen::Vector2d& xy :
       {Eigen::Vector2d(0.3, -0.2), Eigen::Vector2d(-0.5, 0.4), Eigen::Vector2d(0.01, 0.7)}) {
    Eigen::Matrix2d jacobian;
    d.Apply(xy, &jacobian);
    const double h = 1e-7;
    Eigen::Matrix2d numeric;
    for (int k = 0; k < 2; ++k) {
      Eigen::Vector2d step = Eigen::Vector2d::Zero();
      step[k] = h;
      numeric.col(k) = (d.Apply(xy + step) - d.Apply(xy - step)) / (2 * h);
    }
    EXPECT_THAT(jacobian, EigenNear(numeric, 1e-7));
  }
}

TEST(CameraModelTest, RemoveDistortionRefusesWhereTheLensModelFolds) {
  // Strong barrel distortion folds back beyond r ~ 1: no inverse exists for a point that the
  // forward model never reaches.
  const Distortion d{-0.5, 0.0, 0.0, 0.0, 0.0};
  EXPECT_FALSE(d.Remove(Eigen::Vector2d(2.0, 0.0)).has_value());
  const std::optional<Eigen::Vector2d> inside = d.Remove(Eigen::Vector2d(0.3, 0.1));
  ASSERT_TRUE(inside);
  EXPECT_THAT(d.Apply(*inside), EigenNear(Eigen::Vector2d(0.3, 0.1), 1e-14));
}

TEST(CameraModelTest, ScaledCameraSeesTheSamePointsAtScaledPixels) {
  std::mt19937 rng(5);
  CameraModel camera = RandomCamera(rng, {.width = 5184, .height = 3456});
  const CameraModel quarter = camera.Scaled(0.25);
  EXPECT_EQ(quarter.width, 1296);
  EXPECT_EQ(quarter.height, 864);
  for (const Eigen::Vector3d& p : PointsInView(camera, rng, 50)) {
    const Eigen::Vector2d full = *camera.Project(p);
    const Eigen::Vector2d small = *quarter.Project(p);
    // Pixel edges scale by 0.25: (x + 0.5) * 0.25 - 0.5.
    EXPECT_THAT(small, EigenNear(Eigen::Vector2d((full.array() + 0.5) * 0.25 - 0.5), 1e-9));
  }
  EXPECT_THROW(camera.Scaled(0.0), InvalidArgument);
}

TEST(CameraModelTest, ValidateNamesTheBadField) {
  const CameraModel good{.width = 64, .height = 48, .fx = 50, .fy = 50, .cx = 32, .cy = 24};
  EXPECT_NO_THROW(good.Validate());
  CameraModel bad = good;
  bad.fx = 0;
  CAROUSEL_EXPECT_THROW_WITH(bad.Validate(), InvalidArgument, "CameraModel.fx");
  bad = good;
  bad.height = -1;
  CAROUSEL_EXPECT_THROW_WITH(bad.Validate(), InvalidArgument, "CameraModel.height");
  bad = good;
  bad.distortion.k2 = std::nan("");
  CAROUSEL_EXPECT_THROW_WITH(bad.Validate(), InvalidArgument, "distortion");
  bad = good;
  bad.cam_from_world.rotation(0, 0) = 2.0;
  CAROUSEL_EXPECT_THROW_WITH(bad.Validate(), InvalidArgument, "cam_from_world");
}

TEST(Rigid3dTest, InverseAndCompositionAreConsistent) {
  std::mt19937 rng(9);
  const Rigid3d a = RandomCamera(rng).cam_from_world;
  const Rigid3d b = RandomCamera(rng).cam_from_world;
  const Eigen::Vector3d p(0.1, -0.2, 0.3);
  EXPECT_THAT((a * b) * p, EigenNear(a * (b * p), 1e-12));
  EXPECT_THAT(a.Inverse() * (a * p), EigenNear(p, 1e-12));
  EXPECT_TRUE((a * b).IsValid());
  const Rigid3d quarter_turn = Rigid3d::RotationZ(M_PI / 2);
  EXPECT_THAT(quarter_turn * Eigen::Vector3d(1, 0, 0), EigenNear(Eigen::Vector3d(0, 1, 0), 1e-15));
}

TEST(Rigid3dTest, LookAtRejectsDegenerateInput) {
  EXPECT_THROW(Rigid3d::LookAt({1, 1, 1}, {1, 1, 1}), InvalidArgument);
  EXPECT_THROW(Rigid3d::LookAt({0, 0, 2}, {0, 0, 0}), InvalidArgument);  // looking along up
}

}  // namespace
}  // namespace carousel
