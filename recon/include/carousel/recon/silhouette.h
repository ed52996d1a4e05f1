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
//   kBacklit     no colour test at all: a second photo of the stop with the backlight on (the
//                panel behind the product and a light-table plate lit, the front lights
//                dimmed) shows the product dark against a bright panel whatever its colours
//                (white on white, black, glossy). The panel's level P (a smooth model fitted
//                from the border, like the backdrop) and the product's F (its dark pixels)
//                give alpha = (P - L) / (P - F) per pixel (L: the mask shot's brightness);
//                >= 0.5 is object. A hole the object encloses that lets the panel through
//                dimmed (a see-through part: glass, clear plastic) is filled; one that shows
//                the panel as it is (a mug's handle) stays open. Then the same clean-up,
//                border check and boundary refinement as keying, on the mask shot.
//   kAuto        (the default) kBacklit when every view comes with a mask shot, else kKey.
// The turntable plate (a disc of plate_radius_m at z = 0 in the turntable frame, located with
// the view's camera) is removed: inside its outline B is the plate's colour, fitted robustly
// like the backdrop, and anti-aliased plate/backdrop rim pixels count as background, so the
// plate never becomes part of the object. With kDifference the plate is already in B.
// The pixels that fail the test are candidates. A backdrop that is not smooth (cloth folds, a
// stand, a dark cloth's sheen) fails it too, so the segmentation is a graph cut (GrabCut) at a
// working resolution seeded with the candidates whose colour is not one of the frame's border
// band (object) and the rest (background); the border band itself is background (a view whose
// silhouette reaches it is rejected: the frame cuts the object).
// Then clean-up (specks, small holes) and boundary refinement to an alpha matte: each pixel of
// a band around the outline gets alpha = <I - B, F - B> / |F - B|^2 with F and B the local
// object and background colours (those of the nearest confident pixel either side, then again
// of the nearest wholly object and wholly background pixels right at the outline).
// Masks are 8-bit alpha, 255 = object, >= 128 = object for the hull (DESIGN.md).
#pragma once

#include <array>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"
#include "carousel/recon/visual_hull.h"

