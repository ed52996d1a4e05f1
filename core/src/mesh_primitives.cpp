#include "carousel/core/mesh_primitives.h"

#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>
#include <vector>

#include "carousel/core/error.h"

namespace carousel {
namespace {

using Vec3d = OpenMesh::Vec3d;
using VertexHandle = Mesh::VertexHandle;

void AddTriangle(Mesh& mesh, VertexHandle a, VertexHandle b, VertexHandle c) {
  const Mesh::FaceHandle face = mesh.add_face(a, b, c);
  CAROUSEL_CHECK(face.is_valid(), "primitive generator produced a non-manifold triangle");
}

}  // namespace

Mesh MakeIcosphere(double radius, int subdivisions, const Vec3d& centre) {
  CAROUSEL_THROW_IF(!(radius > 0), InvalidArgument, "MakeIcosphere: radius must be > 0");
  CAROUSEL_THROW_IF(subdivisions < 0 || subdivisions > 8, InvalidArgument,
                    "MakeIcosphere: subdivisions must be in 0..8, got " << subdivisions);
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3d> points = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0},
                               {0, -1, t}, {0, 1, t}, {0, -1, -t}, {0, 1, -t},
                               {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  std::vector<std::array<int, 3>> triangles = {
      {0, 11, 5},  {0, 5, 1},  {0, 1, 7},  {0, 7, 10}, {0, 10, 11}, {1, 5, 9}, {5, 11, 4},
      {11, 10, 2}, {10, 7, 6}, {7, 1, 8},  {3, 9, 4},  {3, 4, 2},   {3, 2, 6}, {3, 6, 8},
      {3, 8, 9},   {4, 9, 5},  {2, 4, 11}, {6, 2, 10}, {8, 6, 7},   {9, 8, 1}};
  for (Vec3d& p : points) p.normalize();
  for (int level = 0; level < subdivisions; ++level) {
    std::map<std::pair<int, int>, int> midpoints;
    auto midpoint = [&](int a, int b) {
      const std::pair<int, int> key = std::minmax(a, b);
      auto [it, inserted] = midpoints.try_emplace(key, static_cast<int>(points.size()));
      if (inserted) points.push_back((points[a] + points[b]).normalized());
      return it->second;
    };
    std::vector<std::array<int, 3>> finer;
    finer.reserve(triangles.size() * 4);
    for (const auto& [a, b, c] : triangles) {
      const int ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      finer.push_back({a, ab, ca});
      finer.push_back({b, bc, ab});
      finer.push_back({c, ca, bc});
      finer.push_back({ab, bc, ca});
    }
    triangles = std::move(finer);
  }
  Mesh mesh;
  std::vector<VertexHandle> handles;
  handles.reserve(points.size());
  for (const Vec3d& p : points) handles.push_back(mesh.add_vertex(centre + radius * p));
  for (const auto& [a, b, c] : triangles) AddTriangle(mesh, handles[a], handles[b], handles[c]);
  mesh.RecomputeNormals();
  return mesh;
}

Mesh MakeTorus(double major_radius, double minor_radius, int major_segments, int minor_segments) {
  CAROUSEL_THROW_IF(!(minor_radius > 0 && major_radius > minor_radius), InvalidArgument,
                    "MakeTorus: need major_radius > minor_radius > 0");
  CAROUSEL_THROW_IF(major_segments < 3 || minor_segments < 3, InvalidArgument,
                    "MakeTorus: need at least 3 segments each way");
  Mesh mesh;
  std::vector<VertexHandle> grid(static_cast<std::size_t>(major_segments) * minor_segments);
  for (int i = 0; i < major_segments; ++i) {
    const double u = 2.0 * std::numbers::pi * i / major_segments;
    for (int j = 0; j < minor_segments; ++j) {
      const double v = 2.0 * std::numbers::pi * j / minor_segments;
      const double r = major_radius + minor_radius * std::cos(v);
      grid[i * minor_segments + j] =
          mesh.add_vertex({r * std::cos(u), r * std::sin(u), minor_radius * std::sin(v)});
    }
  }
  auto at = [&](int i, int j) {
    return grid[(i % major_segments) * minor_segments + (j % minor_segments)];
  };
  for (int i = 0; i < major_segments; ++i) {
    for (int j = 0; j < minor_segments; ++j) {
      AddTriangle(mesh, at(i, j), at(i + 1, j), at(i + 1, j + 1));
      AddTriangle(mesh, at(i, j), at(i + 1, j + 1), at(i, j + 1));
    }
  }
  mesh.RecomputeNormals();
  return mesh;
}

Mesh MakeCylinder(double radius, double height, int segments, int rings) {
  CAROUSEL_THROW_IF(!(radius > 0 && height > 0), InvalidArgument,
                    "MakeCylinder: radius and height must be > 0");
  CAROUSEL_THROW_IF(segments < 3 || rings < 1, InvalidArgument,
                    "MakeCylinder: need segments >= 3 and rings >= 1");
  Mesh mesh;
  std::vector<VertexHandle> grid(static_cast<std::size_t>(rings + 1) * segments);
  for (int k = 0; k <= rings; ++k) {
    const double z = height * k / rings;
    for (int i = 0; i < segments; ++i) {
      const double u = 2.0 * std::numbers::pi * i / segments;
      grid[k * segments + i] = mesh.add_vertex({radius * std::cos(u), radius * std::sin(u), z});
    }
  }
  auto at = [&](int k, int i) { return grid[k * segments + (i % segments)]; };
  for (int k = 0; k < rings; ++k) {
    for (int i = 0; i < segments; ++i) {
      AddTriangle(mesh, at(k, i), at(k, i + 1), at(k + 1, i + 1));
      AddTriangle(mesh, at(k, i), at(k + 1, i + 1), at(k + 1, i));
    }
  }
  const VertexHandle bottom = mesh.add_vertex({0, 0, 0});
  const VertexHandle top = mesh.add_vertex({0, 0, height});
  for (int i = 0; i < segments; ++i) {
    AddTriangle(mesh, bottom, at(0, i + 1), at(0, i));
    AddTriangle(mesh, top, at(rings, i), at(rings, i + 1));
  }
  mesh.RecomputeNormals();
  return mesh;
}

Mesh MakeDisc(double radius, int segments, int rings) {
  CAROUSEL_THROW_IF(!(radius > 0), InvalidArgument, "MakeDisc: radius must be > 0");
  CAROUSEL_THROW_IF(segments < 3 || rings < 1, InvalidArgument,
                    "MakeDisc: need segments >= 3 and rings >= 1");
  Mesh mesh;
  const VertexHandle centre = mesh.add_vertex({0, 0, 0});
  std::vector<VertexHandle> grid(static_cast<std::size_t>(rings) * segments);
  for (int k = 1; k <= rings; ++k) {
    const double r = radius * k / rings;
    for (int i = 0; i < segments; ++i) {
      const double u = 2.0 * std::numbers::pi * i / segments;
      grid[(k - 1) * segments + i] = mesh.add_vertex({r * std::cos(u), r * std::sin(u), 0.0});
    }
  }
  auto at = [&](int k, int i) { return grid[(k - 1) * segments + (i % segments)]; };
  for (int i = 0; i < segments; ++i) AddTriangle(mesh, centre, at(1, i), at(1, i + 1));
  for (int k = 1; k < rings; ++k) {
    for (int i = 0; i < segments; ++i) {
      AddTriangle(mesh, at(k, i), at(k + 1, i), at(k + 1, i + 1));
      AddTriangle(mesh, at(k, i), at(k + 1, i + 1), at(k, i + 1));
    }
  }
  mesh.RecomputeNormals();
  return mesh;
}

}  // namespace carousel
