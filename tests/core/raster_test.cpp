// The z-buffered mesh rasteriser: coverage by the pixel-centre rule, perspective-correct
// barycentrics, depth order, watertight shared edges, anti-aliased coverage, lens-curved edges,
// determinism and bad input.
#include "carousel/core/raster.h"

#include <random>
#include <set>
#include <utility>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/mesh.h"
#include "carousel/core/mesh_primitives.h"

namespace carousel {
namespace {

// A pinhole camera at the origin looking down +z (world = camera frame).
CameraModel Pinhole(int width = 160, int height = 120) {
  CameraModel camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 150.0;
  camera.cx = (width - 1) / 2.0;
  camera.cy = (height - 1) / 2.0;
  return camera;
}

// The world point (camera frame) at depth z that projects to pixel (u, v) of a pinhole camera.
Eigen::Vector3d AtPixel(const CameraModel& camera, double u, double v, double z) {
  return {(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z};
}

TEST(RasterTest, CoverageFollowsThePixelCentreRuleAndBarycentricsAreExact) {
  const CameraModel camera = Pinhole();
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-20.0, 180.0), v(-20.0, 140.0), z(0.5, 3.0);
  int covered = 0;
  for (int trial = 0; trial < 40; ++trial) {
    std::array<Eigen::Vector2d, 3> pixels;
    std::vector<Eigen::Vector3d> positions;
    for (Eigen::Vector2d& p : pixels) {
      p = {u(rng), v(rng)};
      positions.push_back(AtPixel(camera, p.x(), p.y(), z(rng)));  // depth differs per corner
    }
    const std::vector<Eigen::Vector3i> triangles = {{0, 1, 2}};
    const MeshRaster raster = RasterizeMesh(positions, triangles, camera);
    std::set<std::pair<int, int>> expected;
    ForEachPixelCentreIn(pixels, camera.width, camera.height,
                         [&](int x, int y) { expected.emplace(x, y); });
    for (int y = 0; y < camera.height; ++y)
      for (int x = 0; x < camera.width; ++x) {
        const auto fragments = raster.Fragments(x, y);
        ASSERT_EQ(fragments.size(), expected.count({x, y}))
            << "trial " << trial << " at " << x << "," << y;
        if (fragments.empty()) continue;
        ++covered;
        const RasterFragment& f = fragments[0];
        EXPECT_EQ(f.face, 0);
        EXPECT_EQ(f.samples, 1);
        EXPECT_NEAR(f.barycentric.sum(), 1.0f, 1e-5f);
        // The surface point of the barycentrics projects onto the pixel centre, at its depth.
        const Eigen::Vector3d point = f.barycentric[0] * positions[0] +
                                      f.barycentric[1] * positions[1] +
                                      f.barycentric[2] * positions[2];
        const Eigen::Vector2d pixel = *camera.Project(point);
        EXPECT_NEAR(pixel.x(), x, 2e-3);
        EXPECT_NEAR(pixel.y(), y, 2e-3);
        EXPECT_NEAR(f.depth, point.z(), 1e-4 * point.z());
      }
  }
  EXPECT_GT(covered, 10000);
}

// The barycentric walk visits the same pixels as the plain one, in either orientation, and
// its barycentrics (in the corners' given order) sum to 1 and give back the pixel centre; a
// degenerate triangle visits nothing.
TEST(RasterTest, BarycentricsOfEveryPixelCentreGiveItBack) {
  std::mt19937 random(5);
  std::uniform_real_distribution<double> coordinate(-3.0, 40.0);
  for (int trial = 0; trial < 50; ++trial) {
    std::array<Eigen::Vector2d, 3> t;
    for (auto& corner : t) corner = Eigen::Vector2d(coordinate(random), coordinate(random));
    std::set<std::pair<int, int>> plain, walked;
    ForEachPixelCentreIn(t, 32, 24, [&](int x, int y) { plain.emplace(x, y); });
    ForEachPixelCentreWithBarycentrics(
        t, 32, 24, [&](int x, int y, const std::array<double, 3>& b) {
          walked.emplace(x, y);
          EXPECT_NEAR(b[0] + b[1] + b[2], 1.0, 1e-12);
          const Eigen::Vector2d back = b[0] * t[0] + b[1] * t[1] + b[2] * t[2];
          EXPECT_NEAR(back.x(), x, 1e-9);
          EXPECT_NEAR(back.y(), y, 1e-9);
          for (const double w : b) EXPECT_GE(w, -1e-9);
        });
    EXPECT_EQ(walked, plain) << trial;
  }
  int visits = 0;
  ForEachPixelCentreWithBarycentrics(
      {Eigen::Vector2d(1, 1), Eigen::Vector2d(5, 5), Eigen::Vector2d(9, 9)}, 32, 24,
      [&](int, int, const std::array<double, 3>&) { ++visits; });
  EXPECT_EQ(visits, 0);
}

TEST(RasterTest, TheNearerFaceWinsWhateverTheOrder) {
  const CameraModel camera = Pinhole();
  // Two overlapping squares' worth of triangles: one at 1 m, one at 2 m, offset sideways.
  std::vector<Eigen::Vector3d> positions;
  auto add_triangle = [&](double u0, double v0, double z) {
    positions.push_back(AtPixel(camera, u0, v0, z));
    positions.push_back(AtPixel(camera, u0 + 60.3, v0, z));
    positions.push_back(AtPixel(camera, u0, v0 + 60.7, z));
  };
  add_triangle(20.2, 20.1, 2.0);
  add_triangle(40.4, 30.3, 1.0);
  for (const bool near_first : {false, true}) {
    const std::vector<Eigen::Vector3i> triangles =
        near_first ? std::vector<Eigen::Vector3i>{{3, 4, 5}, {0, 1, 2}}
                   : std::vector<Eigen::Vector3i>{{0, 1, 2}, {3, 4, 5}};
    const int near_face = near_first ? 0 : 1, far_face = 1 - near_face;
    const cv::Mat ids = RasterizeMesh(positions, triangles, camera).FaceIds();
    // (50, 40) is inside both, (25, 25) only in the far one.
    EXPECT_EQ(ids.at<int>(40, 50), near_face);
    EXPECT_EQ(ids.at<int>(25, 25), far_face);
    EXPECT_EQ(ids.at<int>(5, 5), -1);
    int near_pixels = 0;
    for (int y = 0; y < ids.rows; ++y)
      for (int x = 0; x < ids.cols; ++x) near_pixels += ids.at<int>(y, x) == near_face;
    EXPECT_NEAR(near_pixels, 60.3 * 60.7 / 2, 60);  // none of it hidden by the far one
  }
}

TEST(RasterTest, SharedEdgesLeaveNoCracksAndEdgeSamplesAreTakenOnce) {
  // A fronto-parallel grid of quads with corners on pixel centres: many samples lie exactly on
  // shared edges (horizontal, vertical and diagonal).
  // Powers of two and unit depth: the corners project exactly onto the pixel centres.
  CameraModel camera = Pinhole(64, 64);
  camera.fx = camera.fy = 128.0;
  camera.cx = camera.cy = 32.0;
  std::vector<Eigen::Vector3d> positions;
  std::vector<Eigen::Vector3i> triangles;
  const int cells = 6, step = 8, origin = 4;
  for (int j = 0; j <= cells; ++j)
    for (int i = 0; i <= cells; ++i)
      positions.push_back(AtPixel(camera, origin + i * step, origin + j * step, 1.0));
  auto at = [&](int i, int j) { return j * (cells + 1) + i; };
  for (int j = 0; j < cells; ++j)
    for (int i = 0; i < cells; ++i) {
      triangles.emplace_back(at(i, j), at(i + 1, j), at(i + 1, j + 1));
      triangles.emplace_back(at(i, j), at(i + 1, j + 1), at(i, j + 1));
    }
  for (const int n : {1, 2, 3}) {
    const MeshRaster raster = RasterizeMesh(positions, triangles, camera, {.samples_per_axis = n});
    const int last = origin + cells * step;
    for (int y = origin + 1; y < last; ++y)
      for (int x = origin + 1; x < last; ++x)
        ASSERT_EQ(raster.CoveredSamples(x, y), n * n) << "n " << n << " at " << x << "," << y;
    // Exactly one of the two triangles sharing each edge takes the samples on it: over the
    // grid's interior every face's fragments add up to its area in samples.
    std::vector<int> samples(triangles.size(), 0);
    for (const RasterFragment& f : raster.fragments()) samples[f.face] += f.samples;
    int total = 0;
    for (const int s : samples) total += s;
    // The square [origin, last]^2 of pixel centres; its top and left edges are in, the bottom
    // and right ones out (top-left rule), so n x n samples per pixel of a (cells * step)^2 area.
    EXPECT_EQ(total, cells * step * cells * step * n * n) << "n " << n;
  }
}

TEST(RasterTest, PartialCoverageIsCountedPerSample) {
  const CameraModel camera = Pinhole(40, 30);
  // A large triangle whose right edge is the vertical line x = 10 (through pixel centres).
  const std::vector<Eigen::Vector3d> positions = {
      AtPixel(camera, -30, -30, 1.0), AtPixel(camera, 10, -30, 1.0), AtPixel(camera, 10, 100, 1.0)};
  const std::vector<Eigen::Vector3i> triangles = {{0, 1, 2}};
  const MeshRaster raster = RasterizeMesh(positions, triangles, camera, {.samples_per_axis = 2});
  EXPECT_EQ(raster.CoveredSamples(9, 15), 4);
  EXPECT_EQ(raster.CoveredSamples(10, 15), 2);  // samples at x = 9.75 in, 10.25 out
  EXPECT_EQ(raster.CoveredSamples(11, 15), 0);
  const cv::Mat coverage = raster.Coverage(), mask = raster.Mask();
  EXPECT_EQ(coverage.at<std::uint8_t>(15, 10), 128);
  EXPECT_EQ(mask.at<std::uint8_t>(15, 10), 255);  // at least half
  EXPECT_EQ(mask.at<std::uint8_t>(15, 11), 0);
  // The fragment of the half-covered pixel is shaded at its samples' centroid (x = 9.75).
  const RasterFragment& f = raster.Fragments(10, 15)[0];
  const Eigen::Vector3d point = f.barycentric[0] * positions[0] + f.barycentric[1] * positions[1] +
                                f.barycentric[2] * positions[2];
  EXPECT_NEAR(camera.Project(point)->x(), 9.75, 1e-3);
}

// Pixels where the rasteriser's coverage differs from the exact one (undistorting each pixel
// centre and intersecting its ray with the triangle), and the largest reprojection error of
// the barycentrics, for a large triangle seen through a strongly distorting lens.
struct LensAgreement {
  int wrong_pixels = 0;
  int covered_pixels = 0;
  double max_error_px = 0.0;
};
LensAgreement CompareWithRayCasting(double max_edge_error_px) {
  CameraModel camera = Pinhole(320, 240);
  camera.fx = camera.fy = 200.0;
  camera.distortion.k1 = -0.35;
  camera.distortion.k2 = 0.12;
  const std::vector<Eigen::Vector3d> positions = {
      {-0.9, -0.65, 1.2}, {0.85, -0.55, 1.0}, {0.1, 0.7, 1.4}};
  const std::vector<Eigen::Vector3i> triangles = {{0, 1, 2}};
  const MeshRaster raster =
      RasterizeMesh(positions, triangles, camera, {.max_edge_error_px = max_edge_error_px});
  const Eigen::Vector3d a = positions[0], b = positions[1], c = positions[2];
  const Eigen::Vector3d normal = (b - a).cross(c - a);
  LensAgreement agreement;
  for (int y = 0; y < camera.height; ++y)
    for (int x = 0; x < camera.width; ++x) {
      const auto ray = camera.RayThrough(Eigen::Vector2d(x, y));
      bool inside = false;
      if (ray) {
        const double t = normal.dot(a - ray->origin) / normal.dot(ray->direction);
        const Eigen::Vector3d p = ray->origin + t * ray->direction;
        inside = t > 0 && (b - a).cross(p - a).dot(normal) >= 0 &&
                 (c - b).cross(p - b).dot(normal) >= 0 && (a - c).cross(p - c).dot(normal) >= 0;
      }
      const auto fragments = raster.Fragments(x, y);
      agreement.wrong_pixels += inside != !fragments.empty();
      if (fragments.empty()) continue;
      ++agreement.covered_pixels;
      const RasterFragment& f = fragments[0];
      const Eigen::Vector3d point =
          f.barycentric[0] * a + f.barycentric[1] * b + f.barycentric[2] * c;
      agreement.max_error_px =
          std::max(agreement.max_error_px, (*camera.Project(point) - Eigen::Vector2d(x, y)).norm());
    }
  return agreement;
}

TEST(RasterTest, LensCurvedEdgesAreFollowedBySubdivision) {
  const LensAgreement split = CompareWithRayCasting(0.02);
  const LensAgreement straight = CompareWithRayCasting(1e9);  // never split
  EXPECT_GT(split.covered_pixels, 10000);
  std::printf("lens: %d / %d pixels wrong split (%.3f px), %d straight (%.3f px)\n",
              split.wrong_pixels, split.covered_pixels, split.max_error_px, straight.wrong_pixels,
              straight.max_error_px);
  // Only centres within ~0.02 px of the curved edges can differ.
  EXPECT_LE(split.wrong_pixels, 10);
  EXPECT_LT(split.max_error_px, 0.1);
  EXPECT_GT(straight.wrong_pixels, 20 * std::max(split.wrong_pixels, 5));
  EXPECT_GT(straight.max_error_px, 2.0);
}

TEST(RasterTest, TheSameWhateverTheThreadCountAndMeshFacesKeepTheirIndex) {
  Mesh sphere = MakeIcosphere(0.2, 3);
  CameraModel camera = Pinhole(200, 150);
  camera.distortion.k1 = -0.1;
  camera.cam_from_world = Rigid3d::LookAt({0.3, -0.8, 0.4}, {0, 0, 0});
  const MeshRaster one = RasterizeMesh(sphere, camera, {.samples_per_axis = 2, .threads = 1});
  const MeshRaster four = RasterizeMesh(sphere, camera, {.samples_per_axis = 2, .threads = 4});
  ASSERT_EQ(one.fragments().size(), four.fragments().size());
  for (std::size_t i = 0; i < one.fragments().size(); ++i) {
    const RasterFragment &a = one.fragments()[i], &b = four.fragments()[i];
    ASSERT_EQ(a.face, b.face);
    ASSERT_EQ(a.samples, b.samples);
    ASSERT_EQ(a.depth, b.depth);
    ASSERT_EQ(a.barycentric, b.barycentric);
  }
  // Faces are the mesh's face indices; the sphere's far side is hidden (a back face can win a
  // sample only at the rim, where the two sides meet at equal depth).
  std::set<int> seen;
  const Eigen::Vector3d eye = camera.Centre();
  sphere.RecomputeNormals();
  int back_samples = 0, all_samples = 0;
  for (const RasterFragment& f : one.fragments()) {
    ASSERT_GE(f.face, 0);
    ASSERT_LT(f.face, static_cast<int>(sphere.n_faces()));
    seen.insert(f.face);
    const Mesh::FaceHandle handle(f.face);
    const auto& n = sphere.normal(handle);
    const auto& p = sphere.point(*sphere.fv_begin(handle));
    const bool back =
        Eigen::Vector3d(n[0], n[1], n[2]).dot(eye - Eigen::Vector3d(p[0], p[1], p[2])) < 0;
    back_samples += back ? f.samples : 0;
    all_samples += f.samples;
  }
  EXPECT_LT(back_samples, all_samples / 200);
  EXPECT_GT(seen.size(), sphere.n_faces() / 3);
  EXPECT_LT(seen.size(), 2 * sphere.n_faces() / 3);
}

TEST(RasterTest, BadInputIsRefused) {
  const CameraModel camera = Pinhole();
  const std::vector<Eigen::Vector3d> positions = {{0, 0, 1}, {0.1, 0, 1}, {0, 0.1, 1}};
  EXPECT_THROW(RasterizeMesh(positions, std::vector<Eigen::Vector3i>{{0, 1, 3}}, camera),
               InvalidArgument);
  const std::vector<Eigen::Vector3i> triangles = {{0, 1, 2}};
  EXPECT_THROW(RasterizeMesh(positions, triangles, camera, {.samples_per_axis = 0}),
               InvalidArgument);
  EXPECT_THROW(RasterizeMesh(positions, triangles, camera, {.samples_per_axis = 5}),
               InvalidArgument);
  CameraModel bad = camera;
  bad.fx = 0;
  EXPECT_THROW(RasterizeMesh(positions, triangles, bad), InvalidArgument);
  // Behind the camera or too near: skipped, not drawn.
  const std::vector<Eigen::Vector3d> behind = {{0, 0, -1}, {0.1, 0, -1}, {0, 0.1, -1}};
  EXPECT_TRUE(RasterizeMesh(behind, triangles, camera).fragments().empty());
}

}  // namespace
}  // namespace carousel
