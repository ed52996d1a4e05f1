#include "carousel/core/mesh_io.h"

#include <cmath>

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/mesh_primitives.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using testing::ReadBytes;
using testing::SharedDataFile;
using testing::TempDir;
using testing::WriteBytes;

double MaxVertexError(const Mesh& a, const Mesh& b) {
  double error = 0.0;
  for (Mesh::VertexHandle v : a.vertices())
    error = std::max(error, (a.point(v) - b.point(v)).norm());
  return error;
}

class MeshIoFormatTest : public ::testing::TestWithParam<const char*> {};

TEST_P(MeshIoFormatTest, RoundTripKeepsGeometryAndConnectivity) {
  TempDir dir;
  const Mesh torus = MakeTorus(0.1, 0.03, 24, 12);
  const auto path = dir / (std::string("torus") + GetParam());
  WriteMesh(torus, path);
  const Mesh back = ReadMesh(path);
  ASSERT_EQ(back.n_vertices(), torus.n_vertices());
  ASSERT_EQ(back.n_faces(), torus.n_faces());
  EXPECT_LT(MaxVertexError(torus, back), 1e-7);
  for (Mesh::FaceHandle f : torus.faces()) {
    auto a = torus.cfv_iter(f);
    auto b = back.cfv_iter(Mesh::FaceHandle(f.idx()));
    for (int k = 0; k < 3; ++k, ++a, ++b) ASSERT_EQ(a->idx(), b->idx());
  }
}

TEST_P(MeshIoFormatTest, MissingFileIsAnIoErrorNamingIt) {
  TempDir dir;
  const auto path = dir / (std::string("missing") + GetParam());
  try {
    ReadMesh(path);
    FAIL() << "no exception";
  } catch (const FormatError&) {
    FAIL() << "a missing file is not a format error";
  } catch (const IoError& e) {
    EXPECT_EQ(e.path(), path);
    EXPECT_EQ(e.reason(), "no such file");
  }
}

TEST_P(MeshIoFormatTest, EmptyFileIsAFormatError) {
  TempDir dir;
  const auto path = dir / (std::string("empty") + GetParam());
  WriteBytes(path, "");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(path), FormatError, "file is empty");
}

TEST_P(MeshIoFormatTest, BinaryGarbageIsAFormatError) {
  TempDir dir;
  const auto path = dir / (std::string("garbage") + GetParam());
  std::string garbage(4096, '\0');
  for (std::size_t i = 0; i < garbage.size(); ++i)
    garbage[i] = static_cast<char>((i * 131 + 7) % 256);
  WriteBytes(path, garbage);
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(path), FormatError, path.filename().string());
}

TEST_P(MeshIoFormatTest, TruncatedFileIsAFormatError) {
  TempDir dir;
  const auto whole = dir / (std::string("whole") + GetParam());
  WriteMesh(MakeIcosphere(0.1, 2), whole);
  const std::string bytes = ReadBytes(whole);
  for (double keep : {0.3, 0.6, 0.95}) {
    const auto path = dir / (std::string("cut") + GetParam());
    WriteBytes(path, bytes.substr(0, static_cast<std::size_t>(bytes.size() * keep)));
    EXPECT_THROW(ReadMesh(path), FormatError) << "kept " << keep << " of " << GetParam();
  }
}

std::string FormatName(const ::testing::TestParamInfo<const char*>& param_info) {
  return param_info.param + 1;  // "obj", "ply", "off"
}
INSTANTIATE_TEST_SUITE_P(Formats, MeshIoFormatTest, ::testing::Values(".obj", ".ply", ".off"),
                         FormatName);

TEST(MeshIoTest, AsciiPlyRoundTripAndTruncation) {
  TempDir dir;
  const Mesh sphere = MakeIcosphere(0.05, 1);
  WriteMesh(sphere, dir / "ascii.ply", {.binary = false});
  EXPECT_EQ(ReadBytes(dir / "ascii.ply").find("format ascii"), 4u);
  EXPECT_LT(MaxVertexError(sphere, ReadMesh(dir / "ascii.ply")), 1e-7);
  const std::string bytes = ReadBytes(dir / "ascii.ply");
  WriteBytes(dir / "cut.ply", bytes.substr(0, bytes.size() * 3 / 4));
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "cut.ply"), FormatError, "truncated");
}

