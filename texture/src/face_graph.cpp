#include "face_graph.h"

#include <Eigen/Geometry>

namespace carousel::texture::internal {

FaceGraph BuildFaceGraph(const Mesh& mesh) {
  FaceGraph g;
  g.positions.resize(mesh.n_vertices());
  for (const auto v : mesh.vertices()) {
    const auto& p = mesh.point(v);
    g.positions[v.idx()] = Eigen::Vector3d(p[0], p[1], p[2]);
  }
  const auto n_faces = static_cast<std::size_t>(mesh.n_faces());
  g.faces.resize(n_faces);
  g.neighbours.resize(n_faces);
  g.normals.resize(n_faces);
  g.areas.resize(n_faces);
  g.centroids.resize(n_faces);
  for (const auto f : mesh.faces()) {
    // The halfedge into corner k + 1 runs along edge (k, k + 1).
    auto h = mesh.halfedge_handle(f);
    for (int k = 0; k < 3; ++k) {
      g.faces[f.idx()][k] = mesh.from_vertex_handle(h).idx();
      const auto opposite = mesh.opposite_face_handle(h);
      g.neighbours[f.idx()][k] = opposite.is_valid() ? opposite.idx() : -1;
      h = mesh.next_halfedge_handle(h);
    }
    const auto& t = g.faces[f.idx()];
    const Eigen::Vector3d& a = g.positions[t[0]];
    const Eigen::Vector3d& b = g.positions[t[1]];
    const Eigen::Vector3d& c = g.positions[t[2]];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    const double twice_area = n.norm();
    g.areas[f.idx()] = 0.5 * twice_area;
    g.normals[f.idx()] = twice_area > 0.0 ? Eigen::Vector3d(n / twice_area)
                                          : Eigen::Vector3d(Eigen::Vector3d::Zero());
    g.centroids[f.idx()] = (a + b + c) / 3.0;
  }
  g.boundary_vertex.resize(g.positions.size());
  for (const auto v : mesh.vertices()) g.boundary_vertex[v.idx()] = mesh.is_boundary(v) ? 1 : 0;
  g.fan_start.assign(g.positions.size() + 1, 0);
  for (const auto& t : g.faces)
    for (const int v : t) ++g.fan_start[v + 1];
  for (std::size_t v = 0; v < g.positions.size(); ++v) g.fan_start[v + 1] += g.fan_start[v];
  g.fan.resize(g.fan_start.back());
  std::vector<int> fill(g.fan_start.begin(), g.fan_start.end() - 1);
  for (std::size_t f = 0; f < g.faces.size(); ++f)
    for (const int v : g.faces[f]) g.fan[fill[v]++] = static_cast<int>(f);
  return g;
}

}  // namespace carousel::texture::internal
