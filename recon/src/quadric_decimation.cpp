#include "quadric_decimation.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numbers>
#include <queue>

#include <Eigen/Dense>

#include "carousel/core/error.h"

namespace carousel::recon::internal {
namespace {

using Quadric = Eigen::Matrix4d;

struct Candidate {
  double cost;
  int v;
  int w;
  std::uint32_t stamp_v;
  std::uint32_t stamp_w;
  Eigen::Vector3d target;
  bool operator<(const Candidate& other) const { return cost > other.cost; }  // min-heap
};

double AspectRatio(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const double longest_sq =
      std::max({(a - b).squaredNorm(), (b - c).squaredNorm(), (c - a).squaredNorm()});
  const double twice_area = (b - a).cross(c - a).norm();
  return twice_area > 0.0 ? longest_sq / twice_area : std::numeric_limits<double>::infinity();
}

class Decimator {
 public:
  Decimator(IndexedMesh* mesh, double max_normal_deviation_deg, double max_aspect_ratio)
      : mesh_(*mesh),
        cos_max_deviation_(std::cos(max_normal_deviation_deg * std::numbers::pi / 180.0)),
        max_aspect_(max_aspect_ratio) {
    const std::size_t n = mesh_.vertices.size();
    faces_of_.resize(n);
    quadric_.assign(n, Quadric::Zero());
    stamp_.assign(n, 0);
    vertex_alive_.assign(n, true);
    face_alive_.assign(mesh_.faces.size(), true);
    alive_faces_ = mesh_.faces.size();
    for (std::size_t f = 0; f < mesh_.faces.size(); ++f) {
      const auto& t = mesh_.faces[f];
      for (const int v : t) faces_of_[v].push_back(static_cast<int>(f));
      const Eigen::Vector3d& a = mesh_.vertices[t[0]];
      const Eigen::Vector3d normal = (mesh_.vertices[t[1]] - a).cross(mesh_.vertices[t[2]] - a);
      const double twice_area = normal.norm();
      if (!(twice_area > 0.0)) continue;
      const Eigen::Vector3d unit = normal / twice_area;
      const Eigen::Vector4d plane(unit.x(), unit.y(), unit.z(), -unit.dot(a));
      const Quadric k = 0.5 * twice_area * plane * plane.transpose();  // area weighted
      for (const int v : t) quadric_[v] += k;
    }
    for (std::size_t f = 0; f < mesh_.faces.size(); ++f) {
      const auto& t = mesh_.faces[f];
      for (int k = 0; k < 3; ++k) {
        const int a = t[k];
        const int b = t[(k + 1) % 3];
        if (a < b) Push(a, b);  // each interior edge once (its other face has b -> a)
      }
    }
  }

  void Run(std::size_t target_faces) {
    while (alive_faces_ > target_faces && !heap_.empty()) {
      const Candidate c = heap_.top();
      heap_.pop();
      if (!vertex_alive_[c.v] || !vertex_alive_[c.w] || stamp_[c.v] != c.stamp_v ||
          stamp_[c.w] != c.stamp_w)
        continue;
      Collapse(c);
    }
  }

 private:
  void Neighbours(int v, std::vector<int>* out) const {
    out->clear();
    for (const int f : faces_of_[v])
      for (const int u : mesh_.faces[f])
        if (u != v) out->push_back(u);
    std::sort(out->begin(), out->end());
    out->erase(std::unique(out->begin(), out->end()), out->end());
  }

  void Push(int v, int w) {
    const Quadric q = quadric_[v] + quadric_[w];
    const Eigen::Vector3d& pv = mesh_.vertices[v];
    const Eigen::Vector3d& pw = mesh_.vertices[w];
    auto cost_at = [&](const Eigen::Vector3d& x) {
      const Eigen::Vector4d h(x.x(), x.y(), x.z(), 1.0);
      return std::max(0.0, h.dot(q * h));
    };
    Eigen::Vector3d best = 0.5 * (pv + pw);
    double best_cost = cost_at(best);
    const Eigen::Matrix3d a = q.topLeftCorner<3, 3>();
    const Eigen::Vector3d b = -q.topRightCorner<3, 1>();
    const double length = (pw - pv).norm();
    const double det = a.determinant();
    const double scale = a.cwiseAbs().maxCoeff();
    if (std::abs(det) > 1e-9 * scale * scale * scale) {
      const Eigen::Vector3d x = a.inverse() * b;  // closed form for 3x3
      // Far-away optima come from nearly flat neighbourhoods: stay near the edge.
      if (x.allFinite() && (x - best).norm() <= 2.0 * length) {
        const double c = cost_at(x);
        if (c <= best_cost) {
          best = x;
          best_cost = c;
        }
      }
    }
    for (const Eigen::Vector3d* end : {&pv, &pw}) {
      const double c = cost_at(*end);
      if (c < best_cost) {
        best = *end;
        best_cost = c;
      }
    }
    heap_.push({best_cost, v, w, stamp_[v], stamp_[w], best});
  }

