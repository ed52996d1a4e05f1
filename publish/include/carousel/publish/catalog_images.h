// The 2D assets a shop lists beside the 3D view (issue "Publish"): cut-outs of the captured
// photos (the background removed through the session's alpha masks, on pure white or
// transparent, cropped with a uniform margin and centred), the 360° set marketplaces ask for
// (equal steps from one elevation, sequentially named, one zip per product) and the spin (an
// animated WebP, libwebp's WebPAnimEncoder).
//
// Images are OpenCV's: CV_8UC3 BGR on white, CV_8UC4 BGRA when transparent (straight, not
// premultiplied, alpha: what PNG and WebP store).
#pragma once

#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

namespace carousel::publish {

enum class CutoutBackdrop { kWhite, kTransparent };

// "white" / "transparent"; the reverse \throw InvalidArgument naming the accepted values.
std::string CutoutBackdropName(CutoutBackdrop backdrop);
CutoutBackdrop ParseCutoutBackdrop(const std::string& name);

struct CutoutOptions {
  CutoutBackdrop backdrop = CutoutBackdrop::kWhite;
  // The gap between the object's bounding box and the square image's edge along the box's
  // longer side, as a fraction of the image side, [0, 0.45].
  double margin = 0.06;
  // Side of the square result in pixels (area-averaged down, or up, from the crop); 0 keeps the
  // crop's own size.
  int size = 0;
  // \throw InvalidArgument naming the field.
  void Validate() const;
};

// The object of `photo` (CV_8UC3 BGR) cut out through `alpha` (CV_8UC1 of the same size, 255 =
// object; soft edges blend): a square centred on the bounding box of alpha >= 128, the box
// filling 1 - 2 x margin of the side; parts of the square beyond the photo are backdrop.
// \throw InvalidArgument (types or sizes disagree, or alpha has no object pixel).
cv::Mat CutOut(const cv::Mat& photo, const cv::Mat& alpha, const CutoutOptions& options);

// An image as a catalog file: JPEG (`quality`) for BGR, PNG for BGRA. `name` is the file it is
// meant for, for the message. \throw IoError naming it when the encoder fails.
std::vector<std::uint8_t> EncodeCatalogImage(const cv::Mat& image, int jpeg_quality,
                                             const std::filesystem::path& name);

// The 360° set's file names: "<stem>_01.jpg" ... ("_001" from 100 frames on); `stem` is made
// of [A-Za-z0-9._-] (anything else becomes '-'; empty becomes "product").
std::vector<std::string> SpinSetNames(const std::string& stem, int frames,
                                      const std::string& extension);

// An animated WebP of `frames` (all BGR or all BGRA, one size), each shown `frame_ms`, looping
// forever; lossy at `quality` (0..100). \throw InvalidArgument (no frames, sizes or types
// disagree), IoError naming `name` when libwebp fails.
std::vector<std::uint8_t> EncodeAnimatedWebp(const std::vector<cv::Mat>& frames, int frame_ms,
                                             int quality, const std::filesystem::path& name);

struct AnimatedImage {
  std::vector<cv::Mat> frames;     // CV_8UC4 BGRA
  std::vector<int> timestamps_ms;  // end time of each frame
  int loop_count = 0;              // 0 = forever
};
// Decodes an animated (or still) WebP. \throw FormatError naming `name`.
AnimatedImage DecodeAnimatedWebp(const std::vector<std::uint8_t>& bytes,
                                 const std::filesystem::path& name);

struct ZipEntry {
  std::string name;
  std::vector<std::uint8_t> bytes;
};
// A zip archive of `entries` in their order, stored uncompressed (JPEG and PNG do not shrink)
// with a fixed timestamp, so the same entries give the same bytes (libzip). \throw IoError
// naming `name`, InvalidArgument for an empty or duplicate entry name.
std::vector<std::uint8_t> ZipArchive(const std::vector<ZipEntry>& entries,
                                     const std::filesystem::path& name);
// The entries of a zip file. \throw IoError (unreadable) / FormatError (not a zip) naming it.
std::vector<ZipEntry> ReadZip(const std::filesystem::path& path);

}  // namespace carousel::publish
