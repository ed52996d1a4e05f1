#include "carousel/core/image_io.h"

#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using testing::ReadBytes;
using testing::SharedDataFile;
using testing::TempDir;
using testing::WriteBytes;

cv::Mat Gradient(int width, int height) {
  cv::Mat image(height, width, CV_8UC3);
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      image.at<cv::Vec3b>(y, x) = cv::Vec3b(x * 255 / width, y * 255 / height, (x + y) % 256);
    }
  }
  return image;
}

TEST(ImageIoTest, PngRoundTripIsExactAndJpegIsClose) {
  TempDir dir;
  const cv::Mat image = Gradient(97, 61);
  WriteImage(dir / "a.png", image);
  WriteImage(dir / "a.jpg", image, {.jpeg_quality = 98});
  EXPECT_EQ(cv::norm(ReadImage(dir / "a.png"), image, cv::NORM_INF), 0.0);
  const cv::Mat jpeg = ReadImage(dir / "a.jpg");
  ASSERT_EQ(jpeg.size(), image.size());
  EXPECT_GT(cv::PSNR(jpeg, image), 35.0);
}

TEST(ImageIoTest, ReadsARealCameraJpeg) {
  const cv::Mat photo = ReadImage(SharedDataFile("calib/images/left01.jpg"));
  EXPECT_EQ(photo.cols, 640);
  EXPECT_EQ(photo.rows, 480);
  EXPECT_EQ(photo.type(), CV_8UC3);
  const cv::Mat gray = ReadImage(SharedDataFile("calib/images/left01.jpg"), ImageReadMode::kGray);
  EXPECT_EQ(gray.type(), CV_8UC1);
}

TEST(ImageIoTest, ReductionKeepsThePictureAtLeastTheAskedSize) {
  EXPECT_EQ(ImageReduction(5184, 480), 8);
  EXPECT_EQ(ImageReduction(5184, 648), 8);
  EXPECT_EQ(ImageReduction(5184, 649), 4);
  EXPECT_EQ(ImageReduction(5184, 1920), 2);
  EXPECT_EQ(ImageReduction(5184, 2593), 1);
  EXPECT_EQ(ImageReduction(640, 1000), 1);
  EXPECT_EQ(ImageReduction(100000, 10), 8) << "no reduction past 1/8";
}

// A JPEG reduced by its decoder and a PNG reduced after decoding show the same picture as the
// whole one shrunk, at the size the reduction gives (a JPEG's rounded up, a PNG's down).
TEST(ImageIoTest, ReadsAPictureReduced) {
  TempDir dir;
  cv::Mat image = Gradient(203, 101);
  cv::GaussianBlur(image, image, cv::Size(9, 9), 3.0);
  WriteImage(dir / "a.jpg", image, {.jpeg_quality = 98});
  WriteImage(dir / "a.png", image);
  for (const int reduction : {2, 4, 8}) {
    SCOPED_TRACE(reduction);
    cv::Mat expected;
    const cv::Mat jpeg = ReadImage(dir / "a.jpg", ImageReadMode::kColor, reduction);
    ASSERT_EQ(jpeg.size(),
              cv::Size((203 + reduction - 1) / reduction, (101 + reduction - 1) / reduction));
    cv::resize(image, expected, jpeg.size(), 0, 0, cv::INTER_AREA);
    EXPECT_GT(cv::PSNR(jpeg, expected), 25.0);  // the wrapped blue ramp blurs at its edge
    const cv::Mat png = ReadImage(dir / "a.png", ImageReadMode::kGray, reduction);
    ASSERT_EQ(png.size(), cv::Size(203 / reduction, 101 / reduction));
    EXPECT_EQ(png.type(), CV_8UC1);
  }
  EXPECT_EQ(ReadImage(dir / "a.jpg", ImageReadMode::kColor, 1).size(), image.size());
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "a.jpg", ImageReadMode::kColor, 3), InvalidArgument,
                             "a.jpg");
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "a.png", ImageReadMode::kUnchanged, 2),
                             InvalidArgument, "a.png");
  WriteBytes(dir / "cut.jpg", ReadBytes(dir / "a.jpg").substr(0, 300));
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "cut.jpg", ImageReadMode::kColor, 4), FormatError,
                             "cut.jpg");
}

TEST(ImageIoTest, MissingFileIsAnIoErrorNamingIt) {
  TempDir dir;
  try {
    ReadImage(dir / "photo_017.jpg");
    FAIL() << "no exception";
  } catch (const FormatError&) {
    FAIL() << "a missing file is not a format error";
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find("photo_017.jpg"), std::string::npos);
    EXPECT_EQ(e.reason(), "no such file");
  }
}

TEST(ImageIoTest, EmptyFileIsAFormatError) {
  TempDir dir;
  WriteBytes(dir / "empty.png", "");
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "empty.png"), FormatError, "empty.png: file is empty");
}

