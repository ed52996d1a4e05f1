// Silhouettes: an alpha mask per photo of an object on the studio backdrop (the input of the
// visual hull and of the texture stage's missing-colour correction; paper section 4.3).
//
// Background model per pixel, then a shadow-tolerant colour test (Horprasert et al. 1999):
// a pixel I is background when it is a brightness-scaled copy of the expected background B,
//   alpha = <I, B> / <B, B> in [min_shadow_brightness, max_highlight_brightness] and
//   |I - alpha B| <= chroma_threshold,
// or simply |I - B| <= noise_threshold. Shadows on a white or green backdrop only darken it and
// so stay background; object colours differ in chromaticity or strongly in brightness.
//
// Methods for B:
//   kKey         keying against the backdrop colour: a smooth (quadratic in x and y, per
//                channel) backdrop fitted robustly to the photo itself, the object's pixels
//                rejected as outliers; no extra photo needed.
//   kDifference  differencing against a background plate: a photo of the empty turntable
//                taken with the same camera and settings.
// The turntable plate (a disc of plate_radius_m at z = 0 in the turntable frame, located with
// the view's camera) is removed: inside its outline B is the plate's colour, fitted robustly
// like the backdrop, and anti-aliased plate/backdrop rim pixels count as background, so the
// plate never becomes part of the object. With kDifference the plate is already in B.
// Then clean-up (specks, small holes) and boundary refinement: each boundary pixel gets
// alpha = <I - B, F - B> / |F - B|^2 with F the local object colour (normalized convolution of
// nearby confident object pixels), and is object when alpha >= 0.5, i.e. when the object
// covers at least half of it. Masks are 8-bit, 255 = object (DESIGN.md).
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"

namespace carousel::recon {

enum class SilhouetteMethod {
  kKey,         // keying against the backdrop colour
  kDifference,  // differencing against an empty-turntable background plate
};
// "key" / "difference". \throw InvalidArgument for other names.
SilhouetteMethod ParseSilhouetteMethod(const std::string& name);
const char* SilhouetteMethodName(SilhouetteMethod method);

struct SilhouetteOptions {
  SilhouetteMethod method = SilhouetteMethod::kKey;
  // Largest colour distance |I - B| that is always background (sensor noise, JPEG), 8-bit
  // levels, >= 0.
  double noise_threshold = 10.0;
  // Largest chromaticity distortion |I - alpha B| of a background pixel, 8-bit levels, > 0.
  double chroma_threshold = 9.0;
  // A background pixel may be darkened to this fraction of B (shadows), 0..1.
  double min_shadow_brightness = 0.6;
  // ... or brightened to this multiple of B (highlights, exposure drift), >= 1.
  double max_highlight_brightness = 1.08;
  // Turntable plate radius, metres, centred on the turntable axis at z = 0 of the views'
  // world frame; 0 = no plate to remove (a dataset that is not on our turntable).
  double plate_radius_m = 0.2;
  // The plate's rim band, where plate/backdrop blends are background: the outline swept over
  // +-plate_rim_m in radius and height (plate thickness and edge, its height not exactly at
  // z = 0), metres, 0..0.05, grown by plate_rim_px pixels (anti-aliasing), 0..50.
  double plate_rim_m = 0.0015;
  double plate_rim_px = 1.5;
  // Boundary refinement by local alpha estimation.
  bool refine_boundary = true;
  // Object components smaller than this fraction of the largest one are dropped, 0..1.
  double min_component_fraction = 0.002;
  // Background holes smaller than this fraction of the object's area are filled, 0..1.
  double max_hole_fraction = 0.0005;
  // Worker threads for several views; 0 = one per hardware thread.
  int threads = 0;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<SilhouetteOptions>& Fields();
  void Validate() const;
};

struct SilhouetteStats {
  double object_fraction = 0.0;    // mask area / image area
  double backdrop_residual = 0.0;  // RMS of the fitted backdrop model on its inliers, levels
  int components = 0;              // object components kept
};

// One photo's silhouette. `background` is the background plate (kDifference; same size,
// CV_8UC3), ignored by kKey. `name` names the photo in errors.
// \throw InvalidArgument (image type, missing background, sizes), FormatError if the photo
//        shows no backdrop to key against.
cv::Mat ComputeSilhouette(const cv::Mat& image, const CameraModel& camera,
                          const SilhouetteOptions& options, const cv::Mat& background = {},
                          const std::string& name = "image", SilhouetteStats* stats = nullptr);

struct SilhouettesResult {
  std::vector<cv::Mat> masks;  // per view, CV_8UC1
  std::vector<SilhouetteStats> stats;
};

// Silhouettes for all views (in parallel). `backgrounds`: per view (kDifference), may share
// Mats between the views of one camera; empty for kKey.
// \throw as ComputeSilhouette, IoError/FormatError for unreadable photos, Cancelled.
SilhouettesResult ComputeSilhouettes(const std::vector<View>& views,
                                     const std::vector<cv::Mat>& backgrounds,
                                     const SilhouetteOptions& options, Progress& progress);

// Intersection over union of two masks (>= 128 = object). \pre same size, CV_8UC1.
double MaskIoU(const cv::Mat& a, const cv::Mat& b);

}  // namespace carousel::recon
