#include "carousel/studio/import.h"

#include <cmath>
#include <fstream>
#include <numbers>
#include <random>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/studio/session.h"
#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

using ::testing::HasSubstr;
using testing::TempDir;

TEST(ImportTest, MiddleburyReproducesThePublishedProjection) {
  TempDir dir;
  const auto par = testing::SharedDataFile("middlebury/templeSparseRing/templeSR_par.txt");
  Progress progress;
  const ImportResult result = ImportDataset(
      {.format = ImportOptions::Format::kMiddlebury, .source = par}, dir / "temple", progress);
  EXPECT_EQ(result.views, 16);
  const Session session = ReadSession(dir / "temple");
  EXPECT_EQ(session.frame, "dataset");
  ASSERT_EQ(session.views.size(), 16u);
  // Parse the published numbers independently and project a few points with x ~ K (R X + t).
  std::ifstream in(par);
  int count = 0;
  in >> count;
  const Eigen::Vector3d points[] = {{-0.02, 0.05, 0.0}, {0.0, 0.1, -0.03}, {0.03, 0.02, 0.02}};
  for (int i = 0; i < count; ++i) {
    std::string name;
    Eigen::Matrix3d k, r;
    Eigen::Vector3d t;
    in >> name;
    for (int j = 0; j < 9; ++j) in >> k(j / 3, j % 3);
    for (int j = 0; j < 9; ++j) in >> r(j / 3, j % 3);
    for (int j = 0; j < 3; ++j) in >> t(j);
    const SessionView& view = session.views[i];
    EXPECT_EQ(view.image, "images/" + name);
    EXPECT_EQ(view.camera_model.width, 640);
    // The points are the dataset's; the session stands the dataset upright.
    ASSERT_TRUE(session.world_from_dataset.has_value());
    for (const Eigen::Vector3d& x : points) {
      const Eigen::Vector3d h = k * (r * x + t);
      const Eigen::Vector2d expected = h.head<2>() / h.z();
      EXPECT_LT((*view.camera_model.Project(*session.world_from_dataset * x) - expected).norm(),
                1e-4)
          << name;
    }
    // The photo is a faithful copy.
    EXPECT_EQ(testing::ReadBytes(dir / "temple" / view.image),
              testing::ReadBytes(par.parent_path() / name));
  }
}

// The temple ring stands upright: its cameras circle a level ring above the origin and look
// down at it, the temple's long axis (the dataset's Y, up in the real world) becomes +Z, and
// --keep-frame keeps the dataset's cameras as published.
TEST(ImportTest, TheTempleRingStandsUprightWithTheOriginWhereTheCamerasLook) {
  TempDir dir;
  const auto par = testing::SharedDataFile("middlebury/templeSparseRing/templeSR_par.txt");
  Progress progress;
  const ImportResult result = ImportDataset({.source = par}, dir / "temple", progress);
  EXPECT_THAT(result.frame, HasSubstr("axis of the camera ring"));
  EXPECT_THAT(result.frame, HasSubstr("looking down"));
  const Session session = ReadSession(dir / "temple");
  ASSERT_TRUE(session.world_from_dataset.has_value());
  // The dataset's +Y (the temple's height) maps to about +Z.
  EXPECT_GT((session.world_from_dataset->rotation * Eigen::Vector3d::UnitY()).z(), 0.99);
  double min_z = 1e9, max_z = -1e9, radius = 0.0;
  for (const SessionView& view : session.views) {
    const Rigid3d& pose = view.camera_model.cam_from_world;
    const Eigen::Vector3d centre = -(pose.rotation.transpose() * pose.translation);
    min_z = std::min(min_z, centre.z());
    max_z = std::max(max_z, centre.z());
    radius += centre.head<2>().norm() / static_cast<double>(session.views.size());
    // Each optical axis passes within 2 cm of the origin, and points down.
    const Eigen::Vector3d axis = pose.rotation.row(2).transpose();
    EXPECT_LT((centre - centre.dot(axis) * axis).norm(), 0.02);
    EXPECT_LT(axis.z(), 0.0);
  }
  EXPECT_GT(min_z, 0.0);
  EXPECT_LT(max_z - min_z, 0.1 * radius);

  const ImportResult kept =
      ImportDataset({.source = par, .keep_frame = true}, dir / "kept", progress);
  EXPECT_EQ(kept.frame, "kept");
  const Session as_published = ReadSession(dir / "kept");
  EXPECT_FALSE(as_published.world_from_dataset.has_value());
  const Rigid3d& first = as_published.views[0].camera_model.cam_from_world;
  EXPECT_NEAR(first.rotation(0, 1), 0.98329680886213122, 1e-12);  // r12 of templeSR0001
}

