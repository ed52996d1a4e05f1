// Triangle rasterisation at pixel centres, shared by the silhouette of a mesh in a photo
// (recon), the texel coverage of an atlas (texture) and, through RasterizeMesh, the z-buffered
// rendering of a mesh through a camera (texture's held-out scoring).
//
// Pixels follow DESIGN.md: integer coordinates are pixel centres, (0,0) is the centre of the
// top-left pixel. RasterizeMesh takes world coordinates in metres and projects them through
// CameraModel::Project (lens distortion included).
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"

namespace carousel {

class Mesh;

// Calls visit(x, y) for every pixel (x, y) of a width x height grid whose centre, at integer
// coordinates (x, y), lies in the triangle or on its edges. Either orientation.
template <typename Visit>
void ForEachPixelCentreIn(std::array<Eigen::Vector2d, 3> t, int width, int height, Visit&& visit) {
  auto edge = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b, double x, double y) {
    return (b.x() - a.x()) * (y - a.y()) - (b.y() - a.y()) * (x - a.x());
  };
  // Counter-clockwise in these coordinates: every edge function >= 0 inside.
  if (edge(t[0], t[1], t[2].x(), t[2].y()) < 0.0) std::swap(t[1], t[2]);
  const int x0 = std::max(0, static_cast<int>(std::ceil(std::min({t[0].x(), t[1].x(), t[2].x()}))));
  const int x1 =
      std::min(width - 1, static_cast<int>(std::floor(std::max({t[0].x(), t[1].x(), t[2].x()}))));
  const int y0 = std::max(0, static_cast<int>(std::ceil(std::min({t[0].y(), t[1].y(), t[2].y()}))));
  const int y1 =
      std::min(height - 1, static_cast<int>(std::floor(std::max({t[0].y(), t[1].y(), t[2].y()}))));
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x)
      if (edge(t[0], t[1], x, y) >= 0.0 && edge(t[1], t[2], x, y) >= 0.0 &&
          edge(t[2], t[0], x, y) >= 0.0)
        visit(x, y);
}

// As ForEachPixelCentreIn, with the pixel centre's barycentric coordinates in the triangle
// (corners in the order given): visit(x, y, b), b[0] + b[1] + b[2] = 1; the surface point of
// a texel is then b[0] p0 + b[1] p1 + b[2] p2. Nothing for a degenerate triangle.
template <typename Visit>
void ForEachPixelCentreWithBarycentrics(const std::array<Eigen::Vector2d, 3>& t, int width,
                                        int height, Visit&& visit) {
  const Eigen::Vector2d e1 = t[1] - t[0];
  const Eigen::Vector2d e2 = t[2] - t[0];
  const double area = e1.x() * e2.y() - e1.y() * e2.x();
  if (std::abs(area) < 1e-12) return;
  ForEachPixelCentreIn(t, width, height, [&](int x, int y) {
    const Eigen::Vector2d q = Eigen::Vector2d(x, y) - t[0];
    const double b1 = (q.x() * e2.y() - q.y() * e2.x()) / area;
    const double b2 = (e1.x() * q.y() - e1.y() * q.x()) / area;
    visit(x, y, std::array<double, 3>{1.0 - b1 - b2, b1, b2});
  });
}

// ---- z-buffered mesh rasterisation ------------------------------------------------------
//
// Every pixel holds samples_per_axis^2 samples at offsets ((i + 0.5) / n - 0.5,
// (j + 0.5) / n - 0.5) from its centre (n = 1: the centre itself). A sample belongs to the
// nearest triangle (largest 1 / camera z) that covers it; samples exactly on an edge go to the
// triangle for which it is a top or left edge, so two triangles sharing an edge never both
// cover a sample and never both miss it (no cracks, no double coverage). Ties in depth go to
// the lower triangle index. Both orientations are drawn (no back-face culling). Triangles with
// a vertex closer to the camera than near_m (or behind it) are skipped, not clipped.
//
// Lens distortion bends straight 3D edges into curves: a triangle whose edges the lens moves
// by more than max_edge_error_px from the straight screen line (at the edge's 3D midpoint,
// along and across the edge) is split at 3D edge midpoints, up to 12 times, each edge deciding
// from its own endpoints so that neighbours split alike (no T-junction cracks).
//
// Per pixel the result keeps one fragment per face owning some of its samples: how many, and
// the face's perspective-correct barycentrics (3D barycentrics: attributes linear on the
// triangle, such as UVs, combine with them) and depth at the centroid of those samples. This
// is what a renderer needs to shade a face once per pixel and blend by coverage.
// Deterministic: the same inputs give the same result whatever the thread count.

