#include "carousel/texture/atlas.h"

#include <cmath>
#include <filesystem>
#include <limits>
#include <set>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/testing/testing.h"

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
  options.packing.size = 1024;
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

// Flat, developable and gently curved surfaces flatten almost without stretch; charts stay
// few (the paper: 10-13 from 10 seeds).
TEST(AtlasTest, StretchAndChartCountOnSmoothSurfaces) {
  for (NamedMesh& m : ProceduralMeshes()) {
    if (m.name == "blob") continue;
    Progress progress;
    const AtlasResult result = BuildAtlas(&m.mesh, SmallAtlas(), progress);
    EXPECT_LE(result.quality.l2_stretch, 1.03) << m.name;
    EXPECT_LE(result.quality.angle_distortion_deg, 2.0) << m.name;
    EXPECT_LE(result.quality.charts, 20) << m.name;
  }
}

// An angle-preserving flattening shrinks protrusions: on a real reconstruction (the shoe's
// heel tab and opening) some faces got a hundredth of their share of texels (L2 stretch 6.8)
// until charts were split on stretch.
TEST(AtlasTest, ProtrusionsAreNotStarvedOfTexels) {
  const Mesh shoe =
      ReadMesh(std::filesystem::path(CAROUSEL_TEST_DATA_DIR) / "shoe_reconstructed_4500.ply");
  Progress progress;
  AtlasOptions options = SmallAtlas();
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
    const double aabb = builder.Pack(options, progress).texels_per_metre;
    options.mode = PackingMode::kObb;
    const double obb = builder.Pack(options, progress).texels_per_metre;
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
  CAROUSEL_EXPECT_THROW_WITH(builder.Pack({}, progress), InvalidArgument, "flatten");
  AtlasOptions bad = SmallAtlas();
  bad.charts.seeds = 0;
  Mesh sphere = MakeIcosphere(0.1, 1);
  CAROUSEL_EXPECT_THROW_WITH(BuildAtlas(&sphere, bad, progress), InvalidArgument, "seeds");
}

}  // namespace
}  // namespace carousel::texture