// A camera at `azimuth`/`elevation` (radians) on a sphere of `distance` about `target` looking
// at it, rolled by `roll` about its axis (a camera mounted sideways).
CameraModel LookingAt(const Eigen::Vector3d& target, double azimuth, double elevation,
                      double distance, double roll) {
  const Eigen::Vector3d centre =
      target + distance * Eigen::Vector3d(std::cos(elevation) * std::cos(azimuth),
                                          std::cos(elevation) * std::sin(azimuth),
                                          std::sin(elevation));
  const Eigen::Vector3d z = (target - centre).normalized();
  const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d y = z.cross(x);
  Eigen::Matrix3d r;
  r.row(0) = x.transpose();
  r.row(1) = y.transpose();
  r.row(2) = z.transpose();
  r = Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitZ()).toRotationMatrix() * r;
  CameraModel camera;
  camera.width = 640;
  camera.height = 480;
  camera.fx = camera.fy = 800;
  camera.cx = 320;
  camera.cy = 240;
  camera.cam_from_world = Rigid3d(r, -(r * centre));
  return camera;
}

// Rigs of different shapes, moved into a random frame, some cameras rolled: the upright frame
// finds their up axis and the point they look at.
TEST(ImportTest, UprightFrameFindsUpForRingsTwoRingsAndADomeInAnyFrame) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const std::vector<std::vector<double>> rigs = {{10.0}, {0.0}, {15.0, 45.0}, {10.0, 35.0, 60.0}};
  for (std::size_t r = 0; r < rigs.size(); ++r) {
    for (int trial = 0; trial < 5; ++trial) {
      const Eigen::Vector3d target(0.05 * unit(rng), 0.05 * unit(rng), 0.1);
      const Rigid3d dataset_from_world(Eigen::Quaterniond::UnitRandom().toRotationMatrix(),
                                       Eigen::Vector3d(unit(rng), unit(rng), unit(rng)));
      std::vector<CameraModel> cameras;
      const int stops = 12;
      for (const double elevation : rigs[r]) {
        for (int k = 0; k < stops; ++k) {
          // Rolled cameras: every third one sideways, the level ring's photos upright.
          const double roll = rigs[r][0] == 0.0 ? 0.0 : (k % 3 == 0 ? std::numbers::pi / 2 : 0.0);
          CameraModel camera = LookingAt(target, 2 * std::numbers::pi * k / stops,
                                         elevation * std::numbers::pi / 180.0, 0.8, roll);
          camera.cam_from_world = camera.cam_from_world * dataset_from_world.Inverse();
          cameras.push_back(camera);
        }
      }
      const auto upright = UprightFrame(cameras);
      ASSERT_TRUE(upright.has_value()) << r;
      const Rigid3d world_from_true = upright->world_from_dataset * dataset_from_world;
      // Up is up (within 0.5 degrees); the target is the origin.
      EXPECT_GT((world_from_true.rotation * Eigen::Vector3d::UnitZ()).z(),
                std::cos(0.5 * std::numbers::pi / 180.0))
          << "rig " << r << " trial " << trial << ": " << upright->basis;
      EXPECT_LT((world_from_true * target).norm(), 1e-6) << r;
    }
  }
  // Cameras all on one line, or too few, fix no axis.
  std::vector<CameraModel> two = {LookingAt({0, 0, 0}, 0, 0.2, 1, 0),
                                  LookingAt({0, 0, 0}, 1, 0.2, 1, 0)};
  EXPECT_FALSE(UprightFrame(two).has_value());
}