namespace carousel::recon {

enum class SilhouetteMethod {
  kAuto,        // backlit mask shots when every view has one, else keying
  kKey,         // keying against the backdrop colour
  kDifference,  // differencing against an empty-turntable background plate
  kBacklit,     // the backlit mask shot: the product dark against the lit panel
};
// "auto" / "key" / "difference" / "backlit". \throw InvalidArgument for other names.
SilhouetteMethod ParseSilhouetteMethod(const std::string& name);
const char* SilhouetteMethodName(SilhouetteMethod method);

struct SilhouetteOptions {
  SilhouetteMethod method = SilhouetteMethod::kAuto;
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
  // Boundary refinement to an 8-bit alpha matte by local alpha estimation.
  bool refine_boundary = true;
  // Stop when a silhouette reaches the frame's border band (1% of the shorter side): the
  // frame would cut it. Off for close-ups that show only part of the object; the border band
  // then samples the backdrop only where the smooth backdrop model holds.
  bool check_border = true;
  // Multi-view consistency (4 views or more): a view whose silhouette disagrees with the hull
  // of the other views (object outside it, backdrop well inside it) is segmented again with
  // that hull as a prior (a see-through hole stays open: the neighbouring views see through
  // it too, so it is not inside their hull).
  bool multi_view = true;
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

// How colour keying treated the turntable plate in a view. The views of one camera see the
// same plate under the same light, so ComputeSilhouettes makes them agree: a plate colour that
// no other view of the camera confirms is the product's (a beak over the plate) and is not
// keyed away; a view that found the plate hidden, or another colour, keys against the colour
// the others agree on.
struct PlateKeying {
  enum class State {
    kNone,    // no plate in the frame, or not keyed (the difference and backlit methods)
    kFitted,  // keyed against `coeff`
    kHidden,  // the plate is not seen: keyed as backdrop
  };
  State state = State::kNone;
  // kFitted: the plate's 8-bit BGR colour as a quadratic over the image's coordinates
  // normalised to [-1, 1] (basis 1, x, y, x^2, xy, y^2; `terms` of them used), row k of
  // channel c at coeff[3 * k + c]; `mean_bgr`: its mean over the plate, what views compare.
  int terms = 0;
  std::array<double, 18> coeff{};
  cv::Vec3d mean_bgr;
};

struct SilhouetteStats {
  double object_fraction = 0.0;    // mask area / image area
  double backdrop_residual = 0.0;  // RMS of the fitted backdrop model on its inliers, levels
  // Keyed with the plate in view: the fraction of the outline along the plate's rim band.
  double rim_outline_fraction = 0.0;
  int components = 0;  // object components kept
  // Multi-view consistency: pixels of the first segmentation outside the other views' hull,
  // and backdrop pixels well inside it (both at the priors' size: at most 1024 along the
  // longest side); whether the view was segmented again, and what that changed (photo pixels).
  int outside_others = 0;
  int hole_in_others = 0;
  bool redecided = false;
  int pixels_removed = 0;
  int pixels_added = 0;
  // The mask was given (a dataset's own, or edited by hand), not segmented: the multi-view
  // step repairs it geometrically (holes well inside the others' hull filled, spills outside
  // it removed) instead of segmenting the photo again.
  bool given = false;
  // Colour keying: the plate as this view was keyed against it (after the views agreed).
  PlateKeying plate;
};

// One photo's silhouette. `background` is the background plate (kDifference; same size,
// CV_8UC3), ignored by the other methods; with kBacklit `image` is the photo's backlit mask
// shot; kAuto keys. `name` names the photo in errors. `prior` (optional, CV_8UC1,
// the photo's size or a smaller one of its aspect, resized nearest; OthersHullPriors): 0 = not
// object, 255 = object, 192 = probably object, 128 = the colours decide. `photo` (kBacklit,
// optional): the photo of the same stop; the outline is matted in both shots and each pixel
// takes the larger coverage. \throw InvalidArgument
// (image type, missing background, sizes), FormatError if the photo
//        shows no backdrop to key against, no object, an object touching the frame's border
//        (with check_border) or is over-exposed. `plate` (colour keying, optional): how to treat
//        the
// plate instead of judging it from this photo alone: kHidden keys it as backdrop, kFitted
// seeds the plate's fit with what is near that colour (and keys against it when too little
// of the plate shows to fit).
cv::Mat ComputeSilhouette(const cv::Mat& image, const CameraModel& camera,
                          const SilhouetteOptions& options, const cv::Mat& background = {},
                          const std::string& name = "image", SilhouetteStats* stats = nullptr,
                          const cv::Mat& prior = {}, const cv::Mat& photo = {},
                          const PlateKeying* plate = nullptr);

struct SilhouettesResult {
  std::vector<cv::Mat> masks;  // per view, CV_8UC1
  std::vector<SilhouetteStats> stats;
};

// Silhouettes for all views (in parallel), then multi-view consistency (options.multi_view).
// Keyed silhouettes that stop at the plate's rim in most views (a product as light as the
// backdrop: only what stands before the plate keys) are refused, naming a view.
// `backgrounds`: per view (kDifference), may share Mats between the views of one camera;
// empty otherwise. `hull`: the carving the consistency step assumes (floor). `mask_shots`:
// per view, its backlit mask shot (the view's camera; kBacklit, and kAuto takes them), or
// empty. \throw as ComputeSilhouette, InvalidArgument (kBacklit without mask shots),
// IoError/FormatError for unreadable photos, Cancelled.
SilhouettesResult ComputeSilhouettes(const std::vector<View>& views,
                                     const std::vector<cv::Mat>& backgrounds,
                                     const SilhouetteOptions& options, Progress& progress,
                                     const VisualHullOptions& hull = {},
                                     const std::vector<View>& mask_shots = {});

// The method ComputeSilhouettes uses for these options and inputs (kAuto resolved).
SilhouetteMethod ResolveSilhouetteMethod(SilhouetteMethod method, std::size_t views,
                                         std::size_t mask_shots);

// The consistency step alone, on `result` (from the first segmentation of every view, or
// given masks: stats[v].given).
void MakeConsistent(const std::vector<View>& views, const std::vector<cv::Mat>& backgrounds,
                    const SilhouetteOptions& options, const VisualHullOptions& hull,
                    SilhouettesResult* result, Progress& progress,
                    const std::vector<View>& mask_shots = {});

// Intersection over union of two masks (>= 128 = object). \pre same size, CV_8UC1.
double MaskIoU(const cv::Mat& a, const cv::Mat& b);

}  // namespace carousel::recon