TEST(MeshIoTest, ObjUvsRoundTripPerHalfedge) {
  TempDir dir;
  Mesh disc = MakeDisc(0.1, 16, 3);
  for (Mesh::HalfedgeHandle h : disc.halfedges()) {
    if (disc.is_boundary(h)) continue;
    const OpenMesh::Vec3d p = disc.point(disc.to_vertex_handle(h));
    disc.set_uv(h, OpenMesh::Vec2d(0.5 + 4 * p[0], 0.5 + 4 * p[1]));
  }
  disc.set_has_uvs(true);
  WriteMesh(disc, dir / "disc.obj");
  const Mesh back = ReadMesh(dir / "disc.obj");
  ASSERT_TRUE(back.has_uvs());
  ASSERT_EQ(back.n_faces(), disc.n_faces());
  double max_error = 0.0;
  for (Mesh::FaceHandle f : back.faces()) {
    for (Mesh::HalfedgeHandle h : back.fh_range(f)) {
      const OpenMesh::Vec3d p = back.point(back.to_vertex_handle(h));
      max_error = std::max(max_error,
                           (back.uv(h) - OpenMesh::Vec2d(0.5 + 4 * p[0], 0.5 + 4 * p[1])).norm());
    }
  }
  EXPECT_LT(max_error, 1e-6);
  // Without UVs in the file, the mesh says so.
  WriteMesh(MakeDisc(0.1, 8, 1), dir / "plain.obj");
  EXPECT_FALSE(ReadMesh(dir / "plain.obj").has_uvs());
}

TEST(MeshIoTest, ReadsTheSharedModels) {
  struct Model {
    const char* path;
    std::size_t faces;
  };
  for (const Model& model : {Model{"models/Duck/obj_derived/Duck.obj", 4212},
                             Model{"models/Avocado/obj_derived/Avocado.obj", 682},
                             Model{"models/WaterBottle/obj_derived/WaterBottle.obj", 4510}}) {
    const Mesh mesh = ReadMesh(SharedDataFile(model.path));
    EXPECT_EQ(mesh.n_faces(), model.faces) << model.path;
    EXPECT_TRUE(mesh.has_uvs()) << model.path;
    EXPECT_GT(mesh.SurfaceArea(), 0.0);
  }
}

TEST(MeshIoTest, ObjErrorsNameTheLine) {
  TempDir dir;
  WriteBytes(dir / "index.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "index.obj"), FormatError,
                             "line 4: face refers to vertex 4 but 3 vertices are defined");
  WriteBytes(dir / "short.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "short.obj"), FormatError,
                             "line 4: face needs at least 3");
  WriteBytes(dir / "nan.obj", "v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "nan.obj"), FormatError,
                             "line 2: vertex coordinate is not finite");
  WriteBytes(dir / "word.obj", "v 0 zero 0\n");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "word.obj"), FormatError, "'zero' is not a number");
  WriteBytes(dir / "points.obj", "v 0 0 0\nv 1 0 0\n");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "points.obj"), FormatError, "no faces");
}

TEST(MeshIoTest, QuadsAreTriangulatedAndNegativeIndicesWork) {
  TempDir dir;
  WriteBytes(dir / "quad.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf -4 -3 -2 -1\n");
  const Mesh mesh = ReadMesh(dir / "quad.obj");
  EXPECT_EQ(mesh.n_faces(), 2u);
  EXPECT_NEAR(mesh.SurfaceArea(), 1.0, 1e-12);
}

TEST(MeshIoTest, UnsupportedExtension) {
  TempDir dir;
  WriteBytes(dir / "mesh.stl", "solid x\nendsolid x\n");
  CAROUSEL_EXPECT_THROW_WITH(ReadMesh(dir / "mesh.stl"), FormatError,
                             "unsupported mesh format '.stl'");
  CAROUSEL_EXPECT_THROW_WITH(WriteMesh(MakeIcosphere(1, 0), dir / "mesh.stl"), InvalidArgument,
                             ".stl");
}

TEST(MeshIoTest, WriteFailuresKeepThePreviousFile) {
  TempDir dir;
  CAROUSEL_EXPECT_THROW_WITH(WriteMesh(MakeIcosphere(1, 0), dir / "nope/mesh.ply"), IoError,
                             "does not exist");
  CAROUSEL_EXPECT_THROW_WITH(WriteMesh(Mesh(), dir / "empty.ply"), InvalidArgument, "no faces");
  WriteMesh(MakeIcosphere(1, 0), dir / "mesh.ply");
  const std::string before = ReadBytes(dir / "mesh.ply");
  EXPECT_THROW(WriteMesh(MakeIcosphere(1, 1), dir / "mesh.ply", {.overwrite = false}), IoError);
  EXPECT_EQ(ReadBytes(dir / "mesh.ply"), before);
}

}  // namespace
}  // namespace carousel
