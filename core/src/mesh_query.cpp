#include "carousel/core/mesh_query.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numeric>
#include <random>

#include "carousel/core/error.h"

namespace carousel {
namespace {

constexpr std::uint32_t kLeafSize = 4;

Eigen::Vector3d ToEigen(const OpenMesh::Vec3d& p) { return {p[0], p[1], p[2]}; }

Eigen::AlignedBox3d BoxOf(const TriangleTree::Triangle& t) {
  Eigen::AlignedBox3d box(t.a);
  box.extend(t.b);
  box.extend(t.c);
  return box;
}

std::vector<TriangleTree::Triangle> TrianglesOf(const Mesh& mesh) {
  std::vector<TriangleTree::Triangle> triangles;
  triangles.reserve(mesh.n_faces());
  for (const auto face : mesh.faces()) {
    auto it = mesh.cfv_begin(face);
    TriangleTree::Triangle t;
    t.a = ToEigen(mesh.point(*it));
    t.b = ToEigen(mesh.point(*++it));
    t.c = ToEigen(mesh.point(*++it));
    triangles.push_back(t);
  }
  return triangles;
}

// Segment p->q crosses the interior of triangle (a, b, c)? Touching within `eps` (relative)
// does not count, so triangles meeting along an edge or a vertex are not reported.
bool SegmentCrossesTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& q,
                            const Eigen::Vector3d& a, const Eigen::Vector3d& b,
                            const Eigen::Vector3d& c) {
  constexpr double kEps = 1e-9;
  const Eigen::Vector3d dir = q - p;
  const Eigen::Vector3d e1 = b - a;
  const Eigen::Vector3d e2 = c - a;
  const Eigen::Vector3d h = dir.cross(e2);
  const double det = e1.dot(h);
  const double scale = e1.norm() * e2.norm() * dir.norm();
  if (std::abs(det) <= kEps * scale) return false;  // parallel or degenerate
  const double inv = 1.0 / det;
  const Eigen::Vector3d s = p - a;
  const double u = inv * s.dot(h);
  if (u <= kEps || u >= 1.0 - kEps) return false;
  const Eigen::Vector3d qv = s.cross(e1);
  const double v = inv * dir.dot(qv);
  if (v <= kEps || u + v >= 1.0 - kEps) return false;
  const double t = inv * e2.dot(qv);
  return t > kEps && t < 1.0 - kEps;
}

}  // namespace

Eigen::Vector3d ClosestPointOnTriangle(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                                       const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a;
  const Eigen::Vector3d ac = c - a;
  const Eigen::Vector3d ap = p - a;
  const double d1 = ab.dot(ap);
  const double d2 = ac.dot(ap);
  if (d1 <= 0.0 && d2 <= 0.0) return a;
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp);
  const double d4 = ac.dot(bp);
  if (d3 >= 0.0 && d4 <= d3) return b;
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0) return a + ab * (d1 / (d1 - d3));
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp);
  const double d6 = ac.dot(cp);
  if (d6 >= 0.0 && d5 <= d6) return c;
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0) return a + ac * (d2 / (d2 - d6));
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0)
    return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
  const double sum = va + vb + vc;
  if (!(std::abs(sum) > 0.0)) return a;  // degenerate triangle
  const double v = vb / sum;
  const double w = vc / sum;
  return a + ab * v + ac * w;
}

TriangleTree::TriangleTree(const Mesh& mesh) : TriangleTree(TrianglesOf(mesh)) {}

TriangleTree::TriangleTree(std::vector<Triangle> triangles) : triangles_(std::move(triangles)) {
  CAROUSEL_THROW_IF(triangles_.size() >= std::numeric_limits<std::uint32_t>::max() / 2,
                    InvalidArgument,
                    "TriangleTree: too many triangles (" << triangles_.size() << ")");
  order_.resize(triangles_.size());
  std::iota(order_.begin(), order_.end(), 0U);
  boxes_.reserve(triangles_.size());
  for (const Triangle& t : triangles_) boxes_.push_back(BoxOf(t));
  if (!triangles_.empty()) {
    nodes_.reserve(2 * triangles_.size() / kLeafSize + 1);
    Build(0, static_cast<std::uint32_t>(triangles_.size()));
  }
}

