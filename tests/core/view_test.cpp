#include "carousel/core/view.h"

#include <thread>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using testing::TempDir;

CameraModel SmallCamera() {
  return {.width = 40, .height = 30, .fx = 50, .fy = 50, .cx = 19.5, .cy = 14.5};
}

TEST(ViewTest, LoadsPixelsLazilyAndSharesThemBetweenCopies) {
  TempDir dir;
  WriteImage(dir / "photo.png", cv::Mat(30, 40, CV_8UC3, cv::Scalar(1, 2, 3)));
  WriteImage(dir / "mask.png", cv::Mat(30, 40, CV_8UC1, cv::Scalar(255)));
  const View view(SmallCamera(), dir / "photo.png", dir / "mask.png", 0.5);
  EXPECT_EQ(view.name(), "photo.png");
  EXPECT_DOUBLE_EQ(view.table_angle_rad(), 0.5);
  const View copy = view;  // NOLINT(performance-unnecessary-copy-initialization): a copy's cache
  const cv::Mat image = view.Image();
  EXPECT_EQ(image.at<cv::Vec3b>(0, 0), cv::Vec3b(1, 2, 3));
  EXPECT_EQ(copy.Image().data, image.data) << "copies share the decoded pixels";
  EXPECT_EQ(cv::countNonZero(view.Mask()), 1200);
}

TEST(ViewTest, ConcurrentFirstLoadsDecodeOnce) {
  TempDir dir;
  WriteImage(dir / "photo.png", cv::Mat(30, 40, CV_8UC3, cv::Scalar(9, 9, 9)));
  const View view(SmallCamera(), dir / "photo.png");
  std::vector<const uchar*> data(8);
  std::vector<std::thread> threads;
  threads.reserve(8);
  for (int i = 0; i < 8; ++i) threads.emplace_back([&, i] { data[i] = view.Image().data; });
  for (auto& t : threads) t.join();
  for (const uchar* d : data) EXPECT_EQ(d, data[0]);
}

TEST(ViewTest, WrongSizeIsAFormatErrorNamingTheFile) {
  TempDir dir;
  WriteImage(dir / "small.png", cv::Mat(20, 20, CV_8UC3, cv::Scalar(0)));
  WriteImage(dir / "mask.png", cv::Mat(20, 20, CV_8UC1, cv::Scalar(0)));
  const View view(SmallCamera(), dir / "small.png", dir / "mask.png");
  CAROUSEL_EXPECT_THROW_WITH(view.Image(), FormatError,
                             "small.png: photo is 20x20 but its camera is 40x30");
  CAROUSEL_EXPECT_THROW_WITH(view.Mask(), FormatError, "mask.png: mask is 20x20");
}

// The photo for a small picture: decoded reduced and not kept, unless it is in memory.
TEST(ViewTest, ReducedPhotoIsDecodedSmallUnlessLoaded) {
  TempDir dir;
  const CameraModel camera{
      .width = 400, .height = 300, .fx = 500, .fy = 500, .cx = 199.5, .cy = 149.5};
  WriteImage(dir / "photo.jpg", cv::Mat(300, 400, CV_8UC3, cv::Scalar(40, 90, 160)));
  const View view(camera, dir / "photo.jpg");
  const cv::Mat small = view.ImageAtLeast(100);
  EXPECT_EQ(small.size(), cv::Size(100, 75));
  EXPECT_LT(cv::norm(small.at<cv::Vec3b>(30, 50), cv::Vec3b(40, 90, 160), cv::NORM_INF), 4.0);
  EXPECT_EQ(view.ImageAtLeast(101).size(), cv::Size(200, 150));
  EXPECT_EQ(view.ImageAtLeast(300).size(), cv::Size(400, 300));
  const cv::Mat whole = view.Image();
  EXPECT_EQ(view.ImageAtLeast(100).data, whole.data) << "a loaded photo is not decoded again";

  WriteImage(dir / "small.jpg", cv::Mat(150, 200, CV_8UC3, cv::Scalar(0)));
  const View wrong(camera, dir / "small.jpg");
  CAROUSEL_EXPECT_THROW_WITH(wrong.ImageAtLeast(50), FormatError,
                             "small.jpg: photo is about 200x152 but its camera is 400x300");
  EXPECT_THROW(View(camera, {}).ImageAtLeast(50), InvalidArgument);
}

TEST(ViewTest, MissingFilesAndMasksAreReported) {
  TempDir dir;
  const View view(SmallCamera(), dir / "gone.jpg");
  CAROUSEL_EXPECT_THROW_WITH(view.Image(), IoError, "gone.jpg");
  EXPECT_FALSE(view.HasMask());
  CAROUSEL_EXPECT_THROW_WITH(view.Mask(), InvalidArgument, "has no silhouette mask");
  const View empty(SmallCamera(), "");
  EXPECT_FALSE(empty.HasImage());
  EXPECT_THROW(empty.Image(), InvalidArgument);
}

TEST(ViewTest, InMemoryPixelsAreCheckedAndKeptOnRelease) {
  View view(SmallCamera(), "");
  EXPECT_THROW(view.SetImage(cv::Mat(30, 40, CV_8UC1)), InvalidArgument);
  EXPECT_THROW(view.SetImage(cv::Mat(31, 40, CV_8UC3)), InvalidArgument);
  EXPECT_THROW(view.SetMask(cv::Mat(30, 40, CV_8UC3)), InvalidArgument);
  view.SetImage(cv::Mat(30, 40, CV_8UC3, cv::Scalar(7, 7, 7)));
  view.SetMask(cv::Mat(30, 40, CV_8UC1, cv::Scalar(255)));
  view.ReleasePixels();
  EXPECT_EQ(view.Image().at<cv::Vec3b>(3, 3), cv::Vec3b(7, 7, 7));
  EXPECT_TRUE(view.HasMask());
}

TEST(ViewTest, ReleasedPixelsReloadFromTheFile) {
  TempDir dir;
  WriteImage(dir / "photo.png", cv::Mat(30, 40, CV_8UC3, cv::Scalar(4, 5, 6)));
  const View view(SmallCamera(), dir / "photo.png");
  const cv::Mat first = view.Image().clone();
  view.ReleasePixels();
  EXPECT_EQ(cv::norm(view.Image(), first, cv::NORM_INF), 0.0);
}

}  // namespace
}  // namespace carousel