// Three quarters of a ring about an axis, the cameras aimed at a point beside it (a product
// off-centre on the turntable): the origin lies on the ring's axis, at the height they look
// at, not at the point they aim at; the ring's radius is measured.
TEST(ImportTest, UprightFrameCentresTheOriginOnTheRingsAxis) {
  const Eigen::Vector3d axis_point(0.0, 0.0, 0.1);
  const Eigen::Vector3d aim = axis_point + Eigen::Vector3d(0.06, 0.02, 0.0);
  const double radius = 0.8, elevation = 10.0 * std::numbers::pi / 180.0;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  const Rigid3d dataset_from_world(Eigen::Quaterniond::UnitRandom().toRotationMatrix(),
                                   Eigen::Vector3d(unit(rng), unit(rng), unit(rng)));
  std::vector<CameraModel> cameras;
  for (int k = 0; k < 12; ++k) {
    const double azimuth = 1.5 * std::numbers::pi * k / 11;
    // On the ring about the axis, looking at the aim point.
    const CameraModel on_ring = LookingAt(axis_point, azimuth, elevation, radius, 0.0);
    const Eigen::Vector3d centre = on_ring.Centre();
    const Eigen::Vector3d z = (aim - centre).normalized();
    const Eigen::Vector3d x = z.cross(Eigen::Vector3d::UnitZ()).normalized();
    Eigen::Matrix3d r;
    r.row(0) = x.transpose();
    r.row(1) = z.cross(x).transpose();
    r.row(2) = z.transpose();
    CameraModel camera = on_ring;
    camera.cam_from_world = Rigid3d(r, -(r * centre)) * dataset_from_world.Inverse();
    cameras.push_back(camera);
  }
  const auto upright = UprightFrame(cameras);
  ASSERT_TRUE(upright.has_value());
  const Rigid3d world_from_true = upright->world_from_dataset * dataset_from_world;
  // The axis point is the origin (the aim point, 6 cm off the axis, is not).
  EXPECT_LT((world_from_true * axis_point).norm(), 1e-6) << upright->basis;
  EXPECT_GT((world_from_true * aim).norm(), 0.05);
  EXPECT_NEAR(upright->ring_radius, radius * std::cos(elevation), 1e-6);
  EXPECT_LT(upright->ring_rms, 1e-6);
  EXPECT_NE(upright->basis.find("through the ring's centre"), std::string::npos);
}

TEST(ImportTest, MalformedParFileNamesTheLine) {
  TempDir dir;
  std::filesystem::copy_file(
      testing::SharedDataFile("middlebury/templeSparseRing/templeSR0001.png"), dir / "a.png");
  Progress progress;
  testing::WriteBytes(dir / "bad_par.txt", "1\na.png 1 0 2 0 1 3 0 0 1 1 0 0 0 1 0 0 0 1 0 0\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.source = dir / "bad_par.txt"}, dir / "s", progress),
                             FormatError, "line 2: expected 22 fields");
  testing::WriteBytes(dir / "bad_par.txt", "1\na.png 1 0 2 0 1 3 0 0 1 1 0 0 0 1 0 0 0 x 0 0 1\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.source = dir / "bad_par.txt"}, dir / "s", progress),
                             FormatError, "line 2: 'x' is not a number");
  testing::WriteBytes(dir / "bad_par.txt", "1\na.png 1 0 2 0 1 3 0 0 1 1 0 0 0 2 0 0 0 1 0 0 1\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.source = dir / "bad_par.txt"}, dir / "s", progress),
                             FormatError, "not a rotation");
  testing::WriteBytes(dir / "bad_par.txt", "2\na.png 1 0 2 0 1 3 0 0 1 1 0 0 0 1 0 0 0 1 0 0 1\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.source = dir / "bad_par.txt"}, dir / "s", progress),
                             FormatError, "announces 2 images");
  testing::WriteBytes(dir / "bad_par.txt", "1\nb.png 1 0 2 0 1 3 0 0 1 1 0 0 0 1 0 0 0 1 0 0 1\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.source = dir / "bad_par.txt"}, dir / "s", progress),
                             IoError, "b.png");
  EXPECT_FALSE(std::filesystem::exists(dir / "s"));
}

