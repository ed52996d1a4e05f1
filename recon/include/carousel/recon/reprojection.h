// Silhouette agreement: how well a reconstructed mesh reproduces the silhouettes it was made
// from, in pixels of each photo. The mesh is projected through each view's camera (lens
// distortion included, triangles rasterised at pixel centres) and compared with the view's
// mask: intersection over union, and the boundary deviation, i.e. the area where the two
// disagree divided by the length of the mask's outline (the mean distance between the two
// outlines when they differ by a thin band), plus the largest distance of a disagreeing pixel
// from the mask's outline. A calibration error, a bad mask or too coarse a hull shows here.
#pragma once

#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/mesh.h"
#include "carousel/core/view.h"

namespace carousel::recon {

struct SilhouetteAgreement {
  std::string view;
  double iou = 0.0;
  double mean_deviation_px = 0.0;  // disagreeing area / outline length of the mask
  double max_deviation_px = 0.0;   // farthest disagreeing pixel from the mask's outline
};

// The mesh's silhouette in a camera: 255 where a triangle covers the pixel centre.
cv::Mat RasterizeSilhouette(const Mesh& mesh, const CameraModel& camera);

// Compares the mesh's silhouette with `mask` (CV_8UC1 of the camera's size, >= 128 = object).
// \throw InvalidArgument for a mask of the wrong size or type.
SilhouetteAgreement CompareSilhouette(const Mesh& mesh, const CameraModel& camera,
                                      const cv::Mat& mask);

// Per view (views carry masks), in parallel. \throw as View::Mask(), InvalidArgument.
std::vector<SilhouetteAgreement> MeasureSilhouetteAgreement(const Mesh& mesh,
                                                            const std::vector<View>& views,
                                                            int threads = 0);

}  // namespace carousel::recon
