#include "carousel/core/mesh.h"

#include <limits>

namespace carousel {

Mesh::Mesh() {
  add_property(chart_id_, "carousel:chart_id");
  add_property(front_view_, "carousel:front_view");
}

void Mesh::RecomputeNormals() {
  update_face_normals();
  update_vertex_normals();
}

double Mesh::FaceArea(FaceHandle face) const {
  auto fv = cfv_iter(face);
  const OpenMesh::Vec3d a = point(*fv);
  const OpenMesh::Vec3d b = point(*++fv);
  const OpenMesh::Vec3d c = point(*++fv);
  return 0.5 * OpenMesh::cross(b - a, c - a).norm();
}

double Mesh::SurfaceArea() const {
  double area = 0.0;
  for (FaceHandle face : faces()) area += FaceArea(face);
  return area;
}

void Mesh::Bounds(OpenMesh::Vec3d* min, OpenMesh::Vec3d* max) const {
  constexpr double kInf = std::numeric_limits<double>::infinity();
  *min = OpenMesh::Vec3d(kInf, kInf, kInf);
  *max = OpenMesh::Vec3d(-kInf, -kInf, -kInf);
  for (VertexHandle vertex : vertices()) {
    min->minimize(point(vertex));
    max->maximize(point(vertex));
  }
}

}  // namespace carousel