TEST(ImageIoTest, GarbageIsAFormatError) {
  TempDir dir;
  std::string garbage(5000, '\0');
  for (std::size_t i = 0; i < garbage.size(); ++i) garbage[i] = static_cast<char>((i * 7919) % 251);
  WriteBytes(dir / "garbage.png", garbage);
  WriteBytes(dir / "garbage.jpg", garbage);
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "garbage.png"), FormatError, "not an image");
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "garbage.jpg"), FormatError, "garbage.jpg");
}

TEST(ImageIoTest, TruncatedJpegIsAFormatError) {
  TempDir dir;
  const std::string bytes = ReadBytes(SharedDataFile("calib/images/left01.jpg"));
  for (double keep : {0.9, 0.5, 0.1}) {
    WriteBytes(dir / "cut.jpg", bytes.substr(0, static_cast<std::size_t>(bytes.size() * keep)));
    CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "cut.jpg"), FormatError, "truncated JPEG");
  }
}

TEST(ImageIoTest, TruncatedOrCorruptPngIsAFormatError) {
  TempDir dir;
  WriteImage(dir / "good.png", Gradient(120, 80), {.png_compression = 0});
  const std::string bytes = ReadBytes(dir / "good.png");
  WriteBytes(dir / "cut.png", bytes.substr(0, bytes.size() / 2));
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "cut.png"), FormatError, "truncated PNG");
  // Bit flips inside the image data keep the file's shape but break its CRC/zlib stream.
  std::string flipped = bytes;
  for (std::size_t i = 200; i < 260; ++i) flipped[i] = static_cast<char>(flipped[i] ^ 0x5a);
  WriteBytes(dir / "flipped.png", flipped);
  CAROUSEL_EXPECT_THROW_WITH(ReadImage(dir / "flipped.png"), FormatError, "flipped.png");
}

TEST(ImageIoTest, MasksAreSingleChannel8Bit) {
  TempDir dir;
  cv::Mat mask(30, 40, CV_8UC1, cv::Scalar(0));
  mask(cv::Rect(10, 5, 20, 10)).setTo(255);
  WriteImage(dir / "mask.png", mask);
  const cv::Mat back = ReadMask(dir / "mask.png");
  EXPECT_EQ(back.type(), CV_8UC1);
  EXPECT_EQ(cv::countNonZero(back), 200);
  // A colour PNG mask (as some tools save them) is converted.
  cv::Mat colour;
  cv::cvtColor(mask, colour, cv::COLOR_GRAY2BGR);
  WriteImage(dir / "colour_mask.png", colour);
  EXPECT_EQ(cv::countNonZero(ReadMask(dir / "colour_mask.png")), 200);
  // A 16-bit mask is refused.
  WriteImage(dir / "deep.png", cv::Mat(4, 4, CV_16UC1, cv::Scalar(1000)));
  CAROUSEL_EXPECT_THROW_WITH(ReadMask(dir / "deep.png"), FormatError, "8-bit");
}

TEST(ImageIoTest, WriteRejectsBadRequestsAndKeepsOldFiles) {
  TempDir dir;
  CAROUSEL_EXPECT_THROW_WITH(WriteImage(dir / "a.xyz", Gradient(4, 4)), InvalidArgument, ".xyz");
  CAROUSEL_EXPECT_THROW_WITH(WriteImage(dir / "a.png", cv::Mat()), InvalidArgument, "empty");
  CAROUSEL_EXPECT_THROW_WITH(WriteImage(dir / "a.jpg", Gradient(4, 4), {.jpeg_quality = 0}),
                             InvalidArgument, "jpeg_quality");
  CAROUSEL_EXPECT_THROW_WITH(WriteImage(dir / "missing/a.png", Gradient(4, 4)), IoError,
                             "does not exist");
  WriteImage(dir / "keep.png", Gradient(8, 8));
  const std::string before = ReadBytes(dir / "keep.png");
  EXPECT_THROW(WriteImage(dir / "keep.png", Gradient(9, 9), {.overwrite = false}), IoError);
  EXPECT_EQ(ReadBytes(dir / "keep.png"), before);
}

TEST(ImageIoTest, DetectsEncodingFromContent) {
  const unsigned char png[] = {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A};
  const unsigned char jpeg[] = {0xFF, 0xD8, 0xFF, 0xE0};
  const unsigned char elf[] = {0x7F, 'E', 'L', 'F'};
  EXPECT_EQ(DetectImageEncoding(png, sizeof png), ImageEncoding::kPng);
  EXPECT_EQ(DetectImageEncoding(jpeg, sizeof jpeg), ImageEncoding::kJpeg);
  EXPECT_EQ(DetectImageEncoding(elf, sizeof elf), ImageEncoding::kUnknown);
  EXPECT_EQ(DetectImageEncoding(png, 3), ImageEncoding::kUnknown);
}

}  // namespace
}  // namespace carousel
