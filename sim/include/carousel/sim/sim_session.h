// A simulated capture held in memory: the views (photo, exact camera, table angle) of a scene
// on the simulated rig, with ground truth. For tests and benchmarks of the stages that take
// std::vector<View> (recon, texture) without going through a session folder.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"
#include "carousel/core/view.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"

namespace carousel::sim {

struct SimViewsOptions {
  SimRigOptions rig;
  int stops = 16;            // turntable stops, evenly spaced from 0 deg, >= 1
  RenderOptions render;      // seed varies per view
  int jpeg_quality = 95;     // photos go through JPEG at this quality; 0 = keep them lossless
  bool backgrounds = false;  // also render each camera's empty-turntable background plate
  bool mask_shots = false;   // also render each view's backlit mask shot (RenderOptions::backlit)
  void Validate() const;
};

struct SimViews {
  std::vector<View> views;           // named camC_stopNN, pixels in memory, no masks
  std::vector<cv::Mat> truth_masks;  // per view, exact silhouettes (CV_8UC1)
  std::vector<cv::Mat> backgrounds;  // per view (shared per camera) when requested
  std::vector<View> mask_shots;      // per view, its backlit mask shot, when requested
  Mesh truth_mesh;                   // the scene's surface, turntable frame
};

// \throw InvalidArgument for bad options or scene.
SimViews RenderViews(const Scene& scene, const SimViewsOptions& options);

}  // namespace carousel::sim