  void Collapse(const Candidate& c) {
    const int v = c.v;
    const int w = c.w;
    // Topology: exactly two faces on the edge, and the one-rings share exactly their two
    // opposite vertices (the link condition).
    shared_.clear();
    for (const int f : faces_of_[v]) {
      const auto& t = mesh_.faces[f];
      if (t[0] == w || t[1] == w || t[2] == w) shared_.push_back(f);
    }
    if (shared_.size() != 2) return;
    Neighbours(v, &ring_v_);
    Neighbours(w, &ring_w_);
    common_.clear();
    std::set_intersection(ring_v_.begin(), ring_v_.end(), ring_w_.begin(), ring_w_.end(),
                          std::back_inserter(common_));
    if (common_.size() != 2) return;
    if (ring_v_.size() <= 3 || ring_w_.size() <= 3) return;  // would pinch a tetrahedron
    // Geometry: surviving faces around v and w keep their orientation and shape.
    for (const int x : {v, w}) {
      for (const int f : faces_of_[x]) {
        if (f == shared_[0] || f == shared_[1]) continue;
        const auto& t = mesh_.faces[f];
        std::array<Eigen::Vector3d, 3> before, after;
        for (int k = 0; k < 3; ++k) {
          before[k] = mesh_.vertices[t[k]];
          after[k] = (t[k] == v || t[k] == w) ? c.target : before[k];
        }
        const Eigen::Vector3d n0 = (before[1] - before[0]).cross(before[2] - before[0]);
        const Eigen::Vector3d n1 = (after[1] - after[0]).cross(after[2] - after[0]);
        const double l0 = n0.norm();
        const double l1 = n1.norm();
        if (!(l1 > 0.0)) return;
        if (l0 > 0.0 && n0.dot(n1) < cos_max_deviation_ * l0 * l1) return;
        const double aspect = AspectRatio(after[0], after[1], after[2]);
        if (aspect > max_aspect_ && aspect > AspectRatio(before[0], before[1], before[2])) return;
      }
    }
    // Collapse w into v.
    mesh_.vertices[v] = c.target;
    quadric_[v] += quadric_[w];
    vertex_alive_[w] = false;
    for (const int f : shared_) {
      face_alive_[f] = false;
      --alive_faces_;
      for (const int u : mesh_.faces[f]) {
        if (u == w) continue;
        auto& list = faces_of_[u];
        list.erase(std::remove(list.begin(), list.end(), f), list.end());
      }
    }
    for (const int f : faces_of_[w]) {
      if (!face_alive_[f]) continue;
      for (int& u : mesh_.faces[f])
        if (u == w) u = v;
      faces_of_[v].push_back(f);
    }
    faces_of_[w].clear();
    faces_of_[w].shrink_to_fit();
    ++stamp_[v];
    Neighbours(v, &ring_v_);
    for (const int u : ring_v_) Push(v, u);
  }

 public:
  void Compact() {
    std::vector<int> remap(mesh_.vertices.size(), -1);
    IndexedMesh out;
    for (std::size_t f = 0; f < mesh_.faces.size(); ++f) {
      if (!face_alive_[f]) continue;
      std::array<int, 3> t{};
      for (int k = 0; k < 3; ++k) {
        const int u = mesh_.faces[f][k];
        if (remap[u] < 0) {
          remap[u] = static_cast<int>(out.vertices.size());
          out.vertices.push_back(mesh_.vertices[u]);
        }
        t[k] = remap[u];
      }
      out.faces.push_back(t);
    }
    mesh_ = std::move(out);
  }

 private:
  IndexedMesh& mesh_;
  double cos_max_deviation_;
  double max_aspect_;
  std::vector<std::vector<int>> faces_of_;
  std::vector<Quadric, Eigen::aligned_allocator<Quadric>> quadric_;
  std::vector<std::uint32_t> stamp_;
  std::vector<bool> vertex_alive_;
  std::vector<bool> face_alive_;
  std::size_t alive_faces_ = 0;
  std::priority_queue<Candidate> heap_;
  std::vector<int> shared_, ring_v_, ring_w_, common_;
};

}  // namespace

IndexedMesh ToIndexed(const Mesh& mesh) {
  IndexedMesh out;
  std::vector<int> remap(mesh.n_vertices(), -1);
  for (const auto v : mesh.vertices()) {
    remap[v.idx()] = static_cast<int>(out.vertices.size());
    const auto& p = mesh.point(v);
    out.vertices.emplace_back(p[0], p[1], p[2]);
  }
  for (const auto f : mesh.faces()) {
    std::array<int, 3> t{};
    int k = 0;
    for (const auto v : mesh.fv_range(f)) t[k++] = remap[v.idx()];
    out.faces.push_back(t);
  }
  return out;
}

Mesh FromIndexed(const IndexedMesh& mesh) {
  Mesh out;
  std::vector<Mesh::VertexHandle> handles;
  handles.reserve(mesh.vertices.size());
  for (const auto& p : mesh.vertices) handles.push_back(out.add_vertex({p.x(), p.y(), p.z()}));
  for (const auto& t : mesh.faces) {
    const auto face = out.add_face(handles[t[0]], handles[t[1]], handles[t[2]]);
    CAROUSEL_CHECK(face.is_valid(), "decimation produced a non-manifold face");
  }
  out.RecomputeNormals();
  return out;
}

void DecimateIndexed(IndexedMesh* mesh, std::size_t target_faces, double max_normal_deviation_deg,
                     double max_aspect_ratio) {
  if (mesh->faces.size() <= target_faces) return;
  Decimator decimator(mesh, max_normal_deviation_deg, max_aspect_ratio);
  decimator.Run(target_faces);
  decimator.Compact();
}

}  // namespace carousel::recon::internal
