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

struct Flat {
  double fill = 0.0;        // of the chart's minimum-area box
  int flipped = 0;          // UV triangles not counter-clockwise
  double l2_stretch = 0.0;  // as the parameterization reports it
  int unbent = 0;
};

Flat FlattenOneChart(const Mesh& mesh, const ParameterizationOptions& options) {
  Progress progress;
  const std::vector<int> one_chart(mesh.n_faces(), 0);
  const ParameterizationResult result = ParameterizeCharts(mesh, one_chart, 1, options, progress);
  EXPECT_EQ(result.charts, 1);
  Flat flat;
  std::vector<cv::Point2f> points;
  double area = 0.0;
  for (const auto& t : result.uv) {
    const double twice = (t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x();
    if (!(twice > 0.0)) ++flat.flipped;
    area += 0.5 * twice;
    for (const auto& p : t) points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  flat.fill = area / cv::minAreaRect(points).size.area();
  flat.l2_stretch = result.l2_stretch;
  flat.unbent = result.charts_unbent;
  return flat;
}

// A thin bent band is straightened: it then fills its box, unflipped, nearly isometric (its
// inner and outer edges differ by 10 %). Without unbending it stays bent.
TEST(ParameterizationTest, BentBandsAreStraightened) {
  const Mesh band = MakeAnnularSector(0.1, 0.11, 270.0, 96, 3);
  ParameterizationOptions options;
  const Flat unbent = FlattenOneChart(band, options);
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

}  // namespace
}  // namespace carousel::texture
