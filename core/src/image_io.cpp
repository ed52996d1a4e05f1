#include "carousel/core/image_io.h"

#include <algorithm>
#include <array>
#include <cstring>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel {
namespace {

bool StartsWith(const unsigned char* data, std::size_t size, std::initializer_list<int> prefix) {
  if (size < prefix.size()) return false;
  std::size_t i = 0;
  for (int byte : prefix) {
    if (data[i++] != static_cast<unsigned char>(byte)) return false;
  }
  return true;
}

std::string HexPrefix(const std::vector<std::uint8_t>& bytes) {
  static constexpr const char* kDigits = "0123456789abcdef";
  std::string out;
  for (std::size_t i = 0; i < std::min<std::size_t>(bytes.size(), 8); ++i) {
    if (i) out += ' ';
    out += kDigits[bytes[i] >> 4];
    out += kDigits[bytes[i] & 15];
  }
  return out;
}

// A PNG ends with the IEND chunk: length 0, "IEND", CRC ae 42 60 82.
bool PngIsComplete(const std::vector<std::uint8_t>& bytes) {
  static constexpr std::array<std::uint8_t, 12> kIend = {0,   0,   0,    0,    'I',  'E',
                                                         'N', 'D', 0xae, 0x42, 0x60, 0x82};
  return std::search(bytes.begin(), bytes.end(), kIend.begin(), kIend.end()) != bytes.end();
}

// A JPEG's last scan (the last SOS marker, FF DA) must be followed by the end-of-image marker
// (FF D9). Inside entropy-coded data FF is always stuffed, so neither marker appears by
// accident there; an embedded EXIF thumbnail's EOI precedes the main image's scans.
bool JpegIsComplete(const std::vector<std::uint8_t>& bytes) {
  std::size_t last_sos = 0;
  bool have_sos = false;
  for (std::size_t i = 0; i + 1 < bytes.size(); ++i) {
    if (bytes[i] == 0xFF && bytes[i + 1] == 0xDA) {
      last_sos = i;
      have_sos = true;
    }
  }
  if (!have_sos) return false;
  for (std::size_t i = last_sos + 2; i + 1 < bytes.size(); ++i) {
    if (bytes[i] == 0xFF && bytes[i + 1] == 0xD9) return true;
  }
  return false;
}

int DecodeFlags(ImageReadMode mode, int reduction) {
  if (reduction > 1) {
    const bool colour = mode == ImageReadMode::kColor;
    const int reduced =
        reduction == 2   ? (colour ? cv::IMREAD_REDUCED_COLOR_2 : cv::IMREAD_REDUCED_GRAYSCALE_2)
        : reduction == 4 ? (colour ? cv::IMREAD_REDUCED_COLOR_4 : cv::IMREAD_REDUCED_GRAYSCALE_4)
                         : (colour ? cv::IMREAD_REDUCED_COLOR_8 : cv::IMREAD_REDUCED_GRAYSCALE_8);
    return reduced | cv::IMREAD_IGNORE_ORIENTATION;
  }
  switch (mode) {
    case ImageReadMode::kColor:
      return cv::IMREAD_COLOR | cv::IMREAD_IGNORE_ORIENTATION;
    case ImageReadMode::kGray:
      return cv::IMREAD_GRAYSCALE | cv::IMREAD_IGNORE_ORIENTATION;
    case ImageReadMode::kUnchanged:
      return cv::IMREAD_UNCHANGED;
  }
  return cv::IMREAD_UNCHANGED;
}

}  // namespace

ImageEncoding DetectImageEncoding(const unsigned char* data, std::size_t size) {
  if (StartsWith(data, size, {0x89, 'P', 'N', 'G', 0x0D, 0x0A, 0x1A, 0x0A})) {
    return ImageEncoding::kPng;
  }
  if (StartsWith(data, size, {0xFF, 0xD8, 0xFF})) return ImageEncoding::kJpeg;
  if (StartsWith(data, size, {'I', 'I', 42, 0}) || StartsWith(data, size, {'M', 'M', 0, 42})) {
    return ImageEncoding::kTiff;
  }
  if (StartsWith(data, size, {'B', 'M'}) && size >= 26) return ImageEncoding::kBmp;
  if (size >= 3 && data[0] == 'P' && data[1] >= '1' && data[1] <= '6' &&
      (data[2] == '\n' || data[2] == ' ' || data[2] == '\r' || data[2] == '\t')) {
    return ImageEncoding::kPnm;
  }
  if (size >= 12 && std::memcmp(data, "RIFF", 4) == 0 && std::memcmp(data + 8, "WEBP", 4) == 0) {
    return ImageEncoding::kWebp;
  }
  return ImageEncoding::kUnknown;
}

const char* ImageEncodingName(ImageEncoding encoding) {
  switch (encoding) {
    case ImageEncoding::kPng:
      return "PNG";
    case ImageEncoding::kJpeg:
      return "JPEG";
    case ImageEncoding::kTiff:
      return "TIFF";
    case ImageEncoding::kBmp:
      return "BMP";
    case ImageEncoding::kPnm:
      return "PNM";
    case ImageEncoding::kWebp:
      return "WebP";
    case ImageEncoding::kUnknown:
      break;
  }
  return "unknown";
}