struct MeshRasterOptions {
  // Samples per pixel along each axis, 1..4 (n x n samples per pixel).
  int samples_per_axis = 1;
  // Largest bend of a projected 3D edge from its straight screen line before the triangle is
  // split, pixels, > 0. Ignored for cameras without distortion.
  double max_edge_error_px = 0.02;
  // Near plane, camera-frame z in metres, > 0: triangles with a vertex closer are skipped.
  double near_m = 0.01;
  // Worker threads; 0 = one per hardware thread.
  int threads = 0;
  // \throw InvalidArgument naming the field.
  void Validate() const;
};

// One face's share of one pixel.
struct RasterFragment {
  int face = -1;    // index into the triangles given to RasterizeMesh (Mesh: face idx())
  int samples = 0;  // samples of the pixel the face owns, 1..samples_per_axis^2
  float depth = 0;  // camera-frame z at the centroid of those samples, metres
  Eigen::Vector3f barycentric = Eigen::Vector3f::Zero();  // of the face's vertices, in the
                                                          // order given; >= 0, sum 1
};

class MeshRaster {
 public:
  MeshRaster() = default;
  int width() const { return width_; }
  int height() const { return height_; }
  int samples_per_axis() const { return samples_per_axis_; }
  int samples_per_pixel() const { return samples_per_axis_ * samples_per_axis_; }
  // Fragments of pixel (x, y), in the order of their first sample (row-major within the
  // pixel); empty where no face covers a sample. \pre 0 <= x < width, 0 <= y < height.
  std::span<const RasterFragment> Fragments(int x, int y) const {
    const std::size_t pixel = static_cast<std::size_t>(y) * width_ + x;
    return {fragments_.data() + offsets_[pixel], fragments_.data() + offsets_[pixel + 1]};
  }
  // Samples of pixel (x, y) that some face covers, 0..samples_per_pixel().
  int CoveredSamples(int x, int y) const;
  // CV_8UC1: 255 where faces cover at least half of the pixel's samples, else 0.
  cv::Mat Mask() const;
  // CV_8UC1: round(255 * covered samples / samples per pixel).
  cv::Mat Coverage() const;
  // CV_32SC1: per pixel the face owning the most samples (the first such fragment), -1 where
  // none.
  cv::Mat FaceIds() const;
  // All fragments, pixel after pixel (row-major).
  const std::vector<RasterFragment>& fragments() const { return fragments_; }
  // Screen triangles rasterised, after lens subdivision.
  std::size_t triangles_rasterized() const { return triangles_rasterized_; }

 private:
  friend MeshRaster RasterizeMesh(std::span<const Eigen::Vector3d> positions_world,
                                  std::span<const Eigen::Vector3i> triangles,
                                  const CameraModel& camera, const MeshRasterOptions& options);
  int width_ = 0;
  int height_ = 0;
  int samples_per_axis_ = 1;
  std::vector<std::uint32_t> offsets_ = {0};  // width * height + 1: pixel p's fragments are
                                              // fragments_[offsets_[p], offsets_[p + 1])
  std::vector<RasterFragment> fragments_;
  std::size_t triangles_rasterized_ = 0;
};

// Rasterises triangles (vertex indices into positions_world, metres, turntable frame) through
// `camera` (cam_from_world included). Positions that are not finite drop their triangles.
// \throw InvalidArgument for an invalid camera or options, or a vertex index out of range.
MeshRaster RasterizeMesh(std::span<const Eigen::Vector3d> positions_world,
                         std::span<const Eigen::Vector3i> triangles, const CameraModel& camera,
                         const MeshRasterOptions& options = {});
// The same for a Mesh: fragment face ids are face handle indices. \pre a triangle mesh.
MeshRaster RasterizeMesh(const Mesh& mesh, const CameraModel& camera,
                         const MeshRasterOptions& options = {});

}  // namespace carousel
