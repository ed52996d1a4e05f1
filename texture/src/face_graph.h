// Internal: a compact, index-based view of a triangle mesh for the atlas stages (charts,
// flattening, packing): positions, faces, face normals, areas and centroids, the face across
// each edge and the faces around each vertex. Built once per mesh.
#pragma once

#include <array>
#include <vector>

#include <Eigen/Core>

#include "carousel/core/mesh.h"

namespace carousel::texture::internal {

struct FaceGraph {
  std::vector<Eigen::Vector3d> positions;      // per vertex
  std::vector<std::array<int, 3>> faces;       // vertex indices, counter-clockwise
  std::vector<Eigen::Vector3d> normals;        // per face, unit (zero for degenerate faces)
  std::vector<double> areas;                   // per face, m^2
  std::vector<Eigen::Vector3d> centroids;      // per face
  std::vector<std::array<int, 3>> neighbours;  // face across edge (k, k + 1), or -1
  std::vector<int> fan_start;                  // faces around vertex v: fan[fan_start[v] ..
  std::vector<int> fan;                        //   fan_start[v + 1])
  std::vector<char> boundary_vertex;           // on the mesh's boundary

  int face_count() const { return static_cast<int>(faces.size()); }
  int vertex_count() const { return static_cast<int>(positions.size()); }
  // Corner of `face` at vertex `v`, or -1.
  int CornerOf(int face, int v) const {
    for (int k = 0; k < 3; ++k)
      if (faces[face][k] == v) return k;
    return -1;
  }
};

// \pre a valid OpenMesh triangle mesh (manifold by construction); faces indexed as in the mesh.
FaceGraph BuildFaceGraph(const Mesh& mesh);

// Squared L2 stretch (Sander, Snyder, Gortler, Hoppe 2001) of the map from a UV triangle q
// (signed area a_uv > 0) to its surface triangle p: the mean squared length of the surface
// position's derivatives along u and v.
inline double L2StretchSquared(const Eigen::Vector3d& p1, const Eigen::Vector3d& p2,
                               const Eigen::Vector3d& p3, const Eigen::Vector2d& q1,
                               const Eigen::Vector2d& q2, const Eigen::Vector2d& q3, double a_uv) {
  const Eigen::Vector3d ss =
      (p1 * (q2.y() - q3.y()) + p2 * (q3.y() - q1.y()) + p3 * (q1.y() - q2.y())) / (2 * a_uv);
  const Eigen::Vector3d st =
      (p1 * (q3.x() - q2.x()) + p2 * (q1.x() - q3.x()) + p3 * (q2.x() - q1.x())) / (2 * a_uv);
  return 0.5 * (ss.squaredNorm() + st.squaredNorm());
}

}  // namespace carousel::texture::internal