std::uint32_t TriangleTree::Build(std::uint32_t begin, std::uint32_t end) {
  const auto index = static_cast<std::uint32_t>(nodes_.size());
  nodes_.emplace_back();
  Eigen::AlignedBox3d box;
  Eigen::AlignedBox3d centroids;
  for (std::uint32_t i = begin; i < end; ++i) {
    const Eigen::AlignedBox3d& b = boxes_[order_[i]];
    box.extend(b);
    centroids.extend(b.center());
  }
  nodes_[index].box = box;
  if (end - begin <= kLeafSize) {
    nodes_[index].first = begin;
    nodes_[index].count = end - begin;
    return index;
  }
  int axis = 0;
  centroids.sizes().maxCoeff(&axis);
  const std::uint32_t middle = begin + (end - begin) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + middle, order_.begin() + end,
                   [&](std::uint32_t x, std::uint32_t y) {
                     const Triangle& tx = triangles_[x];
                     const Triangle& ty = triangles_[y];
                     return tx.a[axis] + tx.b[axis] + tx.c[axis] <
                            ty.a[axis] + ty.b[axis] + ty.c[axis];
                   });
  const std::uint32_t left = Build(begin, middle);
  const std::uint32_t right = Build(middle, end);
  nodes_[index].first = left;
  nodes_[index].right = right;
  nodes_[index].count = 0;
  return index;
}

TriangleTree::Hit TriangleTree::ClosestPoint(const Eigen::Vector3d& query) const {
  CAROUSEL_THROW_IF(triangles_.empty(), InvalidArgument, "TriangleTree: no triangles");
  Hit best;
  double best_sq = std::numeric_limits<double>::infinity();
  std::uint32_t stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (node.box.squaredExteriorDistance(query) >= best_sq) continue;
    if (node.count > 0) {
      for (std::uint32_t i = node.first; i < node.first + node.count; ++i) {
        const Triangle& t = triangles_[order_[i]];
        const Eigen::Vector3d point = ClosestPointOnTriangle(query, t.a, t.b, t.c);
        const double sq = (point - query).squaredNorm();
        if (sq < best_sq) {
          best_sq = sq;
          best.point = point;
          best.triangle = order_[i];
        }
      }
      continue;
    }
    const double dl = nodes_[node.first].box.squaredExteriorDistance(query);
    const double dr = nodes_[node.right].box.squaredExteriorDistance(query);
    if (top + 2 > 128) continue;  // cannot happen for a median-split tree of < 2^32 triangles
    // Visit the nearer child first.
    if (dl < dr) {
      stack[top++] = node.right;
      stack[top++] = node.first;
    } else {
      stack[top++] = node.first;
      stack[top++] = node.right;
    }
  }
  best.distance = std::sqrt(best_sq);
  return best;
}

void TriangleTree::Overlapping(const Eigen::AlignedBox3d& box,
                               std::vector<std::size_t>* out) const {
  out->clear();
  if (nodes_.empty()) return;
  // A fixed stack (a median-split tree of < 2^32 triangles is at most 32 deep): this runs once
  // per face in FindSelfIntersections, and an allocation per query cost more than the query.
  std::array<std::uint32_t, 128> stack;
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& node = nodes_[stack[--top]];
    if (!node.box.intersects(box)) continue;
    if (node.count > 0) {
      for (std::uint32_t i = node.first; i < node.first + node.count; ++i)
        if (boxes_[order_[i]].intersects(box)) out->push_back(order_[i]);
      continue;
    }
    if (top + 2 > static_cast<int>(stack.size())) continue;  // cannot happen, see above
    stack[top++] = node.first;
    stack[top++] = node.right;
  }
}

std::vector<Eigen::Vector3d> SampleSurface(const Mesh& mesh, std::size_t count,
                                           std::uint64_t seed) {
  const std::vector<TriangleTree::Triangle> triangles = TrianglesOf(mesh);
  CAROUSEL_THROW_IF(triangles.empty(), InvalidArgument, "SampleSurface: the mesh has no faces");
  std::vector<double> cumulative(triangles.size());
  double total = 0.0;
  for (std::size_t i = 0; i < triangles.size(); ++i) {
    const auto& t = triangles[i];
    total += 0.5 * (t.b - t.a).cross(t.c - t.a).norm();
    cumulative[i] = total;
  }
  CAROUSEL_THROW_IF(!(total > 0.0), InvalidArgument, "SampleSurface: the mesh has no area");
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::vector<Eigen::Vector3d> points;
  points.reserve(count);
  for (std::size_t i = 0; i < count; ++i) {
    const double pick = uniform(random) * total;
    const auto it = std::lower_bound(cumulative.begin(), cumulative.end(), pick);
    const auto& t = triangles[std::min<std::size_t>(it - cumulative.begin(), triangles.size() - 1)];
    double u = uniform(random);
    double v = uniform(random);
    if (u + v > 1.0) {
      u = 1.0 - u;
      v = 1.0 - v;
    }
    points.push_back(t.a + u * (t.b - t.a) + v * (t.c - t.a));
  }
  return points;
}

