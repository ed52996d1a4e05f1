#include "carousel/studio/import.h"

#include <fstream>
#include <sstream>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/studio/session.h"
#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

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
    for (const Eigen::Vector3d& x : points) {
      const Eigen::Vector3d h = k * (r * x + t);
      const Eigen::Vector2d expected = h.head<2>() / h.z();
      EXPECT_LT((*view.camera_model.Project(x) - expected).norm(), 1e-4) << name;
    }
    // The photo is a faithful copy.
    EXPECT_EQ(testing::ReadBytes(dir / "temple" / view.image),
              testing::ReadBytes(par.parent_path() / name));
  }
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
