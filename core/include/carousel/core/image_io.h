// Image files: photos, masks, depth maps. Reads check the file's content (signature, complete
// PNG/JPEG stream) before decoding, so a truncated download or a garbage file is a FormatError
// naming the file, never a half-grey photo. Writes are atomic (file_util.h).
// EXIF orientation is ignored on purpose: calibration refers to the sensor's pixel grid.
#pragma once

#include <filesystem>
#include <string>

#include <opencv2/core.hpp>

namespace carousel {

enum class ImageReadMode {
  kColor,      // 8-bit, 3 channels, BGR (OpenCV's order)
  kGray,       // 8-bit, 1 channel
  kUnchanged,  // as stored (depth maps, 16-bit, alpha)
};

// The encodings recognised from a file's first bytes.
enum class ImageEncoding { kUnknown, kPng, kJpeg, kTiff, kBmp, kPnm, kWebp };

// Recognises the encoding from the leading bytes (not the file name).
ImageEncoding DetectImageEncoding(const unsigned char* data, std::size_t size);
const char* ImageEncodingName(ImageEncoding encoding);

// \throw IoError (missing/unreadable) or FormatError (empty, unknown content, truncated,
//        undecodable), naming the file.
cv::Mat ReadImage(const std::filesystem::path& path, ImageReadMode mode = ImageReadMode::kColor);

// The largest of 1, 2, 4 and 8 that leaves a picture `long_side` pixels long at least
// `min_side` long (1 when it is shorter already).
int ImageReduction(int long_side, int min_side);

// ReadImage at 1/`reduction` of the picture's size in each direction (`reduction` 1, 2, 4 or
// 8; kColor or kGray): a JPEG by its decoder's scaled decoding (at 1/8, several times faster
// than decoding it whole), other encodings decoded whole, then reduced. A JPEG's reduced size
// is rounded up, the others' down. \throw as ReadImage; InvalidArgument for another reduction
// or kUnchanged.
cv::Mat ReadImage(const std::filesystem::path& path, ImageReadMode mode, int reduction);

// A silhouette mask: 8-bit single channel, 255 = object, 0 = background. Colour files are
// converted to grey. \throw as ReadImage.
cv::Mat ReadMask(const std::filesystem::path& path);

struct ImageWriteOptions {
  int jpeg_quality = 95;    // 1..100, for .jpg/.jpeg
  int png_compression = 3;  // 0..9, for .png (higher = smaller, slower)
  bool overwrite = true;    // see AtomicWriteOptions
  bool sync = true;         // fsync before returning
};

// Encodes by the file extension (.png, .jpg/.jpeg, .tif/.tiff, .bmp, .pgm/.ppm) and writes
// atomically. \throw InvalidArgument for an empty image or unknown extension; IoError on
//        write failure (the previous file, if any, is untouched).
void WriteImage(const std::filesystem::path& path, const cv::Mat& image,
                const ImageWriteOptions& options = {});

}  // namespace carousel
