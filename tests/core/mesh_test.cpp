#include "carousel/core/mesh.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/mesh_primitives.h"

namespace carousel {
namespace {

// Signed volume by the divergence theorem: positive for a closed, outward-oriented mesh.
double SignedVolume(const Mesh& mesh) {
  double volume = 0.0;
  for (Mesh::FaceHandle f : mesh.faces()) {
    auto v = mesh.cfv_iter(f);
    const OpenMesh::Vec3d a = mesh.point(*v), b = mesh.point(*++v), c = mesh.point(*++v);
    volume += OpenMesh::dot(a, OpenMesh::cross(b, c)) / 6.0;
  }
  return volume;
}

std::size_t BoundaryEdges(const Mesh& mesh) {
  std::size_t n = 0;
  for (Mesh::EdgeHandle e : mesh.edges()) n += mesh.is_boundary(e) ? 1 : 0;
  return n;
}

TEST(MeshTest, TypedPropertiesStartUnsetAndSurviveCopies) {
  Mesh mesh = MakeIcosphere(1.0, 1);
  for (Mesh::FaceHandle f : mesh.faces()) {
    EXPECT_EQ(mesh.chart_id(f), Mesh::kNoChart);
    EXPECT_EQ(mesh.front_view(f), Mesh::kNoView);
  }
  EXPECT_FALSE(mesh.has_uvs());
  const Mesh::FaceHandle f0(0), f5(5);
  mesh.set_chart_id(f0, 3);
  mesh.set_front_view(f5, 11);
  const Mesh copy = mesh;
  EXPECT_EQ(copy.chart_id(f0), 3);
  EXPECT_EQ(copy.front_view(f5), 11);
  EXPECT_EQ(copy.chart_id(f5), Mesh::kNoChart);
  // Faces added later start unset too.
  Mesh grown = copy;
  const auto a = grown.add_vertex({5, 5, 5}), b = grown.add_vertex({6, 5, 5}),
             c = grown.add_vertex({5, 6, 5});
  const Mesh::FaceHandle added = grown.add_face(a, b, c);
  EXPECT_EQ(grown.chart_id(added), Mesh::kNoChart);
  EXPECT_EQ(grown.front_view(added), Mesh::kNoView);
}

TEST(MeshTest, ClosedPrimitivesAreWatertightAndOutward) {
  const double r = 0.1;
  const Mesh sphere = MakeIcosphere(r, 4);
  EXPECT_EQ(sphere.n_faces(), 20u * 256u);
  EXPECT_EQ(BoundaryEdges(sphere), 0u);
  EXPECT_NEAR(SignedVolume(sphere), 4.0 / 3.0 * std::numbers::pi * r * r * r, 0.01 * r * r * r);
  EXPECT_NEAR(sphere.SurfaceArea(), 4.0 * std::numbers::pi * r * r,
              0.01 * 4 * std::numbers::pi * r * r);

  const Mesh torus = MakeTorus(0.1, 0.03, 64, 32);
  EXPECT_EQ(BoundaryEdges(torus), 0u);
  const double torus_volume = 2 * std::numbers::pi * std::numbers::pi * 0.1 * 0.03 * 0.03;
  EXPECT_NEAR(SignedVolume(torus), torus_volume, 0.01 * torus_volume);

  const Mesh cylinder = MakeCylinder(0.05, 0.2, 64, 4);
  EXPECT_EQ(BoundaryEdges(cylinder), 0u);
  const double cylinder_volume = std::numbers::pi * 0.05 * 0.05 * 0.2;
  EXPECT_NEAR(SignedVolume(cylinder), cylinder_volume, 0.01 * cylinder_volume);
}

// The marching-cubes blob: closed, outward, about 15 r^2 faces, deterministic; field noise
// changes it (bumps) but keeps it closed.
TEST(MeshTest, MarchingBlobIsClosedOutwardAndDeterministic) {
  const Mesh blob = MakeMarchingBlob(24, 0.0, 1);
  EXPECT_EQ(BoundaryEdges(blob), 0u);
  EXPECT_GT(SignedVolume(blob), 0.1);
  EXPECT_GT(blob.n_faces(), 10u * 24u * 24u);
  EXPECT_LT(blob.n_faces(), 20u * 24u * 24u);
  const Mesh noisy = MakeMarchingBlob(24, 0.3, 1);
  EXPECT_EQ(BoundaryEdges(noisy), 0u);
  EXPECT_NE(noisy.n_faces(), blob.n_faces());
  EXPECT_EQ(MakeMarchingBlob(24, 0.3, 1).n_faces(), noisy.n_faces());
  EXPECT_THROW(MakeMarchingBlob(2, 0.1, 1), InvalidArgument);
}

// Random blobs: closed and outward like the fixed one, the same for a seed, another shape
// for another seed (volumes differ), about 15 r^2 faces.
TEST(MeshTest, RandomBlobsAreClosedAndDifferBySeed) {
  std::vector<double> volumes;
  for (const std::uint64_t seed : {1u, 2u, 3u, 4u}) {
    const Mesh blob = MakeRandomBlob(24, 0.3, seed);
    EXPECT_EQ(BoundaryEdges(blob), 0u) << seed;
    EXPECT_GT(blob.n_faces(), 5u * 24u * 24u) << seed;
    EXPECT_LT(blob.n_faces(), 25u * 24u * 24u) << seed;
    volumes.push_back(SignedVolume(blob));
    EXPECT_GT(volumes.back(), 0.05) << seed;
    EXPECT_EQ(MakeRandomBlob(24, 0.3, seed).n_faces(), blob.n_faces()) << seed;
  }
  std::sort(volumes.begin(), volumes.end());
  for (std::size_t i = 1; i < volumes.size(); ++i) EXPECT_GT(volumes[i], volumes[i - 1] * 1.01);
  EXPECT_THROW(MakeRandomBlob(600, 0.1, 1), InvalidArgument);
}

TEST(MeshTest, DiscHasOneBoundaryLoopAndFacesUp) {
  Mesh disc = MakeDisc(0.1, 32, 4);
  EXPECT_EQ(BoundaryEdges(disc), 32u);
  disc.RecomputeNormals();
  for (Mesh::FaceHandle f : disc.faces()) EXPECT_GT(disc.normal(f)[2], 0.999);
}

TEST(MeshTest, BoundsAndArea) {
  const Mesh cylinder = MakeCylinder(0.05, 0.2, 16, 1);
  OpenMesh::Vec3d min, max;
  cylinder.Bounds(&min, &max);
  EXPECT_NEAR(min[2], 0.0, 1e-15);
  EXPECT_NEAR(max[2], 0.2, 1e-15);
  EXPECT_NEAR(max[0], 0.05, 1e-15);
  Mesh empty;
  empty.Bounds(&min, &max);
  EXPECT_GT(min[0], max[0]);
}

TEST(MeshTest, PrimitivesRejectBadSizes) {
  EXPECT_THROW(MakeIcosphere(0, 1), InvalidArgument);
  EXPECT_THROW(MakeIcosphere(1, 9), InvalidArgument);
  EXPECT_THROW(MakeTorus(0.1, 0.2, 8, 8), InvalidArgument);
  EXPECT_THROW(MakeCylinder(0.1, 0.2, 2, 1), InvalidArgument);
  EXPECT_THROW(MakeDisc(0.1, 8, 0), InvalidArgument);
}

}  // namespace
}  // namespace carousel
