// Geometric queries on triangle meshes: closest points (AABB tree), surface sampling,
// self-intersection search, and the topology and volume figures the pipeline checks its meshes
// with (recon's hull and optimized mesh, texture's inputs, the tests' MeshNear).
//
// Frames and units are the mesh's own (metres in the turntable frame for Carousel meshes).
#pragma once

#include <cstdint>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "carousel/core/mesh.h"

namespace carousel {

// A static bounding-volume hierarchy over triangles for closest-point queries.
class TriangleTree {
 public:
  struct Triangle {
    Eigen::Vector3d a, b, c;
  };
  TriangleTree() = default;
  explicit TriangleTree(std::vector<Triangle> triangles);
  // The mesh's non-deleted faces, in face-handle order of the non-deleted ones.
  explicit TriangleTree(const Mesh& mesh);

  struct Hit {
    Eigen::Vector3d point;     // closest point on the surface
    double distance = 0.0;     // to the query point
    std::size_t triangle = 0;  // index into triangles()
  };
  // The closest surface point to `query`. \pre !empty().
  Hit ClosestPoint(const Eigen::Vector3d& query) const;
  // Indices of triangles whose bounding box overlaps `box`.
  void Overlapping(const Eigen::AlignedBox3d& box, std::vector<std::size_t>* out) const;

  bool empty() const { return triangles_.empty(); }
  const std::vector<Triangle>& triangles() const { return triangles_; }

 private:
  struct Node {
    Eigen::AlignedBox3d box;
    std::uint32_t first = 0;  // leaf: first index into order_; inner: left child
    std::uint32_t count = 0;  // leaf: number of triangles; inner: 0
    std::uint32_t right = 0;  // inner: right child
  };
  std::uint32_t Build(std::uint32_t begin, std::uint32_t end);

  std::vector<Triangle> triangles_;
  std::vector<Eigen::AlignedBox3d> boxes_;  // per triangle, in triangles_' order
  std::vector<std::uint32_t> order_;
  std::vector<Node> nodes_;
};

// Closest point on triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5).
Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c);

// `count` points spread over the surface with probability proportional to area; deterministic
// for a given seed.
std::vector<Eigen::Vector3d> SampleSurface(const Mesh& mesh, std::size_t count,
                                           std::uint64_t seed = 1);

// Pairs of faces (indices of non-deleted faces in handle order) that intersect other than
// along shared vertices or edges. Stops after `max_pairs`.
std::vector<std::pair<int, int>> FindSelfIntersections(const Mesh& mesh,
                                                       std::size_t max_pairs = 100);

struct MeshTopology {
  std::size_t vertices = 0;
  std::size_t faces = 0;
  std::size_t boundary_edges = 0;         // edges with one face
  std::size_t non_manifold_vertices = 0;  // vertices whose faces form more than one fan
  std::size_t isolated_vertices = 0;
  std::size_t components = 0;        // face-connected components
  std::size_t degenerate_faces = 0;  // area below 1e-18 (m^2)
  int euler_characteristic = 0;      // V - E + F
  bool closed() const { return boundary_edges == 0; }
  bool manifold() const { return non_manifold_vertices == 0; }
};
MeshTopology AnalyzeTopology(const Mesh& mesh);

// Signed enclosed volume (positive for a closed mesh with outward, counter-clockwise faces).
double SignedVolume(const Mesh& mesh);

// How far points on `inner` lie outside the closed surface `outer` (side from the closest
// face's orientation), from `samples` points: the largest such distance (0 if none) and the
// mean unsigned distance to `outer`.
struct Containment {
  double max_outside = 0.0;
  double mean_distance = 0.0;
};
Containment MeasureContainment(const Mesh& inner, const Mesh& outer, std::size_t samples = 20000);

// Chamfer-style distances between two surfaces from `samples` points on each.
struct SurfaceDistance {
  double mean_a_to_b = 0.0;  // mean distance of points on a to surface b
  double mean_b_to_a = 0.0;
  double max_a_to_b = 0.0;  // Hausdorff in each direction (over the samples)
  double max_b_to_a = 0.0;
  double chamfer() const { return 0.5 * (mean_a_to_b + mean_b_to_a); }
  double hausdorff() const { return max_a_to_b > max_b_to_a ? max_a_to_b : max_b_to_a; }
};
SurfaceDistance MeasureSurfaceDistance(const Mesh& a, const Mesh& b, std::size_t samples = 20000);

}  // namespace carousel
