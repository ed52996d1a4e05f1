#include "carousel/core/mesh_primitives.h"

#include <array>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>
#include <vector>

#include "carousel/core/error.h"
#include "carousel/core/marching_tetrahedra.h"

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

namespace {

void CheckBlobArguments(int resolution, double noise) {
  CAROUSEL_THROW_IF(resolution < 4 || resolution > 512, InvalidArgument,
                    "blob: resolution must be in 4..512, got " << resolution);
  CAROUSEL_THROW_IF(!(noise >= 0.0), InvalidArgument, "blob: noise must be >= 0");
}

// A Gaussian lobe of a blob's field: centre, radius, weight.
struct Lobe {
  Vec3d centre;
  double sigma;
  double weight;
};

// Deterministic uniform numbers in [0, 1) from a seed (xorshift64).
class BlobRandom {
 public:
  explicit BlobRandom(std::uint64_t seed) : state_(seed * 0x9E3779B97F4A7C15ull + 1) {}
  double Next() {
    state_ ^= state_ << 13;
    state_ ^= state_ >> 7;
    state_ ^= state_ << 17;
    return static_cast<double>(state_ >> 11) * (1.0 / 9007199254740992.0);
  }

 private:
  std::uint64_t state_;
};

// The zero set of -0.5 + the lobes' sum + noise over [-1, 1]^3, contoured by marching
// tetrahedra on a resolution^3 grid.
Mesh ContourLobes(const std::vector<Lobe>& lobes, int resolution, double noise,
                  BlobRandom& random) {
  const int n = resolution + 1;
  const double h = 2.0 / resolution;
  auto corner = [&](int i, int j, int k) { return Vec3d(-1 + i * h, -1 + j * h, -1 + k * h); };
  std::vector<double> field(static_cast<std::size_t>(n) * n * n);
  auto index = [&](int i, int j, int k) { return (static_cast<std::size_t>(k) * n + j) * n + i; };
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) {
        const Vec3d x = corner(i, j, k);
        double f = -0.5;
        for (const Lobe& lobe : lobes)
          f += lobe.weight * std::exp(-(x - lobe.centre).sqrnorm() / (2 * lobe.sigma * lobe.sigma));
        // Noise in the field: bumps of up to about `noise` cells (the field's slope at the
        // surface is about 1.5 per unit length), deterministic per corner.
        f += noise * h * 1.5 * (2.0 * random.Next() - 1.0);
        if (f == 0.0) f = -1e-12;
        field[index(i, j, k)] = f;
      }
  // Marching tetrahedra (marching_tetrahedra.h), a vertex per edge that changes sign (keyed
  // by the edge's first corner and direction).
  Mesh mesh;
  std::map<std::uint64_t, VertexHandle> vertex_of_edge;
  for (int k = 0; k < resolution; ++k)
    for (int j = 0; j < resolution; ++j)
      for (int i = 0; i < resolution; ++i) {
        std::array<double, 8> value{};
        std::array<Vec3d, 8> position;
        std::array<std::uint64_t, 8> key{};
        bool inside = false;
        bool outside = false;
        for (int d = 0; d < 8; ++d) {
          const int ci = i + (d & 1);
          const int cj = j + ((d >> 1) & 1);
          const int ck = k + ((d >> 2) & 1);
          value[d] = field[index(ci, cj, ck)];
          position[d] = corner(ci, cj, ck);
          key[d] = index(ci, cj, ck);
          (value[d] > 0 ? inside : outside) = true;
        }
        if (!inside || !outside) continue;
        auto edge = [&](int a, int b) {
          if (a > b) std::swap(a, b);
          const std::uint64_t edge_key = key[a] * 8 + static_cast<std::uint64_t>(b - a);
          const auto it = vertex_of_edge.find(edge_key);
          if (it != vertex_of_edge.end()) return it->second;
          const double t = value[a] / (value[a] - value[b]);
          const VertexHandle v = mesh.add_vertex(position[a] + t * (position[b] - position[a]));
          vertex_of_edge.emplace(edge_key, v);
          return v;
        };
        MarchCube(value, position,
                  [&](const std::array<std::array<int, 2>, 3>& edges, const Vec3d& towards_out) {
                    const VertexHandle v0 = edge(edges[0][0], edges[0][1]);
                    VertexHandle v1 = edge(edges[1][0], edges[1][1]);
                    VertexHandle v2 = edge(edges[2][0], edges[2][1]);
                    const Vec3d normal =
                        (mesh.point(v1) - mesh.point(v0)) % (mesh.point(v2) - mesh.point(v0));
                    if ((normal | towards_out) < 0) std::swap(v1, v2);
                    AddTriangle(mesh, v0, v1, v2);
                  });
      }
  mesh.RecomputeNormals();
  return mesh;
}

}  // namespace

Mesh MakeMarchingBlob(int resolution, double noise, std::uint64_t seed) {
  CheckBlobArguments(resolution, noise);
  const std::vector<Lobe> lobes = {{{0.0, 0.0, 0.0}, 0.45, 1.0},
                                   {{0.45, 0.1, 0.1}, 0.3, 0.8},
                                   {{-0.35, 0.3, -0.15}, 0.28, 0.8},
                                   {{0.05, -0.4, 0.3}, 0.25, 0.7},
                                   {{-0.1, 0.05, -0.5}, 0.22, 0.7}};
  BlobRandom random(seed);
  return ContourLobes(lobes, resolution, noise, random);
}

Mesh MakeRandomBlob(int resolution, double noise, std::uint64_t seed) {
  CheckBlobArguments(resolution, noise);
  BlobRandom random(seed ^ 0x5DEECE66Dull);
  // A central lobe and 3 to 7 more, each reaching out from it in a random direction.
  std::vector<Lobe> lobes = {{{0.0, 0.0, 0.0}, 0.35 + 0.1 * random.Next(), 1.0}};
  const int extra = 3 + static_cast<int>(random.Next() * 5.0);
  while (static_cast<int>(lobes.size()) <= extra) {
    Vec3d direction(2 * random.Next() - 1, 2 * random.Next() - 1, 2 * random.Next() - 1);
    if (direction.sqrnorm() < 1e-4 || direction.sqrnorm() > 1.0) continue;
    direction.normalize();
    lobes.push_back({direction * (0.3 + 0.25 * random.Next()), 0.15 + 0.15 * random.Next(),
                     0.6 + 0.4 * random.Next()});
  }
  return ContourLobes(lobes, resolution, noise, random);
}

}  // namespace carousel
