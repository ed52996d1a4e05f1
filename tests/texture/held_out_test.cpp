// Held-out scoring: a textured quad rendered through a known camera reproduces its texture, a
// wrong UV flip is caught by the scores, mip-mapping averages a minified texture, the backdrop
// shows where the model does not, the GLB read back renders like the mesh it came from, and
// the scores' definitions (PSNR, masked SSIM, silhouette IoU).
#include "carousel/texture/held_out.h"

#include <cmath>
#include <map>
#include <random>

#include <gtest/gtest.h>

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"
#include "carousel/core/mesh_io.h"
#include "carousel/testing/testing.h"
#include "carousel/texture/export.h"
#include "carousel/texture/textured_model.h"

namespace carousel::texture {
namespace {

using carousel::testing::TempDir;

// A pinhole camera at the origin looking down +z (world = camera frame); powers of two so that
// points given at pixel coordinates project back exactly.
CameraModel Pinhole(int width, int height) {
  CameraModel camera;
  camera.width = width;
  camera.height = height;
  camera.fx = camera.fy = 256.0;
  camera.cx = width / 2.0;
  camera.cy = height / 2.0;
  return camera;
}

Eigen::Vector3d AtPixel(const CameraModel& camera, double u, double v, double z) {
  return {(u - camera.cx) / camera.fx * z, (v - camera.cy) / camera.fy * z, z};
}

// A texture that is neither symmetric nor smooth: a gradient, blocks of random colour, a bar.
cv::Mat Pattern(int width, int height) {
  cv::Mat texture(height, width, CV_8UC3);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> level(0, 255);
  cv::Mat blocks(height / 8 + 1, width / 8 + 1, CV_8UC3);
  for (int y = 0; y < blocks.rows; ++y)
    for (int x = 0; x < blocks.cols; ++x)
      blocks.at<cv::Vec3b>(y, x) = cv::Vec3b(level(rng), level(rng), level(rng));
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const cv::Vec3b& b = blocks.at<cv::Vec3b>(y / 8, x / 8);
      texture.at<cv::Vec3b>(y, x) = cv::Vec3b(static_cast<std::uint8_t>((b[0] + 2 * y) % 256), b[1],
                                              y < height / 4 ? 255 : b[2]);
    }
  return texture;
}

// A fronto-parallel quad covering the pixels [x0, x0 + w) x [y0, y0 + h) exactly (its corners
// on pixel corners), UV (0,0) at its top-left: one texel per pixel for a w x h texture.
TexturedModel Quad(const CameraModel& camera, int x0, int y0, int w, int h, const cv::Mat& texture,
                   double z = 1.0) {
  TexturedModel model;
  model.positions = {
      AtPixel(camera, x0 - 0.5, y0 - 0.5, z), AtPixel(camera, x0 + w - 0.5, y0 - 0.5, z),
      AtPixel(camera, x0 + w - 0.5, y0 + h - 0.5, z), AtPixel(camera, x0 - 0.5, y0 + h - 0.5, z)};
  model.uvs = {{0.0f, 0.0f}, {1.0f, 0.0f}, {1.0f, 1.0f}, {0.0f, 1.0f}};
  model.triangles = {{0, 1, 2}, {0, 2, 3}};
  model.texture = texture;
  return model;
}

double Psnr(const cv::Mat& a, const cv::Mat& b) {
  const double mse = cv::norm(a, b, cv::NORM_L2SQR) / static_cast<double>(a.total() * a.channels());
  return mse > 0 ? 10.0 * std::log10(255.0 * 255.0 / mse) : 99.0;
}

TEST(HeldOutTest, AQuadOnePixelPerTexelReproducesItsTexture) {
  const CameraModel camera = Pinhole(200, 160);
  const cv::Mat texture = Pattern(128, 96);
  const cv::Rect where(40, 30, 128, 96);
  const ModelRendering r =
      RenderTexturedModel(Quad(camera, where.x, where.y, where.width, where.height, texture),
                          camera, {.samples_per_axis = 1});
  // Pixel centres are texel centres: the texture itself, up to the 8-bit sRGB round trip.
  EXPECT_GT(Psnr(r.image(where), texture), 50.0);
  EXPECT_EQ(cv::countNonZero(r.mask(where)), where.area());
  EXPECT_EQ(cv::countNonZero(r.mask), where.area());
  // With 2 x 2 samples the diagonal's pixels are shaded per half: still close.
  const ModelRendering aa = RenderTexturedModel(
      Quad(camera, where.x, where.y, where.width, where.height, texture), camera);
  EXPECT_GT(Psnr(aa.image(where), texture), 30.0);
  EXPECT_EQ(cv::countNonZero(aa.mask), where.area());
}

TEST(HeldOutTest, AFlippedUvIsCaughtByTheScores) {
  const CameraModel camera = Pinhole(200, 160);
  const cv::Mat texture = Pattern(128, 96);
  const cv::Rect where(40, 30, 128, 96);
  // The "photo": the texture on the backdrop the renderer draws, and its mask.
  const TexturedModel right = Quad(camera, where.x, where.y, where.width, where.height, texture);
  cv::Mat photo = RenderTexturedModel(right, camera).image.clone();
  texture.copyTo(photo(where));
  cv::Mat mask = cv::Mat::zeros(camera.height, camera.width, CV_8UC1);
  mask(where).setTo(255);
  View view(camera, {});
  view.SetImage(photo);
  const HeldOutScore good = ScoreHeldOutView(right, view, 7, mask);
  TexturedModel flipped = right;
  for (Eigen::Vector2f& uv : flipped.uvs) uv.y() = 1.0f - uv.y();
  const HeldOutScore bad = ScoreHeldOutView(flipped, view, 7, mask);
  std::printf("right UVs: PSNR %.2f dB, SSIM %.4f; flipped: PSNR %.2f dB, SSIM %.4f\n",
              good.psnr_db, good.ssim, bad.psnr_db, bad.ssim);
  EXPECT_EQ(good.view, 7);
  EXPECT_GT(good.psnr_db, 30.0);
  EXPECT_GT(good.ssim, 0.95);
  EXPECT_DOUBLE_EQ(good.mask_agreement, 1.0);
  EXPECT_LT(bad.psnr_db, good.psnr_db - 15.0);
  EXPECT_LT(bad.ssim, 0.5);
  EXPECT_DOUBLE_EQ(bad.mask_agreement, 1.0);  // the silhouette does not see UVs
}

TEST(HeldOutTest, MipMappingAveragesAMinifiedTexture) {
  // A one-texel checkerboard, ~4.3 x 4.3 texels per pixel: mip levels 2 and 3 are flat grey.
  cv::Mat checker(256, 256, CV_8UC3);
  for (int y = 0; y < checker.rows; ++y)
    for (int x = 0; x < checker.cols; ++x)
      checker.at<cv::Vec3b>(y, x) = (x + y) % 2 ? cv::Vec3b(255, 255, 255) : cv::Vec3b(0, 0, 0);
  const CameraModel camera = Pinhole(100, 100);
  const cv::Rect where(18, 18, 60, 60);
  const TexturedModel quad = Quad(camera, where.x, where.y, where.width, where.height, checker);
  const cv::Rect inside(where.x + 2, where.y + 2, where.width - 4, where.height - 4);
  cv::Scalar mean, deviation;
  cv::meanStdDev(RenderTexturedModel(quad, camera).image(inside), mean, deviation);
  EXPECT_NEAR(mean[0], 128.0, 3.0);  // the pyramid averages 8-bit values, as viewers do
  EXPECT_LT(deviation[0], 3.0);
  cv::meanStdDev(RenderTexturedModel(quad, camera, {.mipmaps = false}).image(inside), mean,
                 deviation);
  EXPECT_GT(deviation[0], 20.0);  // aliasing without the pyramid
}

TEST(HeldOutTest, TheBackdropShowsWhereTheModelDoesNot) {
  const CameraModel camera = Pinhole(64, 48);
  const cv::Mat red(16, 16, CV_8UC3, cv::Scalar(0, 0, 255));
  // Right edge of the quad through pixel centres x = 30: half of those pixels' samples.
  TexturedModel quad = Quad(camera, 10, 10, 20, 20, red);
  const ModelRendering r = RenderTexturedModel(quad, camera);
  EXPECT_EQ(r.image.at<cv::Vec3b>(0, 0), cv::Vec3b(245, 245, 245));
  EXPECT_EQ(r.image.at<cv::Vec3b>(47, 63), cv::Vec3b(219, 219, 219));
  EXPECT_EQ(r.image.at<cv::Vec3b>(20, 20), cv::Vec3b(0, 0, 255));
  EXPECT_EQ(r.mask.at<std::uint8_t>(20, 20), 255);
  EXPECT_EQ(r.mask.at<std::uint8_t>(5, 5), 0);
  // Edge pixels blend in linear light: between the two, brighter than the sRGB midpoint's red.
  quad.positions[1] = AtPixel(camera, 30.0, 9.5, 1.0);
  quad.positions[2] = AtPixel(camera, 30.0, 29.5, 1.0);
  const cv::Vec3b edge = RenderTexturedModel(quad, camera).image.at<cv::Vec3b>(20, 30);
  EXPECT_GT(edge[2], 240);
  EXPECT_GT(edge[0], 150);
  EXPECT_LT(edge[0], 200);  // half of the backdrop's ~0.83 in linear light: sRGB ~171
  // Options are checked.
  EXPECT_THROW(RenderTexturedModel(quad, camera, {.samples_per_axis = 0}), InvalidArgument);
  quad.triangles[0][2] = 9;
  EXPECT_THROW(RenderTexturedModel(quad, camera), InvalidArgument);
}

// A unit-ish quad mesh in the turntable frame (z up), with UVs (v up) over a texture.
Mesh TexturedQuadMesh() {
  Mesh mesh;
  const auto a = mesh.add_vertex({-0.1, 0.0, 0.0}), b = mesh.add_vertex({0.1, 0.0, 0.0}),
             c = mesh.add_vertex({0.1, 0.0, 0.15}), d = mesh.add_vertex({-0.1, 0.0, 0.15});
  const Mesh::FaceHandle f0 = mesh.add_face(a, b, c), f1 = mesh.add_face(a, c, d);
  const std::map<int, OpenMesh::Vec2d> uv = {{a.idx(), {0.05, 0.05}},
                                             {b.idx(), {0.95, 0.05}},
                                             {c.idx(), {0.95, 0.95}},
                                             {d.idx(), {0.05, 0.95}}};
  for (const auto f : {f0, f1})
    for (const auto h : mesh.fh_range(f)) mesh.set_uv(h, uv.at(mesh.to_vertex_handle(h).idx()));
  mesh.set_has_uvs(true);
  return mesh;
}

TEST(HeldOutTest, TheGlbReadBackRendersLikeTheMeshItCameFrom) {
  const Mesh mesh = TexturedQuadMesh();
  const cv::Mat texture = Pattern(256, 256);
  TempDir dir;
  const ExportResult files = ExportTexturedModel(mesh, texture, dir.path(), {});
  const TexturedModel glb = ReadTexturedModel(files.glb);
  const TexturedModel memory = TexturedModelFromMesh(mesh, texture);
  EXPECT_EQ(glb.triangles.size(), 2u);
  EXPECT_EQ(glb.wrap, TexturedModel::Wrap::kClampToEdge);
  EXPECT_EQ(cv::norm(glb.texture, texture, cv::NORM_INF), 0.0);  // PNG: lossless
  const cv::Mat png = cv::imread(files.texture.string(), cv::IMREAD_COLOR);
  ASSERT_EQ(png.size(), texture.size());
  EXPECT_EQ(cv::norm(png, texture, cv::NORM_INF), 0.0);
  // Z up again: the quad stands in the plane y = 0, from z = 0 to 0.15.
  for (const Eigen::Vector3d& p : glb.positions) {
    EXPECT_NEAR(p.y(), 0.0, 1e-6);
    EXPECT_GT(p.z(), -1e-6);
    EXPECT_LT(p.z(), 0.15 + 1e-6);
  }
  // Seen from the front (-y), with lens distortion.
  CameraModel camera = Pinhole(240, 180);
  camera.fx = camera.fy = 300;
  camera.distortion.k1 = -0.15;
  camera.cam_from_world = Rigid3d::LookAt({0.05, -0.5, 0.12}, {0.0, 0.0, 0.075});
  const ModelRendering a = RenderTexturedModel(glb, camera);
  const ModelRendering b = RenderTexturedModel(memory, camera);
  EXPECT_GT(cv::countNonZero(a.mask), 10000);
  EXPECT_LE(cv::norm(a.mask, b.mask, cv::NORM_L1), 255.0 * 4);
  EXPECT_GT(Psnr(a.image, b.image), 45.0);
  // The texture's top-left corner (v up: UV (0.05, 0.95)) is the quad's top-left seen from the
  // front: the image's top rows show the texture's top rows (the bright bar).
  const int top = [&] {
    for (int y = 0; y < a.mask.rows; ++y)
      if (cv::countNonZero(a.mask.row(y)) > 0) return y;
    return -1;
  }();
  ASSERT_GE(top, 0);
  const int middle = a.image.cols / 2;
  EXPECT_GT(a.image.at<cv::Vec3b>(top + 5, middle)[2], 250);
}

// The OBJ is Y-up by default (Blender, MeshLab): the quad, standing from z = 0 to 0.15 in the
// turntable frame, stands from y = 0 to 0.15 in the file; --obj-up z keeps the turntable frame.
TEST(HeldOutTest, TheObjIsYUpUnlessAskedForTheTurntableFrame) {
  const Mesh mesh = TexturedQuadMesh();
  const cv::Mat texture = Pattern(64, 64);
  TempDir dir;
  const auto heights = [&](ExportOptions::Up up, int axis) {
    ExportOptions options;
    options.obj_up = up;
    const ExportResult files = ExportTexturedModel(mesh, texture, dir.path(), options);
    const Mesh obj = ReadMesh(files.obj);
    double lo = 1e9, hi = -1e9;
    for (const auto v : obj.vertices()) {
      lo = std::min(lo, obj.point(v)[axis]);
      hi = std::max(hi, obj.point(v)[axis]);
    }
    return std::make_pair(lo, hi);
  };
  const auto [y_lo, y_hi] = heights(ExportOptions::Up::kY, 1);
  EXPECT_NEAR(y_lo, 0.0, 1e-6);
  EXPECT_NEAR(y_hi, 0.15, 1e-6);
  const auto [z_lo, z_hi] = heights(ExportOptions::Up::kZ, 2);
  EXPECT_NEAR(z_lo, 0.0, 1e-6);
  EXPECT_NEAR(z_hi, 0.15, 1e-6);
  ExportOptions bad;
  EXPECT_THROW(ExportOptions::Fields().Find("obj-up").text_set(bad, "x"), InvalidArgument);
}

TEST(HeldOutTest, ReadingABadFileNamesIt) {
  TempDir dir;
  CAROUSEL_EXPECT_THROW_WITH(ReadTexturedModel(dir / "missing.glb"), IoError, "missing.glb");
  carousel::testing::WriteBytes(dir / "garbage.glb", "glTF but not really");
  CAROUSEL_EXPECT_THROW_WITH(ReadTexturedModel(dir / "garbage.glb"), FormatError, "garbage.glb");
  EXPECT_THROW(TexturedModelFromMesh(Mesh(), cv::Mat()), InvalidArgument);
}

TEST(HeldOutTest, ScoresAreDefinedOverTheReferenceMask) {
  const cv::Rect object(10, 10, 40, 40);
  cv::Mat photo(60, 80, CV_8UC3, cv::Scalar(100, 120, 140));
  cv::randu(photo(object), 10, 255);  // >= 10: no clipping at 0 below
  cv::Mat mask = cv::Mat::zeros(60, 80, CV_8UC1);
  mask(object).setTo(255);
  const ModelRendering same{photo.clone(), mask.clone()};
  HeldOutScore s = CompareWithPhoto(same, photo, mask, 3);
  EXPECT_EQ(s.view, 3);
  EXPECT_DOUBLE_EQ(s.psnr_db, 99.0);
  EXPECT_NEAR(s.ssim, 1.0, 1e-6);
  EXPECT_DOUBLE_EQ(s.mask_agreement, 1.0);
  // Off by 10 levels everywhere inside the mask (MSE 100); anything outside it is ignored.
  ModelRendering off{photo.clone(), mask.clone()};
  off.image(object) -= cv::Scalar::all(10);
  off.image(cv::Rect(60, 0, 20, 60)).setTo(cv::Scalar(0, 255, 0));
  s = CompareWithPhoto(off, photo, mask, 3);
  EXPECT_NEAR(s.psnr_db, 10.0 * std::log10(255.0 * 255.0 / 100.0), 1e-9);
  EXPECT_LT(s.ssim, 1.0);
  EXPECT_GT(s.ssim, 0.9);  // a small offset of a textured patch keeps its structure
  // Half the silhouette: IoU 1/2.
  off.mask = cv::Mat::zeros(60, 80, CV_8UC1);
  off.mask(cv::Rect(10, 10, 20, 40)).setTo(255);
  EXPECT_DOUBLE_EQ(CompareWithPhoto(off, photo, mask, 3).mask_agreement, 0.5);
  EXPECT_THROW(CompareWithPhoto(off, photo(cv::Rect(0, 0, 40, 40)), mask, 3), InvalidArgument);
  const std::vector<HeldOutScore> two = {{0, 20.0, 0.5, 1.0}, {1, 30.0, 0.7, 1.0}};
  EXPECT_DOUBLE_EQ(MeanPsnrDb(two), 25.0);
  EXPECT_DOUBLE_EQ(MeanSsim(two), 0.6);
  EXPECT_DOUBLE_EQ(MeanPsnrDb({}), 0.0);
}

}  // namespace
}  // namespace carousel::texture
