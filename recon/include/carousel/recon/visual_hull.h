// Visual hull: the largest shape consistent with every silhouette (shape from silhouette, the
// geometry the texture paper starts from).
//
// Octree carving: every cell is tested against every view at once through the view's signed
// distance transform of the mask: if the cell's projected bounding circle lies entirely
// outside the silhouette in one view the whole cell is empty; if it lies inside in all views
// the cell is full; otherwise it is split, down to the finest voxel. Pixels outside a photo are
// unknown, never empty: a view whose frame does not contain the whole object carves nothing
// where it does not see.
// Surface: the field f(x) = min over the views seeing x of the signed pixel distance of x's
// projection to the silhouette boundary (bilinear, sub-pixel), scaled to metres by depth /
// focal length, is evaluated at the finest cells' corners and contoured at f = 0 by marching
// tetrahedra (each cube split into the six Freudenthal tetrahedra: the marching-cubes variant
// without ambiguous cases, so the surface is watertight and manifold by construction) with
// linear interpolation, i.e. at sub-voxel accuracy. The largest closed component is kept.
// Units: metres in the views' world frame (the turntable frame). Masks: >= 128 = object.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/mesh.h"
#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/core/view.h"

namespace carousel::recon {

struct VisualHullOptions {
  // Voxel edge length in metres; 0 = automatic (from `resolution`, else from `voxel_px`).
  double voxel_size_m = 0.0;
  // Voxels along the longest side of the object's bounding box; 0 = use voxel_px. 16..4096.
  int resolution = 0;
  // Automatic voxel size: a voxel at the object's centre spans this many pixels in the view
  // with the finest sampling, > 0 ...
  double voxel_px = 2.0;
  // ... but at most this many voxels along the longest side (16..4096). The surface is
  // interpolated from the masks' distance maps, so voxels of several pixels still reproduce
  // the silhouettes to about a pixel (MeasureSilhouetteAgreement): finer grids cost time and
  // memory and only matter for the hull itself, not for the optimized mesh.
  int max_resolution = 384;
  // The object stands on a floor (the turntable top) at z = floor_z_m: nothing below it.
  bool use_floor = true;
  double floor_z_m = 0.0;
  // A view is inconsistent (wrong calibration, wrong mask) when it keeps less than this
  // fraction of the hull of all the other views, 0..1. Checked with 4 views or more.
  double min_view_consistency = 0.5;
  // Refuse resolutions whose surface would need more cells than this (memory guard).
  std::size_t max_surface_cells = 40'000'000;
  // A hull with more faces than this also gets a coarser contour of the same field (`proxy`,
  // from a coarser octree level) as the input of the mesh optimization, which needs far fewer
  // faces than the hull has; 0 = never.
  // (A coarser level's contour loses what photos of 18 Mpx show: a shoe's outline strays 4.8 px
  // from its silhouettes through a 2-levels-coarser proxy, 1.0 px through a 1-level one.)
  std::size_t proxy_max_faces = 600'000;
  // Worker threads; 0 = one per hardware thread.
  int threads = 0;
  // The description of every field above (core/options.h): flags, widgets, range checks.
  static const OptionTable<VisualHullOptions>& Fields();
  void Validate() const;
};

struct VisualHullResult {
  Mesh mesh;  // closed, manifold, outward (counter-clockwise) triangles
  // When the hull has more than proxy_max_faces faces: the surface contoured at octree level
  // proxy_level (cells of 2^proxy_level voxels), also closed and manifold; else empty, 0.
  Mesh proxy;
  int proxy_level = 0;
  // The mesh to optimize: the proxy when there is one, else the hull.
  const Mesh& OptimizationInput() const { return proxy_level > 0 ? proxy : mesh; }
  double voxel_size_m = 0.0;
  Eigen::AlignedBox3d box;        // the carved region
  Eigen::Vector3i grid{0, 0, 0};  // finest voxels along x, y, z
  std::size_t surface_cells = 0;
  std::size_t corners_evaluated = 0;
  std::size_t components_dropped = 0;  // smaller pieces removed
  std::size_t faces_dropped = 0;       // faces in those pieces
  double volume_m3 = 0.0;
  std::vector<double> view_consistency;  // per view, fraction of the others' hull it keeps
  double seconds_distance = 0.0;
  double seconds_carve = 0.0;
  double seconds_surface = 0.0;
};

// The silhouettes carve no common volume, or some views keep too little of the others' hull:
// a FormatError naming the masks' folder and those views (wrong camera pose or mask), with
// their indices for a diagnosis.
class InconsistentViews : public FormatError {
 public:
  InconsistentViews(const std::filesystem::path& path, const std::string& reason,
                    std::vector<std::size_t> views)
      : FormatError(path, reason), views_(std::move(views)) {}
  const std::vector<std::size_t>& views() const { return views_; }

 private:
  std::vector<std::size_t> views_;
};

// \pre views carry masks (View::Mask()) and cameras in one world frame.
// \throw InvalidArgument (fewer than 2 views, bad options, a mask of the wrong size),
//        FormatError naming views whose silhouettes are empty, InconsistentViews (the hull
//        vanishes, or views inconsistent with the others), IoError for unreadable masks,
//        Cancelled.
VisualHullResult ComputeVisualHull(const std::vector<View>& views, const VisualHullOptions& options,
                                   Progress& progress);

// Multi-view consistency of silhouettes: per view, what the hull of all the OTHER views says
// about each of its pixels, on a coarse grid (96 cells along the carved region). CV_8UC1 at
// the mask's size, or for a mask longer than 1024 pixels at that size (the camera scaled by
// CameraModel::Scaled): 0 = no cell of the others' hull projects there (grown by a cell: surely
// not object), 192 = a cell wholly inside every other silhouette projects there (probably
// object), 255 = that, and a cell's footprint from the outline of that region (object:
// nothing see-through there escapes the neighbouring views), 128 = undecided. Empty when a
// mask is empty. \pre masks[i] sized as views[i]'s camera.
// \throw InvalidArgument (sizes), FormatError (inconsistent calibration).
std::vector<cv::Mat> OthersHullPriors(const std::vector<View>& views,
                                      const std::vector<cv::Mat>& masks,
                                      const VisualHullOptions& options);

}  // namespace carousel::recon
