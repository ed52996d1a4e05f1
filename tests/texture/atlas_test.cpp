#include "carousel/texture/atlas.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>
#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/core/options.h"
#include "carousel/testing/testing.h"
#include "carousel/texture/export.h"
#include "carousel/texture/texture_map.h"

namespace carousel::texture {
namespace {

struct NamedMesh {
  std::string name;
  Mesh mesh;
};

// The procedural meshes: closed smooth ones, a noisy marching-cubes blob full of
// slivers, and an open disc.
std::vector<NamedMesh> ProceduralMeshes() {
  return {{"sphere", MakeIcosphere(0.1, 4)},
          {"torus", MakeTorus(0.2, 0.06, 64, 24)},
          {"cylinder", MakeCylinder(0.1, 0.3, 48, 12)},
          {"blob", MakeMarchingBlob(20, 0.3, 3)},
          {"disc", MakeDisc(0.2, 48, 12)}};
}

AtlasOptions SmallAtlas() {
  AtlasOptions options;
  options.size.size = 1024;
  options.packing.gutter_texels = 4;
  return options;
}

// Every face gets UVs inside [0, 1]; no flipped UV triangle; no texel claimed by two charts,
// gutters clear; every chart one boundary loop; stretch close to an isometry.
void ExpectValidAtlas(const std::string& name, Mesh mesh) {
  Progress progress;
  const AtlasOptions options = SmallAtlas();
  const AtlasResult result = BuildAtlas(&mesh, options, progress);
  const AtlasQuality& q = result.quality;
  EXPECT_TRUE(mesh.has_uvs()) << name;
  EXPECT_EQ(q.faces_without_uvs, 0u) << name;
  EXPECT_EQ(q.flipped_faces, 0u) << name;
  EXPECT_EQ(q.uvs_outside, 0u) << name;
  EXPECT_EQ(q.overlapping_texels, 0u) << name;
  EXPECT_EQ(q.gutter_violations, 0u) << name;
  EXPECT_EQ(q.charts_not_disks, 0) << name;
  EXPECT_TRUE(q.Valid()) << name;
  EXPECT_GE(q.charts, 1) << name;
  EXPECT_LE(q.l2_stretch, 1.1) << name;
  EXPECT_GT(q.utilization, 0.3) << name;
  std::set<int> charts;
  for (const auto f : mesh.faces()) {
    charts.insert(mesh.chart_id(f));
    for (const auto h : mesh.fh_range(f)) {
      const auto uv = mesh.uv(h);
      ASSERT_TRUE(std::isfinite(uv[0]) && std::isfinite(uv[1])) << name;
    }
  }
  EXPECT_EQ(static_cast<int>(charts.size()), q.charts) << name;
  EXPECT_EQ(*charts.begin(), 0) << name;
}

TEST(AtlasTest, ProceduralMeshesGetValidAtlases) {
  for (NamedMesh& m : ProceduralMeshes()) ExpectValidAtlas(m.name, std::move(m.mesh));
}

TEST(AtlasTest, SharedModelsGetValidAtlases) {
  for (const char* model : {"Avocado", "Duck", "MaterialsVariantsShoe", "WaterBottle"}) {
    const std::string relative = std::string("models/") + model + "/obj_derived/" + model + ".obj";
    ExpectValidAtlas(model, ReadMesh(testing::SharedDataFile(relative), {.read_uvs = false}));
  }
}

// Flat, developable and gently curved surfaces flatten almost without stretch (ABF++ alone,
// no rectification); charts stay few (the paper: 10-13 from 10 seeds). Rectification trades
// stretch for packing up to its bound, never beyond (charts packed at one density: a density
// spread would add its own stretch).
TEST(AtlasTest, StretchAndChartCountOnSmoothSurfaces) {
  for (NamedMesh& m : ProceduralMeshes()) {
    if (m.name == "blob") continue;
    Progress progress;
    AtlasOptions options = SmallAtlas();
    options.charts.layouts = 1;  // the same charts for both
    options.packing.max_density_spread = 1.0;
    options.parameterization.rectify_max_stretch = 1.0;
    Mesh plain_mesh = m.mesh;
    const AtlasResult plain = BuildAtlas(&plain_mesh, options, progress);
    EXPECT_LE(plain.quality.l2_stretch, 1.03) << m.name;
    EXPECT_LE(plain.quality.angle_distortion_deg, 2.0) << m.name;
    EXPECT_LE(plain.quality.charts, 20) << m.name;
    options.parameterization.rectify_max_stretch = 1.04;
    const AtlasResult rectified = BuildAtlas(&m.mesh, options, progress);
    EXPECT_TRUE(rectified.quality.Valid()) << m.name;
    EXPECT_LE(rectified.quality.l2_stretch, 1.04) << m.name;
    EXPECT_EQ(rectified.quality.charts, plain.quality.charts) << m.name;
  }
}

// Per pair of neighbouring charts that share one boundary arc: the arc's length over the
// distance between its ends.
std::vector<double> BoundaryArcDetours(const Mesh& mesh) {
  struct Arc {
    double length = 0.0;
    std::map<int, int> degree;  // vertex -> arc edges at it
  };
  std::map<std::pair<int, int>, Arc> arcs;
  for (const auto e : mesh.edges()) {
    if (mesh.is_boundary(e)) continue;
    const auto h = mesh.halfedge_handle(e, 0);
    const int a = mesh.chart_id(mesh.face_handle(h));
    const int b = mesh.chart_id(mesh.opposite_face_handle(h));
    if (a == b) continue;
    Arc& arc = arcs[{std::min(a, b), std::max(a, b)}];
    arc.length += mesh.calc_edge_length(e);
    ++arc.degree[mesh.from_vertex_handle(h).idx()];
    ++arc.degree[mesh.to_vertex_handle(h).idx()];
  }
  std::vector<double> detours;
  for (const auto& [pair, arc] : arcs) {
    std::vector<int> ends;
    bool simple = true;
    for (const auto& [v, degree] : arc.degree) {
      if (degree == 1) ends.push_back(v);
      simple = simple && degree <= 2;
    }
    if (!simple || ends.size() != 2) continue;
    const auto chord =
        mesh.point(Mesh::VertexHandle(ends[0])) - mesh.point(Mesh::VertexHandle(ends[1]));
    if (chord.norm() > 0.0) detours.push_back(arc.length / chord.norm());
  }
  return detours;
}

// Chart growth on a noisy surface leaves boundaries that wander with the noise (here, without
// the re-cut: a median arc 1.43 times as long as the distance between its ends, the worst
// 2.02 times); re-cut along shortest paths they run nearly straight from corner to corner
// (1.11 and 1.36: a shortest edge path on a marching-cubes mesh still zigzags a little).
TEST(AtlasTest, ChartBoundariesRunStraightBetweenCorners) {
  const Mesh blob = MakeMarchingBlob(20, 0.3, 3);
  Mesh mesh = blob;
  AtlasBuilder builder(blob);
  Progress progress;
  const ChartsResult& charts = builder.ComputeCharts({}, progress);
  EXPECT_GT(charts.boundaries_recut, 0);
  for (const auto f : mesh.faces()) mesh.set_chart_id(f, charts.chart_of_face[f.idx()]);
  std::vector<double> detours = BoundaryArcDetours(mesh);
  ASSERT_GE(detours.size(), 10u);
  std::sort(detours.begin(), detours.end());
  EXPECT_LE(detours[detours.size() / 2], 1.2);
  EXPECT_LE(detours.back(), 1.6);
  for (const int loops : CountChartBoundaryLoops(mesh, charts.chart_of_face, charts.charts))
    EXPECT_EQ(loops, 1);
}

// Chart area over the area of its minimum-area rectangle, per chart, averaged.
double MeanBoxFill(const Mesh& mesh) {
  std::map<int, std::vector<cv::Point2f>> points;
  std::map<int, double> area;
  for (const auto f : mesh.faces()) {
    std::array<cv::Point2f, 3> t;
    int k = 0;
    for (const auto h : mesh.fh_range(f)) {
      const auto uv = mesh.uv(h);
      t[k++] = cv::Point2f(static_cast<float>(uv[0]), static_cast<float>(uv[1]));
    }
    const int c = mesh.chart_id(f);
    points[c].insert(points[c].end(), t.begin(), t.end());
    area[c] += 0.5 * std::abs((t[1] - t[0]).cross(t[2] - t[0]));
  }
  double sum = 0.0;
  for (const auto& [c, p] : points) sum += area[c] / cv::minAreaRect(p).size.area();
  return sum / static_cast<double>(points.size());
}

// Angle-preserving charts are round and leave their boxes' corners empty (here 67 % filled);
// rectified, they fill their boxes (83 %) and the atlas (utilization 63 % -> 73 %), within
// the stretch bound, still valid.
TEST(AtlasTest, RectifiedChartsFillTheirBoxes) {
  const Mesh blob = MakeMarchingBlob(24, 0.3, 5);
  AtlasOptions options = SmallAtlas();
  options.charts.layouts = 1;                // the same charts for both
  options.packing.max_density_spread = 1.0;  // the stretch measured is the flattening's alone
  options.parameterization.rectify_max_stretch = 1.0;
  Progress progress;
  Mesh round = blob;
  const AtlasResult plain = BuildAtlas(&round, options, progress);
  options.parameterization.rectify_max_stretch = 1.04;
  Mesh rectangular = blob;
  const AtlasResult rectified = BuildAtlas(&rectangular, options, progress);
  ASSERT_TRUE(plain.quality.Valid());
  ASSERT_TRUE(rectified.quality.Valid());
  const double round_fill = MeanBoxFill(round);
  const double rectified_fill = MeanBoxFill(rectangular);
  EXPECT_LT(round_fill, 0.75);
  EXPECT_GT(rectified_fill, 0.8);
  EXPECT_GT(rectified.quality.utilization, plain.quality.utilization + 0.05);
  EXPECT_LE(rectified.quality.l2_stretch, 1.04);
  // The same charts, but for one that still fills little of its box, split in parts.
  EXPECT_GE(rectified.quality.charts, plain.quality.charts);
  EXPECT_LE(rectified.quality.charts, plain.quality.charts + 2);
}

// Box packing: rectangles of assorted sizes and turns (each two triangles, a chart) fill most
// of the atlas (89 %; the Tetris-like packer alone reached 78 %), none closer to another than
// the gutter, each at its own density: the common one, or up to max_density_spread times it
// where a chart grew into room left.
TEST(AtlasTest, RectangularChartsPackTightly) {
  std::vector<std::array<Eigen::Vector2d, 3>> uv;
  std::vector<int> chart_of_face;
  std::vector<Eigen::Vector2d> sizes;
  std::mt19937 random(3);
  std::uniform_real_distribution<double> side(0.02, 0.1);
  for (int c = 0; c < 60; ++c) {
    const Eigen::Vector2d s(side(random), side(random));
    sizes.push_back(s);
    // Turned by some angle: the packer must find the boxes.
    const Eigen::Rotation2Dd turn(0.1 * c);
    const Eigen::Vector2d p0(static_cast<double>(c), 0.0);
    const Eigen::Vector2d p1 = p0 + turn * Eigen::Vector2d(s.x(), 0.0);
    const Eigen::Vector2d p2 = p0 + turn * s;
    const Eigen::Vector2d p3 = p0 + turn * Eigen::Vector2d(0.0, s.y());
    uv.push_back({p0, p1, p2});
    uv.push_back({p0, p2, p3});
    chart_of_face.push_back(c);
    chart_of_face.push_back(c);
  }
  PackingOptions options;
  options.gutter_texels = 4;
  const int size = 1024;
  Progress progress;
  const PackingResult packed = PackCharts(uv, chart_of_face, 60, size, options, progress);
  EXPECT_GT(packed.utilization, 0.85);
  // Each chart's box in texels, grown by half the gutter: no two overlap.
  std::vector<cv::Rect2d> boxes;
  for (int c = 0; c < 60; ++c) {
    Eigen::AlignedBox2d box;
    for (int f = 2 * c; f < 2 * c + 2; ++f)
      for (const auto& p : packed.uv[f]) {
        EXPECT_GE(p.minCoeff(), 0.0);
        EXPECT_LE(p.maxCoeff(), 1.0);
        box.extend(p * size);
      }
    const double density = packed.chart_texels_per_metre[c];
    EXPECT_GE(density, packed.texels_per_metre);
    EXPECT_LE(density, options.max_density_spread * packed.texels_per_metre * (1 + 1e-9));
    EXPECT_NEAR(box.volume(), sizes[c].prod() * density * density, 1e-6 * box.volume());
    const double half = 0.5 * options.gutter_texels - 1e-6;
    boxes.emplace_back(box.min().x() - half, box.min().y() - half, box.sizes().x() + 2 * half,
                       box.sizes().y() + 2 * half);
  }
  for (std::size_t i = 0; i < boxes.size(); ++i)
    for (std::size_t j = i + 1; j < boxes.size(); ++j)
      EXPECT_LE((boxes[i] & boxes[j]).area(), 0.0) << i << " " << j;
}

// Room the packing leaves goes to charts grown beyond the common density: on a random blob
// nothing was tuned on, more of the atlas is used (on 10 of them, 5k faces: min 72.6 ->
// 76.3 %), the atlas stays valid, L2 stretch stays under 1.05 and no chart gets more than the
// spread allows; with a spread of 1 every chart has the common density.
TEST(AtlasTest, ChartsGrowIntoRoomLeft) {
  const Mesh blob = MakeRandomBlob(18, 0.3, 4);
  AtlasOptions options = SmallAtlas();
  Progress progress;
  options.packing.max_density_spread = 1.0;
  Mesh even = blob;
  const AtlasResult one_density = BuildAtlas(&even, options, progress);
  options.packing.max_density_spread = 1.2;
  AtlasBuilder builder(blob);
  builder.ComputeCharts(options.charts, progress);
  builder.Parameterize(options.parameterization, progress);
  const PackingResult& packed = builder.Pack(options.packing, options.size.size, progress);
  for (const double density : packed.chart_texels_per_metre) {
    EXPECT_GE(density, packed.texels_per_metre);
    EXPECT_LE(density, 1.2 * packed.texels_per_metre * (1 + 1e-9));
  }
  Mesh grown = blob;
  builder.Apply(&grown);
  const AtlasQuality quality = MeasureAtlas(grown, packed.size, options.packing.gutter_texels);
  EXPECT_TRUE(quality.Valid());
  EXPECT_LE(quality.l2_stretch, 1.05);
  EXPECT_GT(quality.utilization, one_density.quality.utilization + 0.02);
  EXPECT_GT(
      *std::max_element(packed.chart_texels_per_metre.begin(), packed.chart_texels_per_metre.end()),
      packed.texels_per_metre);
}

// An angle-preserving flattening shrinks protrusions: on a real reconstruction (the shoe's
// heel tab and opening) some faces got a hundredth of their share of texels (L2 stretch 6.8)
// until charts were split on stretch.
TEST(AtlasTest, ProtrusionsAreNotStarvedOfTexels) {
  const Mesh shoe =
      ReadMesh(std::filesystem::path(CAROUSEL_TEST_DATA_DIR) / "shoe_reconstructed_4500.ply");
  Progress progress;
  AtlasOptions options = SmallAtlas();
  options.charts.layouts = 1;  // the layout whose protrusions starve, not another
  Mesh unlimited = shoe;
  options.parameterization.max_chart_stretch = 1e9;
  const AtlasResult starved = BuildAtlas(&unlimited, options, progress);
  options.parameterization.max_chart_stretch = ParameterizationOptions().max_chart_stretch;
  Mesh fed_mesh = shoe;
  const AtlasResult fed = BuildAtlas(&fed_mesh, options, progress);
  EXPECT_TRUE(fed.quality.Valid());
  EXPECT_LE(fed.quality.l2_stretch, 1.05);
  EXPECT_GT(starved.quality.l2_stretch, 2.0);
  EXPECT_GT(fed.charts_split, 0);
}

// A small mesh is laid out from several random seeds and the tightest packing kept: exactly
// the best of the layouts each seed gives alone. A mesh over layout_faces is laid out once.
TEST(AtlasTest, SmallMeshesKeepTheTightestOfSeveralLayouts) {
  const Mesh blob = MakeRandomBlob(18, 0.3, 10);
  Progress progress;
  AtlasOptions options = SmallAtlas();
  ASSERT_LE(blob.n_faces(), static_cast<std::size_t>(options.charts.layout_faces));
  Mesh several = blob;
  const AtlasResult kept = BuildAtlas(&several, options, progress);
  EXPECT_EQ(kept.layouts, options.charts.layouts);
  EXPECT_TRUE(kept.quality.Valid());
  double best = 0.0;
  double worst = 1.0;
  AtlasOptions alone = options;
  alone.charts.layouts = 1;
  for (int layout = 0; layout < options.charts.layouts; ++layout) {
    alone.charts.random_seed = options.charts.random_seed + layout;
    Mesh mesh = blob;
    const AtlasResult one = BuildAtlas(&mesh, alone, progress);
    EXPECT_EQ(one.layouts, 1);
    best = std::max(best, one.quality.utilization);
    worst = std::min(worst, one.quality.utilization);
  }
  std::printf("%d layouts: utilization %.1f .. %.1f %%, kept %.1f %%\n", options.charts.layouts,
              100.0 * worst, 100.0 * best, 100.0 * kept.quality.utilization);
  EXPECT_NEAR(kept.quality.utilization, best, 1e-9);
  EXPECT_GT(best, worst);

  options.charts.layout_faces = static_cast<int>(blob.n_faces()) - 1;
  Mesh once = blob;
  EXPECT_EQ(BuildAtlas(&once, options, progress).layouts, 1);
}

// The paper's Fig. 11: charts turned into their oriented boxes pack tighter than axis-aligned
// ones, so every chart gets more texels (on the shared models: 1-5 % more density).
TEST(AtlasTest, ObbPackingGivesMoreTexelsThanAabb) {
  double ratios = 0.0;
  for (const char* model : {"Duck", "WaterBottle", "MaterialsVariantsShoe"}) {
    const std::string relative = std::string("models/") + model + "/obj_derived/" + model + ".obj";
    const Mesh mesh = ReadMesh(testing::SharedDataFile(relative), {.read_uvs = false});
    AtlasBuilder builder(mesh);
    Progress progress;
    builder.ComputeCharts({}, progress);
    builder.Parameterize({}, progress);
    PackingOptions options;
    options.mode = PackingMode::kAabb;
    const double aabb = builder.Pack(options, 4096, progress).texels_per_metre;
    options.mode = PackingMode::kObb;
    const double obb = builder.Pack(options, 4096, progress).texels_per_metre;
    EXPECT_GT(obb, aabb) << model;
    ratios += obb / aabb / 3.0;
  }
  EXPECT_GT(ratios, 1.02);
}

// Bad input: a non-finite coordinate is refused naming the vertex; zero-area faces and
// isolated vertices are handled; staged calls out of order are refused.
TEST(AtlasTest, BadInput) {
  Mesh nan_mesh = MakeIcosphere(0.1, 1);
  nan_mesh.set_point(Mesh::VertexHandle(7), {std::numeric_limits<double>::quiet_NaN(), 0, 0});
  Progress progress;
  CAROUSEL_EXPECT_THROW_WITH(BuildAtlas(&nan_mesh, SmallAtlas(), progress), InvalidArgument,
                             "vertex 7");
  Mesh empty;
  CAROUSEL_EXPECT_THROW_WITH(BuildAtlas(&empty, SmallAtlas(), progress), InvalidArgument,
                             "no faces");
  // Zero-area faces: a vertex moved onto a neighbour (the two faces of their edge collapse).
  Mesh degenerate = MakeIcosphere(0.1, 3);
  const auto moved = Mesh::VertexHandle(5);
  degenerate.set_point(moved, degenerate.point(*degenerate.vv_begin(moved)));
  degenerate.add_vertex({1.0, 1.0, 1.0});  // isolated
  ExpectValidAtlas("degenerate", degenerate);
  AtlasBuilder builder(MakeIcosphere(0.1, 1));
  CAROUSEL_EXPECT_THROW_WITH(builder.Pack({}, 1024, progress), InvalidArgument, "flatten");
  AtlasOptions bad = SmallAtlas();
  bad.charts.seeds = 0;
  Mesh sphere = MakeIcosphere(0.1, 1);
  CAROUSEL_EXPECT_THROW_WITH(BuildAtlas(&sphere, bad, progress), InvalidArgument, "seeds");
}

// Every option of the atlas and the texture map is described once, under the flags the
// command line offers, with no name twice in what a texture session exposes (atlas, grouping,
// transfer, export); Validate's range errors name the flag.
TEST(AtlasTest, OptionsAreDescribedOnceUnderTheirFlags) {
  const OptionTable<AtlasOptions>& atlas = AtlasOptions::Fields();
  for (const char* name :
       {"seeds", "packing", "size", "max-size", "density-coverage", "gutter", "rectify-stretch"})
    EXPECT_NO_THROW(atlas.Find(name)) << name;
  EXPECT_EQ(atlas.Find("size").info.special, 0.0);
  EXPECT_EQ(atlas.Find("size").info.min, kMinAtlasSize);
  EXPECT_EQ(atlas.Find("size").info.max, kMaxAtlasSize);
  EXPECT_EQ(atlas.Find("packing").info.choices, (std::vector<std::string>{"obb", "aabb"}));
  struct Session {
    AtlasOptions atlas;
    GroupingOptions grouping;
    TransferOptions transfer;
    ExportOptions output;
  };
  OptionTable<Session> session;
  ASSERT_NO_THROW(session.Include(&Session::atlas, atlas)
                      .Include(&Session::grouping, GroupingOptions::Fields())
                      .Include(&Session::transfer, TransferOptions::Fields())
                      .Include(&Session::output, ExportOptions::Fields()));
  for (const char* name : {"exclude-views", "blend", "correction", "gain"})
    EXPECT_NO_THROW(session.Find(name)) << name;
  for (const auto& field : session.fields())
    EXPECT_FALSE(field.info.help.empty()) << field.info.name;
  // Choices are read and written as words.
  AtlasOptions options;
  atlas.Find("packing").text_set(options, "aabb");
  EXPECT_EQ(options.packing.mode, PackingMode::kAabb);
  EXPECT_EQ(atlas.Find("packing").text_get(options), "aabb");
  CAROUSEL_EXPECT_THROW_WITH(atlas.Find("packing").text_set(options, "box"), InvalidArgument,
                             "--packing must be obb or aabb, got 'box'");

  options = {};
  options.packing.gutter_texels = 99;
  CAROUSEL_EXPECT_THROW_WITH(options.Validate(), InvalidArgument,
                             "--gutter must be 0..64 texels, got 99");
  options = {};
  options.size.size = 20000;
  CAROUSEL_EXPECT_THROW_WITH(options.Validate(), InvalidArgument,
                             "--size must be 64..16384 texels, or 0 = automatic, got 20000");
  options.size.size = 0;
  options.size.max_size = 256;
  CAROUSEL_EXPECT_THROW_WITH(options.Validate(), InvalidArgument, "--max-size must be 512..16384");
  options = {};
  options.charts.seeds = 0;
  CAROUSEL_EXPECT_THROW_WITH(options.Validate(), InvalidArgument, "--seeds must be >= 1, got 0");
  // A decided side is never 0 = automatic.
  CAROUSEL_EXPECT_THROW_WITH(CheckAtlasSize(0), InvalidArgument,
                             "--size must be 64..16384 texels, got 0");
  TransferOptions transfer;
  transfer.dilation_texels = -1;
  CAROUSEL_EXPECT_THROW_WITH(transfer.Validate(), InvalidArgument, "--dilation must be 0..64");
  GroupingOptions grouping;
  grouping.max_island_faces = -1;
  CAROUSEL_EXPECT_THROW_WITH(grouping.Validate(), InvalidArgument,
                             "--max-island-faces must be >= 1 faces, or 0 = no island cleanup");
  ExportOptions output;
  output.name = "a/b";
  CAROUSEL_EXPECT_THROW_WITH(output.Validate(), InvalidArgument,
                             "--name must be a plain file stem");
}

// The atlas side is decided once: a set side as it is; automatic without photos
// min(4096, max_size); transfer refuses a side outside the one range.
TEST(AtlasTest, TheAtlasSideIsDecidedOnce) {
  Progress progress;
  const Mesh sphere = MakeIcosphere(0.1, 2);
  AtlasOptions options;
  Mesh automatic = sphere;
  EXPECT_EQ(BuildAtlas(&automatic, options, progress).size, 4096);
  options.size.max_size = 2048;
  Mesh capped = sphere;
  EXPECT_EQ(BuildAtlas(&capped, options, progress).size, 2048);
  options.size.size = 1024;
  Mesh set = sphere;
  const AtlasResult result = BuildAtlas(&set, options, progress);
  EXPECT_EQ(result.size, 1024);
  EXPECT_TRUE(result.quality.Valid());
  CAROUSEL_EXPECT_THROW_WITH(TransferTexture(set, {}, {}, 20000, {}, progress), InvalidArgument,
                             "--size must be 64..16384 texels, got 20000");
}

}  // namespace
}  // namespace carousel::texture