cv::Mat ReadImage(const std::filesystem::path& path, ImageReadMode mode) {
  return ReadImage(path, mode, 1);
}

int ImageReduction(int long_side, int min_side) {
  int reduction = 1;
  while (reduction < 8 && long_side / (2 * reduction) >= min_side) reduction *= 2;
  return reduction;
}

cv::Mat ReadImage(const std::filesystem::path& path, ImageReadMode mode, int reduction) {
  CAROUSEL_THROW_IF(
      reduction != 1 && reduction != 2 && reduction != 4 && reduction != 8, InvalidArgument,
      "ReadImage: reduction must be 1, 2, 4 or 8, got " << reduction << " for " << path.string());
  CAROUSEL_THROW_IF(reduction > 1 && mode == ImageReadMode::kUnchanged, InvalidArgument,
                    "ReadImage: " << path.string() << " cannot be read reduced as stored");
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  if (bytes.empty()) throw FormatError(path, "file is empty");
  const ImageEncoding encoding = DetectImageEncoding(bytes.data(), bytes.size());
  if (encoding == ImageEncoding::kUnknown) {
    throw FormatError(path,
                      "not an image: unrecognised content (first bytes " + HexPrefix(bytes) + ")");
  }
  if (encoding == ImageEncoding::kPng && !PngIsComplete(bytes)) {
    throw FormatError(path, "truncated PNG: the file ends before its IEND chunk");
  }
  if (encoding == ImageEncoding::kJpeg && !JpegIsComplete(bytes)) {
    throw FormatError(path, "truncated JPEG: the image data ends without an end-of-image marker");
  }
  cv::Mat image;
  try {
    image = cv::imdecode(bytes, DecodeFlags(mode, reduction));
  } catch (const cv::Exception& e) {
    throw FormatError(path,
                      std::string("corrupt ") + ImageEncodingName(encoding) + " data: " + e.what());
  }
  if (image.empty() || image.cols <= 0 || image.rows <= 0) {
    throw FormatError(path, std::string("corrupt ") + ImageEncodingName(encoding) +
                                " data: the decoder could not read it");
  }
  return image;
}

cv::Mat ReadMask(const std::filesystem::path& path) {
  cv::Mat mask = ReadImage(path, ImageReadMode::kUnchanged);
  if (mask.depth() != CV_8U) {
    throw FormatError(
        path, "mask must be 8-bit, found " + std::to_string(8 * mask.elemSize1()) + "-bit samples");
  }
  if (mask.channels() == 3) {
    cv::cvtColor(mask, mask, cv::COLOR_BGR2GRAY);
  } else if (mask.channels() == 4) {
    cv::cvtColor(mask, mask, cv::COLOR_BGRA2GRAY);
  } else if (mask.channels() != 1) {
    throw FormatError(path, "mask must have 1 channel, found " + std::to_string(mask.channels()));
  }
  return mask;
}

void WriteImage(const std::filesystem::path& path, const cv::Mat& image,
                const ImageWriteOptions& options) {
  CAROUSEL_THROW_IF(image.empty(), InvalidArgument,
                    "WriteImage: empty image for " << path.string());
  std::string extension = path.extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  std::vector<int> params;
  if (extension == ".jpg" || extension == ".jpeg") {
    CAROUSEL_THROW_IF(
        options.jpeg_quality < 1 || options.jpeg_quality > 100, InvalidArgument,
        "ImageWriteOptions.jpeg_quality must be in 1..100, got " << options.jpeg_quality);
    params = {cv::IMWRITE_JPEG_QUALITY, options.jpeg_quality};
  } else if (extension == ".png") {
    CAROUSEL_THROW_IF(
        options.png_compression < 0 || options.png_compression > 9, InvalidArgument,
        "ImageWriteOptions.png_compression must be in 0..9, got " << options.png_compression);
    params = {cv::IMWRITE_PNG_COMPRESSION, options.png_compression};
  } else if (extension != ".tif" && extension != ".tiff" && extension != ".bmp" &&
             extension != ".pgm" && extension != ".ppm") {
    throw InvalidArgument("WriteImage: unsupported image extension '" + extension + "' for " +
                          path.string() + " (use .png, .jpg, .tif, .bmp, .pgm or .ppm)");
  }
  std::vector<std::uint8_t> encoded;
  bool ok = false;
  try {
    ok = cv::imencode(extension, image, encoded, params);
  } catch (const cv::Exception& e) {
    throw InvalidArgument("WriteImage: cannot encode " + path.string() + ": " + e.what());
  }
  CAROUSEL_THROW_IF(!ok, InvalidArgument,
                    "WriteImage: cannot encode a "
                        << image.cols << "x" << image.rows << " image of " << image.channels()
                        << " channels as " << extension << " for " << path.string());
  WriteFileAtomic(path, encoded, {.overwrite = options.overwrite, .sync = options.sync});
}

}  // namespace carousel
