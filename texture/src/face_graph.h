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

}  // namespace carousel::texture::internal
