// Mesh: the triangle mesh every stage passes along (hull -> optimized mesh -> atlas -> texture).
//
// An OpenMesh TriMesh in double precision, in the turntable frame (metres), triangles
// counter-clockwise seen from outside. Every per-element datum Carousel attaches to a mesh is
// declared here, once, with its type (STYLE.md, practice 8):
//   - vertex and face normals                  (OpenMesh standard attributes)
//   - UV per halfedge, v up (OBJ convention)   texcoord2D(halfedge); has_uvs() says if valid
//   - chart id per face                        chart_id(face), kNoChart until charted
//   - front view per face                      front_view(face), kNoView until grouped
//   - status flags for deletion                (decimation, cleanup)
// Per-halfedge UVs let a vertex on a chart seam carry one UV per chart.
#pragma once

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

namespace carousel {

struct MeshTraits : public OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  using Normal = OpenMesh::Vec3d;
  using TexCoord2D = OpenMesh::Vec2d;
  VertexAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  FaceAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::Normal);
  EdgeAttributes(OpenMesh::Attributes::Status);
  HalfedgeAttributes(OpenMesh::Attributes::Status | OpenMesh::Attributes::PrevHalfedge |
                     OpenMesh::Attributes::TexCoord2D);
};

using TriMeshBase = OpenMesh::TriMesh_ArrayKernelT<MeshTraits>;

// Property value types carry their "unset" default, so faces added later start unset too.
struct ChartId {
  int value = -1;
};
struct ViewIndex {
  int value = -1;
};

class Mesh : public TriMeshBase {
 public:
  static constexpr int kNoChart = -1;
  static constexpr int kNoView = -1;

  Mesh();
  Mesh(const Mesh& other) = default;
  Mesh& operator=(const Mesh& other) = default;
  Mesh(Mesh&& other) = default;
  Mesh& operator=(Mesh&& other) = default;
  ~Mesh() override = default;

  // Chart (texture/ partitioning) of a face; kNoChart before partitioning.
  int chart_id(FaceHandle face) const { return property(chart_id_, face).value; }
  void set_chart_id(FaceHandle face, int chart) { property(chart_id_, face).value = chart; }

  // Index into the std::vector<View> of the face's front image (texture/ grouping).
  int front_view(FaceHandle face) const { return property(front_view_, face).value; }
  void set_front_view(FaceHandle face, int view) { property(front_view_, face).value = view; }

  // UV of the corner a halfedge points to, inside the face the halfedge belongs to.
  OpenMesh::Vec2d uv(HalfedgeHandle halfedge) const { return texcoord2D(halfedge); }
  void set_uv(HalfedgeHandle halfedge, const OpenMesh::Vec2d& uv) { set_texcoord2D(halfedge, uv); }
  // True once every face's halfedges carry meaningful UVs (set by the atlas or by I/O).
  bool has_uvs() const { return has_uvs_; }
  void set_has_uvs(bool has_uvs) { has_uvs_ = has_uvs; }

  // Recomputes face and vertex normals from the geometry.
  void RecomputeNormals();
  // Area of a face, m^2.
  double FaceArea(FaceHandle face) const;
  // Total surface area, m^2.
  double SurfaceArea() const;
  // Axis-aligned bounds of the vertices; min > max when the mesh is empty.
  void Bounds(OpenMesh::Vec3d* min, OpenMesh::Vec3d* max) const;

 private:
  OpenMesh::FPropHandleT<ChartId> chart_id_;
  OpenMesh::FPropHandleT<ViewIndex> front_view_;
  bool has_uvs_ = false;
};

}  // namespace carousel
