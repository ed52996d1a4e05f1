#include "carousel/texture/parameterization.h"

#include <array>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <vector>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "carousel/core/mesh.h"
#include "carousel/core/progress.h"

namespace carousel::texture {
namespace {

// A flat annular sector (a washer cut open) in the z = 0 plane: one chart that flattens into
// the bent band it is, filling a small part of its box.
Mesh MakeAnnularSector(double inner, double outer, double degrees, int segments, int rings) {
  Mesh mesh;
  std::vector<std::vector<Mesh::VertexHandle>> grid(rings + 1);
  for (int r = 0; r <= rings; ++r)
    for (int s = 0; s <= segments; ++s) {
      const double radius = inner + (outer - inner) * r / rings;
      const double angle = degrees * std::numbers::pi / 180.0 * s / segments;
      grid[r].push_back(mesh.add_vertex({radius * std::cos(angle), radius * std::sin(angle), 0.0}));
    }
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      mesh.add_face(grid[r][s], grid[r][s + 1], grid[r + 1][s + 1]);
      mesh.add_face(grid[r][s], grid[r + 1][s + 1], grid[r + 1][s]);
    }
  return mesh;
}

// A planar L: a 12 x 16 grid of square cells, its arms 4 cells wide, filling half its box.
Mesh MakeL(double cell) {
  constexpr int kWide = 12, kHigh = 16;
  auto kept = [](int x, int y) { return !(x >= 4 && y >= 4); };
  Mesh mesh;
  std::vector<Mesh::VertexHandle> vertex((kWide + 1) * (kHigh + 1));
  auto at = [&](int x, int y) {
    Mesh::VertexHandle& v = vertex[y * (kWide + 1) + x];
    if (!v.is_valid()) v = mesh.add_vertex({x * cell, y * cell, 0.0});
    return v;
  };
  for (int y = 0; y < kHigh; ++y)
    for (int x = 0; x < kWide; ++x) {
      if (!kept(x, y)) continue;
      mesh.add_face(at(x, y), at(x + 1, y), at(x + 1, y + 1));
      mesh.add_face(at(x, y), at(x + 1, y + 1), at(x, y + 1));
    }
  return mesh;
}

struct Flat {
  int charts = 0;
  double fill = 0.0;        // chart area over the area of the charts' minimum-area boxes
  int flipped = 0;          // UV triangles not counter-clockwise
  double l2_stretch = 0.0;  // as the parameterization reports it
  int unbent = 0;
  int split_for_fill = 0;
};

// The mesh flattened as one chart (which may come out as parts).
Flat FlattenOneChart(const Mesh& mesh, const ParameterizationOptions& options) {
  Progress progress;
  const std::vector<int> one_chart(mesh.n_faces(), 0);
  const ParameterizationResult result = ParameterizeCharts(mesh, one_chart, 1, options, progress);
  Flat flat;
  flat.charts = result.charts;
  std::vector<std::vector<cv::Point2f>> points(result.charts);
  double area = 0.0;
  for (std::size_t f = 0; f < result.uv.size(); ++f) {
    const auto& t = result.uv[f];
    const double twice =
        (t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x();
    if (!(twice > 0.0)) ++flat.flipped;
    area += 0.5 * twice;
    for (const auto& p : t)
      points[result.chart_of_face[f]].emplace_back(static_cast<float>(p.x()),
                                                   static_cast<float>(p.y()));
  }
  double boxes = 0.0;
  for (const auto& p : points) boxes += cv::minAreaRect(p).size.area();
  flat.fill = area / boxes;
  flat.l2_stretch = result.l2_stretch;
  flat.unbent = result.charts_unbent;
  flat.split_for_fill = result.charts_split_for_fill;
  return flat;
}

// A thin bent band is straightened: it then fills its box, unflipped, nearly isometric (its
// inner and outer edges differ by 10 %). Without unbending it stays bent.
TEST(ParameterizationTest, BentBandsAreStraightened) {
  const Mesh band = MakeAnnularSector(0.1, 0.11, 270.0, 96, 3);
  ParameterizationOptions options;
  const Flat unbent = FlattenOneChart(band, options);
  EXPECT_EQ(unbent.charts, 1);
  EXPECT_GT(unbent.fill, 0.9);
  EXPECT_EQ(unbent.flipped, 0);
  EXPECT_LE(unbent.l2_stretch, options.rectify_max_stretch);
  EXPECT_EQ(unbent.unbent, 1);

  options.max_unbent_stretch = 1.0;
  options.rectify_max_stretch = 1.0;
  const Flat bent = FlattenOneChart(band, options);
  EXPECT_LT(bent.fill, 0.3);
  EXPECT_EQ(bent.flipped, 0);
  EXPECT_EQ(bent.unbent, 0);
  std::printf("thin band: box fill %.3f bent, %.3f straightened (L2 %.4f)\n", bent.fill,
              unbent.fill, unbent.l2_stretch);
}

// A wide band (outer edge twice the inner) straightens only with more stretch than a
// chart may take: it is taken when the atlas-wide budget allows it, and not otherwise.
TEST(ParameterizationTest, StraighteningBeyondTheChartBoundIsWithinTheBudget) {
  const Mesh band = MakeAnnularSector(0.1, 0.2, 270.0, 96, 8);
  ParameterizationOptions options;
  options.unbend_budget_stretch = 1.0;
  const Flat kept = FlattenOneChart(band, options);
  EXPECT_EQ(kept.unbent, 0);
  EXPECT_LT(kept.fill, 0.6);

  options.unbend_budget_stretch = options.max_unbent_stretch;
  const Flat taken = FlattenOneChart(band, options);
  EXPECT_EQ(taken.unbent, 1);
  std::printf("wide band: box fill %.3f (L2 %.4f) kept, %.3f (L2 %.4f) straightened\n", kept.fill,
              kept.l2_stretch, taken.fill, taken.l2_stretch);
  EXPECT_GT(taken.fill, 0.85);
  EXPECT_EQ(taken.flipped, 0);
  EXPECT_GT(taken.l2_stretch, options.rectify_max_stretch);
  EXPECT_LE(taken.l2_stretch, options.max_unbent_stretch);
}

// An L fills half of its box; neither rectification nor unbending (it is no band) squares
// it: it is split in parts that fill theirs better (92 %). With rectification off, nothing is
// changed.
TEST(ParameterizationTest, ChartsFillingLittleOfTheirBoxAreSplit) {
  const Mesh l_shape = MakeL(0.01);
  ParameterizationOptions options;
  const Flat split = FlattenOneChart(l_shape, options);
  options.rectify_max_stretch = 1.0;
  options.max_unbent_stretch = 1.0;
  const Flat whole = FlattenOneChart(l_shape, options);
  std::printf("L: box fill %.3f whole, %.3f in %d parts\n", whole.fill, split.fill, split.charts);
  EXPECT_EQ(whole.charts, 1);
  EXPECT_EQ(whole.split_for_fill, 0);
  EXPECT_LT(whole.fill, 0.5);
  EXPECT_EQ(split.split_for_fill, 1);
  EXPECT_GE(split.charts, 2);
  EXPECT_GT(split.fill, whole.fill / 0.85);
  EXPECT_EQ(split.flipped, 0);
  EXPECT_EQ(split.unbent, 0);
}

}  // namespace
}  // namespace carousel::texture