std::vector<std::pair<int, int>> FindSelfIntersections(const Mesh& mesh, std::size_t max_pairs) {
  std::vector<std::array<int, 3>> corners;
  corners.reserve(mesh.n_faces());
  for (const auto face : mesh.faces()) {
    std::array<int, 3> c{};
    int k = 0;
    for (const auto v : mesh.fv_range(face)) c[k++] = v.idx();
    corners.push_back(c);
  }
  const TriangleTree tree(mesh);
  const auto& triangles = tree.triangles();
  std::vector<std::pair<int, int>> pairs;
  std::vector<std::size_t> candidates;
  for (std::size_t i = 0; i < triangles.size() && pairs.size() < max_pairs; ++i) {
    tree.Overlapping(BoxOf(triangles[i]), &candidates);
    for (const std::size_t j : candidates) {
      if (j <= i) continue;
      bool shares = false;
      for (const int a : corners[i])
        for (const int b : corners[j]) shares = shares || a == b;
      if (shares) continue;
      const auto& s = triangles[i];
      const auto& t = triangles[j];
      const bool hit = SegmentCrossesTriangle(s.a, s.b, t.a, t.b, t.c) ||
                       SegmentCrossesTriangle(s.b, s.c, t.a, t.b, t.c) ||
                       SegmentCrossesTriangle(s.c, s.a, t.a, t.b, t.c) ||
                       SegmentCrossesTriangle(t.a, t.b, s.a, s.b, s.c) ||
                       SegmentCrossesTriangle(t.b, t.c, s.a, s.b, s.c) ||
                       SegmentCrossesTriangle(t.c, t.a, s.a, s.b, s.c);
      if (hit) {
        pairs.emplace_back(static_cast<int>(i), static_cast<int>(j));
        if (pairs.size() >= max_pairs) break;
      }
    }
  }
  return pairs;
}

MeshTopology AnalyzeTopology(const Mesh& mesh) {
  MeshTopology topology;
  std::size_t edges = 0;
  for (const auto v : mesh.vertices()) {
    ++topology.vertices;
    if (mesh.is_isolated(v)) {
      ++topology.isolated_vertices;
    } else if (!mesh.is_manifold(v)) {
      ++topology.non_manifold_vertices;
    }
  }
  for (const auto e : mesh.edges()) {
    ++edges;
    if (mesh.is_boundary(e)) ++topology.boundary_edges;
  }
  std::vector<int> component(mesh.n_faces(), -1);
  std::vector<OpenMesh::FaceHandle> stack;
  for (const auto face : mesh.faces()) {
    ++topology.faces;
    if (mesh.calc_face_area(face) < 1e-18) ++topology.degenerate_faces;
    if (component[face.idx()] >= 0) continue;
    const int id = static_cast<int>(topology.components++);
    component[face.idx()] = id;
    stack.assign(1, face);
    while (!stack.empty()) {
      const auto f = stack.back();
      stack.pop_back();
      for (const auto g : mesh.ff_range(f)) {
        if (component[g.idx()] >= 0) continue;
        component[g.idx()] = id;
        stack.push_back(g);
      }
    }
  }
  topology.euler_characteristic = static_cast<int>(topology.vertices) - static_cast<int>(edges) +
                                  static_cast<int>(topology.faces);
  return topology;
}

double SignedVolume(const Mesh& mesh) {
  double volume = 0.0;
  for (const auto face : mesh.faces()) {
    auto it = mesh.cfv_begin(face);
    const Eigen::Vector3d a = ToEigen(mesh.point(*it));
    const Eigen::Vector3d b = ToEigen(mesh.point(*++it));
    const Eigen::Vector3d c = ToEigen(mesh.point(*++it));
    volume += a.dot(b.cross(c));
  }
  return volume / 6.0;
}

