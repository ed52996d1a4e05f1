// Held-out scoring, the quality report's measure of a textured model (texture paper, section
// 6): the model rendered through the camera of a view that was not used for texturing and
// compared with that view's photo over the object's mask.
//
// Rendering (RenderTexturedModel), unlit, as a viewer shows the model: core's RasterizeMesh
// (z-buffer, n x n samples per pixel, lens distortion included, edges the lens bends split);
// each face is shaded once per pixel at the centroid of its samples with perspective-correct
// UVs, bilinear texture filtering and trilinear mip-mapping (a pyramid halved by area
// averaging; the level per face from its texel-to-pixel area ratio); colours are blended by
// sample coverage in linear RGB (the texture and the output are sRGB) over a backdrop that is
// a vertical gradient. The defaults are those of the simulated rig's unlit rendering (2 x 2
// samples, its studio-grey backdrop), so scores compare with the ones it gave.
//
// Scores (ScoreHeldOutView): over the reference mask, PSNR (8-bit, mean of the three
// channels' squared errors; 99 dB when equal), the mean of the per-channel SSIM maps (Gaussian
// 11 x 11 window, sigma 1.5, constants (0.01 x 255)^2 and (0.03 x 255)^2), and the IoU of the
// rendered silhouette with the reference mask.
// Pixels: integer coordinates are pixel centres (DESIGN.md).
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/view.h"
#include "carousel/texture/textured_model.h"

namespace carousel::texture {

struct ModelRenderOptions {
  // Samples per pixel along each axis, 1..4: anti-aliased edges.
  int samples_per_axis = 2;
  // Trilinear mip-mapped filtering; false: bilinear from the full-size texture only.
  bool mipmaps = true;
  // Backdrop where the model does not cover a sample: 8-bit BGR at the top and the bottom
  // image row, interpolated linearly per row in linear RGB.
  cv::Vec3b backdrop_top_bgr{245, 245, 245};
  cv::Vec3b backdrop_bottom_bgr{219, 219, 219};
  // Lens-bent edges: see MeshRasterOptions::max_edge_error_px (pixels, > 0).
  double max_edge_error_px = 0.02;
  // Worker threads; 0 = one per hardware thread. The image does not depend on it.
  int threads = 0;
  // \throw InvalidArgument naming the field.
  void Validate() const;
};

struct ModelRendering {
  cv::Mat image;  // CV_8UC3, BGR
  cv::Mat mask;   // CV_8UC1, 255 where the model covers at least half of a pixel's samples
};

// Renders `model` through `camera` (cam_from_world included: the turntable angle is in it).
// \throw InvalidArgument (model, camera, options).
ModelRendering RenderTexturedModel(const TexturedModel& model, const CameraModel& camera,
                                   const ModelRenderOptions& options = {});

// The textured model rendered through a held-out view's camera and compared with its photo
// over the object's mask.
struct HeldOutScore {
  int view = 0;                 // index of the view among the session's
  double psnr_db = 0.0;         // over the reference mask
  double ssim = 0.0;            // mean of the per-channel SSIM map over the mask
  double mask_agreement = 0.0;  // IoU of the rendered and the reference silhouettes
  bool has_reference = true;    // false: no mask, scored over the rendering's own coverage
};

// Scores a rendering against `photo` (CV_8UC3 BGR) over `reference_mask` (CV_8UC1, >= 128 =
// object), all of one size; `view` is copied into the score. An empty `reference_mask` (a view
// without a mask) scores over the rendering's own coverage: mask_agreement is then 1 and
// has_reference false.
// \throw InvalidArgument for sizes or types that disagree.
HeldOutScore CompareWithPhoto(const ModelRendering& rendering, const cv::Mat& photo,
                              const cv::Mat& reference_mask, int view);

// Renders `model` through `view`'s camera and compares it with the view's photo over
// `reference_mask` (the true mask when there is one, else the view's silhouette); `index` is
// the view's index, copied into the score.
// \throw InvalidArgument, IoError/FormatError naming the photo.
HeldOutScore ScoreHeldOutView(const TexturedModel& model, const View& view, int index,
                              const cv::Mat& reference_mask,
                              const ModelRenderOptions& options = {});

// Means over scores (0 when there are none).
double MeanPsnrDb(const std::vector<HeldOutScore>& scores);
double MeanSsim(const std::vector<HeldOutScore>& scores);

}  // namespace carousel::texture