TEST(ImportTest, ColmapTextModelShiftsThePrincipalPoint) {
  TempDir dir;
  std::filesystem::create_directories(dir / "sparse");
  std::filesystem::create_directories(dir / "photos");
  WriteImage(dir / "photos/one.png", cv::Mat(60, 80, CV_8UC3, cv::Scalar(1, 2, 3)));
  WriteImage(dir / "photos/two.png", cv::Mat(60, 80, CV_8UC3, cv::Scalar(4, 5, 6)));
  testing::WriteBytes(dir / "sparse/cameras.txt",
                      "# Camera list\n1 PINHOLE 80 60 100 101 40 30\n"
                      "2 OPENCV 80 60 90 91 41 29 -0.1 0.01 0.001 -0.002\n");
  testing::WriteBytes(dir / "sparse/images.txt",
                      "# Image list\n"
                      "1 1 0 0 0 0.1 0.2 1.5 1 one.png\n"
                      "10.5 20.5 -1\n"
                      "2 0.7071067811865476 0 0.7071067811865476 0 0 0 2 2 two.png\n"
                      "\n");
  Progress progress;
  const ImportResult result = ImportDataset({.format = ImportOptions::Format::kColmap,
                                             .source = dir / "sparse",
                                             .images_dir = dir / "photos"},
                                            dir / "s", progress);
  EXPECT_EQ(result.views, 2);
  const Session session = ReadSession(dir / "s");
  ASSERT_EQ(session.views.size(), 2u);
  const CameraModel& one = session.views[0].camera_model;
  EXPECT_EQ(one.cx, 39.5);
  EXPECT_EQ(one.cy, 29.5);
  EXPECT_EQ(one.fx, 100);
  EXPECT_EQ(one.cam_from_world.translation, Eigen::Vector3d(0.1, 0.2, 1.5));
  const CameraModel& two = session.views[1].camera_model;
  EXPECT_EQ(two.distortion.k1, -0.1);
  EXPECT_EQ(two.distortion.p2, -0.002);
  // 90 deg about y: camera x axis = world -z.
  EXPECT_THAT(two.cam_from_world.rotation * Eigen::Vector3d(0, 0, 1),
              testing::EigenNear(Eigen::Vector3d(1, 0, 0), 1e-12));
  // A photo whose size disagrees with its camera.
  testing::WriteBytes(dir / "sparse/cameras.txt",
                      "1 PINHOLE 64 48 100 101 40 30\n2 PINHOLE 80 60 90 91 41 29\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.format = ImportOptions::Format::kColmap,
                                            .source = dir / "sparse",
                                            .images_dir = dir / "photos"},
                                           dir / "s3", progress),
                             FormatError, "one.png: photo is 80x60 but its camera");
  // --force never replaces the folder that holds the dataset.
  testing::WriteBytes(dir / "sparse/cameras.txt",
                      "1 PINHOLE 80 60 100 101 40 30\n2 PINHOLE 80 60 90 91 41 29\n");
  testing::WriteBytes(dir / "session.json", "{}");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.format = ImportOptions::Format::kColmap,
                                            .source = dir / "sparse",
                                            .images_dir = dir / "photos",
                                            .overwrite = true},
                                           dir.path(), progress),
                             IoError, "holds the dataset");
  EXPECT_TRUE(std::filesystem::exists(dir / "photos/one.png"));
  testing::WriteBytes(dir / "sparse/cameras.txt", "1 FISHEYE 80 60 100 40 30 0.1\n");
  CAROUSEL_EXPECT_THROW_WITH(ImportDataset({.format = ImportOptions::Format::kColmap,
                                            .source = dir / "sparse",
                                            .images_dir = dir / "photos"},
                                           dir / "s2", progress),
                             FormatError, "camera model FISHEYE is not supported");
}

}  // namespace
}  // namespace carousel::studio