Containment MeasureContainment(const Mesh& inner, const Mesh& outer, std::size_t samples) {
  const TriangleTree tree(outer);
  // Which side of `outer` a point lies on is judged at its closest point by the angle-weighted
  // pseudo-normal of the feature there (Baerentzen and Aanaes 2005): face, edge (the two
  // faces' normals) or vertex (its faces' normals weighted by their angles at it). The closest
  // face's own normal gives the wrong side near concave edges and vertices.
  std::vector<Mesh::FaceHandle> faces;  // in the tree's triangle order
  faces.reserve(outer.n_faces());
  for (const auto f : outer.faces()) faces.push_back(f);
  std::vector<Eigen::Vector3d> face_normal(outer.n_faces(), Eigen::Vector3d::Zero());
  std::vector<Eigen::Vector3d> vertex_normal(outer.n_vertices(), Eigen::Vector3d::Zero());
  for (std::size_t i = 0; i < faces.size(); ++i) {
    const auto& t = tree.triangles()[i];
    const Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a);
    const double norm = n.norm();
    if (norm > 0.0) face_normal[faces[i].idx()] = n / norm;
    const std::array<Eigen::Vector3d, 3> p = {t.a, t.b, t.c};
    int k = 0;
    for (const auto v : outer.fv_range(faces[i])) {
      const Eigen::Vector3d u = p[(k + 1) % 3] - p[k];
      const Eigen::Vector3d w = p[(k + 2) % 3] - p[k];
      const double angle = std::atan2(u.cross(w).norm(), u.dot(w));
      vertex_normal[v.idx()] += angle * face_normal[faces[i].idx()];
      ++k;
    }
  }
  Containment result;
  const auto points = SampleSurface(inner, samples, 5);
  for (const auto& p : points) {
    const auto hit = tree.ClosestPoint(p);
    const auto face = faces[hit.triangle];
    const auto& t = tree.triangles()[hit.triangle];
    // Barycentric coordinates of the closest point.
    const Eigen::Vector3d n = (t.b - t.a).cross(t.c - t.a);
    const double area = n.squaredNorm();
    std::array<double, 3> bary = {1.0, 0.0, 0.0};
    if (area > 0.0) {
      bary[1] = (hit.point - t.a).cross(t.c - t.a).dot(n) / area;
      bary[2] = (t.b - t.a).cross(hit.point - t.a).dot(n) / area;
      bary[0] = 1.0 - bary[1] - bary[2];
    }
    constexpr double kOn = 1e-7;
    std::array<Mesh::VertexHandle, 3> v;
    int k = 0;
    for (const auto vh : outer.fv_range(face)) v[k++] = vh;
    int zeros = 0;
    for (const double b : bary) zeros += b < kOn ? 1 : 0;
    Eigen::Vector3d normal = face_normal[face.idx()];
    if (zeros >= 2) {  // at a vertex
      for (int j = 0; j < 3; ++j)
        if (bary[j] >= kOn) normal = vertex_normal[v[j].idx()];
    } else if (zeros == 1) {  // on an edge: the face across it as well
      for (int j = 0; j < 3; ++j) {
        if (bary[j] >= kOn) continue;
        const auto h = outer.find_halfedge(v[(j + 1) % 3], v[(j + 2) % 3]);
        if (h.is_valid()) {
          const auto across = outer.opposite_face_handle(h);
          if (across.is_valid()) normal += face_normal[across.idx()];
        }
      }
    }
    if ((p - hit.point).dot(normal) > 0.0)
      result.max_outside = std::max(result.max_outside, hit.distance);
    result.mean_distance += hit.distance;
  }
  result.mean_distance /= static_cast<double>(points.size());
  return result;
}

SurfaceDistance MeasureSurfaceDistance(const Mesh& a, const Mesh& b, std::size_t samples) {
  const TriangleTree tree_a(a);
  const TriangleTree tree_b(b);
  SurfaceDistance result;
  auto one_way = [&](const Mesh& from, const TriangleTree& to, double* mean, double* max) {
    const auto points = SampleSurface(from, samples, 7);
    double sum = 0.0;
    for (const auto& p : points) {
      const double d = to.ClosestPoint(p).distance;
      sum += d;
      *max = std::max(*max, d);
    }
    *mean = sum / static_cast<double>(points.size());
  };
  one_way(a, tree_b, &result.mean_a_to_b, &result.max_a_to_b);
  one_way(b, tree_a, &result.mean_b_to_a, &result.max_b_to_a);
  return result;
}

}  // namespace carousel
