#include "carousel/core/mesh_query.h"

#include <gtest/gtest.h>

#include "carousel/core/mesh_primitives.h"

namespace carousel {
namespace {

// A star-shaped solid: an icosphere with every other vertex pulled in to 60 % of the radius,
// so the surface has concave vertices and edges, scaled about the centre.
Mesh Spiky(double scale) {
  Mesh mesh = MakeIcosphere(1.0, 2);
  for (const auto v : mesh.vertices()) {
    const double r = (v.idx() % 2 == 1 ? 0.6 : 1.0) * scale;
    mesh.set_point(v, mesh.point(v).normalized() * r);
  }
  return mesh;
}

// A slightly shrunk copy lies inside, everywhere, also where its closest points on the outer
// surface are concave vertices and edges (the side is judged by pseudo-normals there); a
// slightly grown copy sticks out by about the growth.
TEST(MeshQueryTest, ContainmentJudgesTheSideAtConcaveVerticesAndEdges) {
  const Mesh outer = Spiky(1.0);
  const Containment inside = MeasureContainment(Spiky(0.97), outer, 20000);
  EXPECT_EQ(inside.max_outside, 0.0);
  EXPECT_GT(inside.mean_distance, 0.0);
  const Containment outside = MeasureContainment(Spiky(1.05), outer, 20000);
  EXPECT_GT(outside.max_outside, 0.02);
  EXPECT_LT(outside.max_outside, 0.06);
}

}  // namespace
}  // namespace carousel
