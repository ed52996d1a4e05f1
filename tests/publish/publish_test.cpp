// publish/: the web GLB (meshopt + JPEG) read back and rendered against the model it came
// from, the Khronos validator on the GLBs of a simulated session, the viewer page.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/publish/renders.h"
#include "carousel/publish/viewer_page.h"
#include "carousel/publish/web_glb.h"
#include "carousel/testing/testing.h"
#include "carousel/texture/held_out.h"
#include "small_session.h"

namespace carousel::publish {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

// A UV sphere (radius 0.1 m, centre 0.1 m above the plate) textured with a colour pattern of
// side `texture_side`; seams split the vertices as an atlas does.
texture::TexturedModel Sphere(int rings, int segments, int texture_side) {
  texture::TexturedModel m;
  for (int r = 0; r <= rings; ++r)
    for (int s = 0; s <= segments; ++s) {
      const double theta = std::numbers::pi * r / rings, phi = 2 * std::numbers::pi * s / segments;
      m.positions.emplace_back(0.1 * std::sin(theta) * std::cos(phi),
                               0.1 * std::sin(theta) * std::sin(phi), 0.1 + 0.1 * std::cos(theta));
      m.uvs.emplace_back(static_cast<float>(s) / segments, static_cast<float>(r) / rings);
    }
  const auto id = [&](int r, int s) { return r * (segments + 1) + s; };
  for (int r = 0; r < rings; ++r)
    for (int s = 0; s < segments; ++s) {
      // Counter-clockwise seen from outside.
      m.triangles.emplace_back(id(r, s), id(r + 1, s), id(r + 1, s + 1));
      m.triangles.emplace_back(id(r, s), id(r + 1, s + 1), id(r, s + 1));
    }
  m.texture = cv::Mat(texture_side, texture_side, CV_8UC3);
  for (int y = 0; y < texture_side; ++y)
    for (int x = 0; x < texture_side; ++x) {
      const double u = static_cast<double>(x) / texture_side,
                   v = static_cast<double>(y) / texture_side;
      m.texture.at<cv::Vec3b>(y, x) = cv::Vec3b(
          static_cast<uchar>(128 + 100 * std::sin(12 * u)),
          static_cast<uchar>(128 + 100 * std::cos(9 * v)),
          static_cast<uchar>((static_cast<int>(8 * u) + static_cast<int>(8 * v)) % 2 ? 220 : 40));
    }
  return m;
}

double Psnr(const cv::Mat& a, const cv::Mat& b) { return cv::PSNR(a, b); }

TEST(WebGlbTest, ReadsBackAsTheSameModelSmallerAndAtAPowerOfTwo) {
  const texture::TexturedModel model = Sphere(40, 80, 1536);
  testing::TempDir dir;
  WebGlbOptions options;
  const WebGlbResult result = WriteWebGlb(model, dir / "m.web.glb", options);
  EXPECT_EQ(result.texture_size, 2048);  // 1536 rounded up to a power of two
  EXPECT_EQ(result.triangles, model.triangles.size());
  EXPECT_EQ(result.vertices, model.positions.size());
  EXPECT_LT(result.geometry_bytes, 0.8 * static_cast<double>(result.geometry_raw_bytes));
  EXPECT_EQ(result.bytes, std::filesystem::file_size(dir / "m.web.glb"));

  const texture::TexturedModel back = ReadWebGlb(dir / "m.web.glb");
  ASSERT_EQ(back.triangles.size(), model.triangles.size());
  ASSERT_EQ(back.positions.size(), model.positions.size());
  EXPECT_EQ(back.texture.cols, 2048);
  // The turntable frame again (the file is +Y up): the bounding boxes agree.
  Eigen::AlignedBox3d a, b;
  for (const auto& p : model.positions) a.extend(p);
  for (const auto& p : back.positions) b.extend(p);
  EXPECT_LT((a.min() - b.min()).norm(), 1e-6);
  EXPECT_LT((a.max() - b.max()).norm(), 1e-6);
  // Seen by a camera, the two are the same picture up to JPEG and resampling.
  for (const double azimuth : {0.0, 130.0, 250.0}) {
    const OrbitShot shot{.azimuth_deg = azimuth, .elevation_deg = 25, .width = 320, .height = 240};
    const double psnr = Psnr(RenderShot(model, shot), RenderShot(back, shot));
    EXPECT_GT(psnr, 32.0) << "azimuth " << azimuth;
  }
  // Without compression: the same model, larger geometry.
  options.compress = false;
  options.max_texture_size = 1024;
  const WebGlbResult plain = WriteWebGlb(model, dir / "plain.glb", options);
  EXPECT_EQ(plain.texture_size, 1024);
  EXPECT_EQ(plain.geometry_bytes, plain.geometry_raw_bytes);
  const texture::TexturedModel plain_back = ReadWebGlb(dir / "plain.glb");
  EXPECT_EQ(plain_back.triangles.size(), model.triangles.size());
  EXPECT_GT(Psnr(RenderShot(back, {.width = 200, .height = 200}),
                 RenderShot(plain_back, {.width = 200, .height = 200})),
            30.0);
}

TEST(WebGlbTest, TextureSideIsAPowerOfTwoWithinTheLimit) {
  EXPECT_EQ(WebTextureSize(1536, 2048), 2048);
  EXPECT_EQ(WebTextureSize(3072, 2048), 2048);
  EXPECT_EQ(WebTextureSize(512, 2048), 512);
  EXPECT_EQ(WebTextureSize(600, 4096), 1024);
  EXPECT_EQ(WebTextureSize(10, 2048), 64);
  WebGlbOptions bad;
  bad.max_texture_size = 1000;
  EXPECT_THROW(bad.Validate(), InvalidArgument);
}

TEST(WebGlbTest, DamagedOrForeignFilesAreNamed) {
  testing::TempDir dir;
  const texture::TexturedModel model = Sphere(8, 16, 64);
  const std::vector<unsigned char> glb = EncodeWebGlb(model, {});
  // A flipped byte inside the compressed index stream, and a file cut short.
  std::vector<unsigned char> damaged = glb;
  const std::string text(glb.begin(), glb.end());
  const std::size_t bin = text.find("BIN");
  ASSERT_NE(bin, std::string::npos);
  for (std::size_t i = bin + 4; i < bin + 64 && i < damaged.size(); ++i) damaged[i] ^= 0x5a;
  testing::WriteBytes(dir / "damaged.glb", std::string(damaged.begin(), damaged.end()));
  testing::WriteBytes(dir / "short.glb", text.substr(0, text.size() / 2));
  testing::WriteBytes(dir / "text.glb", "this is not a model");
  for (const char* name : {"damaged.glb", "short.glb", "text.glb"}) {
    try {
      ReadWebGlb(dir / name);
      ADD_FAILURE() << name << " was read";
    } catch (const FormatError& e) {
      EXPECT_THAT(e.what(), HasSubstr(name));
    }
  }
  EXPECT_THROW(ReadWebGlb(dir / "missing.glb"), IoError);
  texture::TexturedModel untextured = model;
  untextured.texture = cv::Mat();
  EXPECT_THROW(EncodeWebGlb(untextured, {}), InvalidArgument);
}

TEST(OrbitCameraTest, LooksAtTheCentreAndFramesTheModel) {
  const texture::TexturedModel model = Sphere(16, 32, 64);
  const OrbitShot shot{
      .azimuth_deg = 45, .elevation_deg = 30, .width = 400, .height = 300, .fill = 0.8};
  const CameraModel camera = OrbitCamera(model, shot);
  const auto centre = camera.Project({0, 0, 0.1});
  ASSERT_TRUE(centre);
  EXPECT_NEAR(centre->x(), 199.5, 1e-6);
  EXPECT_NEAR(centre->y(), 149.5, 1e-6);
  // Up in the world is up in the image; the box's bounding sphere (radius 0.1 sqrt 3) spans 80 %
  // of the height, so the sphere inside it spans 0.8 / sqrt 3 of it.
  EXPECT_LT(camera.Project({0, 0, 0.19})->y(), centre->y());
  const cv::Mat image = RenderShot(model, shot);
  cv::Mat gray, covered;
  cv::cvtColor(image, gray, cv::COLOR_BGR2GRAY);
  cv::threshold(gray, covered, 250, 255, cv::THRESH_BINARY_INV);
  const cv::Rect box = cv::boundingRect(covered);
  EXPECT_NEAR(box.height, 0.8 * 300 / std::sqrt(3.0), 0.03 * 300);
  EXPECT_THROW(OrbitCamera(model, {.fill = 0.0}), InvalidArgument);
}

TEST(ViewerPageTest, EscapesTheNameAndShipsItsScripts) {
  const std::string html = ViewerPageHtml({.title = "Shoe <b>\"red\"</b> & co", .poster = "p.jpg"});
  EXPECT_THAT(html, HasSubstr("Shoe &lt;b&gt;&quot;red&quot;&lt;/b&gt; &amp; co"));
  EXPECT_THAT(html, Not(HasSubstr("<b>")));
  EXPECT_THAT(html, HasSubstr("src=\"model.web.glb\""));
  EXPECT_THAT(html, HasSubstr("poster=\"p.jpg\""));
  EXPECT_THAT(html, HasSubstr("meshoptDecoderLocation = 'meshopt_decoder.js'"));
  EXPECT_THAT(html, Not(HasSubstr("http")));  // nothing from the network
  testing::TempDir dir;
  const WebRuntime runtime = FindWebRuntime();
  WriteViewerPage(dir.path(), {.title = "x"}, runtime);
  for (const char* file : {"index.html", "model-viewer.min.js", "meshopt_decoder.js"})
    EXPECT_TRUE(std::filesystem::is_regular_file(dir / file)) << file;
  EXPECT_EQ(ReadFileBytes(dir / "model-viewer.min.js"), ReadFileBytes(runtime.model_viewer));
  // Missing packages are named with what to do.
  ::setenv("CAROUSEL_WEB_MODULES", (dir / "nothing").c_str(), 1);
  try {
    FindWebRuntime();
    ADD_FAILURE() << "found packages in an empty folder";
  } catch (const IoError& e) {
    EXPECT_THAT(e.what(), HasSubstr("model-viewer"));
    EXPECT_THAT(e.what(), HasSubstr("install-deps"));
  }
  ::unsetenv("CAROUSEL_WEB_MODULES");
}

TEST(GltfValidatorTest, TheSessionsGlbsHaveNoErrorsAndNoWarnings) {
  const std::filesystem::path model = SmallSession() / "model";
  const testing::ShellResult check = testing::RunShell(
      "node " + std::string(CAROUSEL_SOURCE_DIR) + "/tests/web/validate-gltf.mjs " +
      (model / "model.glb").string() + " " + (model / "model.web.glb").string());
  EXPECT_EQ(check.code, 0) << check.out;
  EXPECT_THAT(check.out, HasSubstr("model.glb: 0 errors, 0 warnings"));
  EXPECT_THAT(check.out, HasSubstr("model.web.glb: 0 errors, 0 warnings"));
  // The validator does fail: a truncated copy has errors.
  testing::TempDir dir;
  const std::string bytes = testing::ReadBytes(model / "model.web.glb");
  testing::WriteBytes(dir / "cut.glb", bytes.substr(0, bytes.size() / 3));
  const testing::ShellResult cut =
      testing::RunShell("node " + std::string(CAROUSEL_SOURCE_DIR) +
                        "/tests/web/validate-gltf.mjs " + (dir / "cut.glb").string());
  EXPECT_EQ(cut.code, 1) << cut.out;
}

TEST(PublishStageTest, WebGlbScoresAsTheLosslessOneAndIsSmaller) {
  const std::filesystem::path model = SmallSession() / "model";
  for (const char* file : {"index.html", "poster.jpg", "model.web.glb", "model-viewer.min.js",
                           "meshopt_decoder.js", "publish.json"})
    EXPECT_TRUE(std::filesystem::is_regular_file(model / file)) << file;
  const auto summary = nlohmann::json::parse(testing::ReadBytes(model / "publish.json"));
  const double web = summary["held_out"]["mean_psnr_db_web"].get<double>();
  const double lossless = summary["held_out"]["mean_psnr_db_lossless"].get<double>();
  EXPECT_GT(lossless, 15.0);
  EXPECT_NEAR(web, lossless, 0.3);
  EXPECT_LT(summary["web_glb"]["bytes"].get<double>(),
            0.5 * summary["lossless_glb"]["bytes"].get<double>());
}

// Headless Chromium (Debian's) through puppeteer-core opens the viewer page from a local
// server, waits for model-viewer's load event and photographs 4 camera angles
// (tests/web/viewer-shots.mjs): every shot shows the product at a sane size, and the first is
// the picture our own renderer makes of the same GLB from the camera model-viewer reports:
// a third-party renderer reads our axes, UVs and colours as we do.
TEST(BrowserTest, ModelViewerShowsTheWebGlbAsOurRendererDoes) {
  const std::filesystem::path model = SmallSession() / "model";
  testing::TempDir out;
  const testing::ShellResult shots = testing::RunShell(
      "node " + std::string(CAROUSEL_SOURCE_DIR) + "/tests/web/viewer-shots.mjs --site " +
      model.string() + " --page index.html --out " + out.path().string() +
      " --width 480 --height 360 --timeout 120");
  ASSERT_EQ(shots.code, 0) << shots.out;
  const auto json = nlohmann::json::parse(testing::ReadBytes(out / "shots.json"));
  ASSERT_EQ(json["shots"].size(), 4u);
  EXPECT_TRUE(json["external_requests"].empty()) << json["external_requests"].dump();
  const texture::TexturedModel web = ReadWebGlb(model / "model.web.glb");
  for (std::size_t k = 0; k < json["shots"].size(); ++k) {
    const auto& shot = json["shots"][k];
    const double fraction = shot["nonwhite_fraction"].get<double>();
    EXPECT_GT(fraction, 0.03) << "shot " << k;
    EXPECT_LT(fraction, 0.8) << "shot " << k;
    // glTF (x, y, z) is the turntable's (x, -z, y).
    const auto world = [](const nlohmann::json& p) {
      return Eigen::Vector3d(p[0].get<double>(), -p[2].get<double>(), p[1].get<double>());
    };
    const CameraModel camera = PinholeLookingAt(
        world(shot["camera_position_m"]), world(shot["reported"]["camera_target_m"]),
        shot["fov_deg"].get<double>(), shot["width"].get<int>(), shot["height"].get<int>());
    texture::ModelRenderOptions options;
    options.backdrop_top_bgr = options.backdrop_bottom_bgr = {255, 255, 255};
    const cv::Mat ours = texture::RenderTexturedModel(web, camera, options).image;
    const cv::Mat theirs =
        cv::imread((out / shot["file"].get<std::string>()).string(), cv::IMREAD_COLOR);
    ASSERT_EQ(theirs.size(), ours.size()) << "shot " << k;
    // Over the pixels where either image shows the object (the white backdrop would inflate
    // a whole-frame figure).
    cv::Mat gray_ours, gray_theirs;
    cv::cvtColor(ours, gray_ours, cv::COLOR_BGR2GRAY);
    cv::cvtColor(theirs, gray_theirs, cv::COLOR_BGR2GRAY);
    const cv::Mat object = (gray_ours < 250) | (gray_theirs < 250);
    cv::Mat diff;
    cv::absdiff(ours, theirs, diff);
    diff.convertTo(diff, CV_64FC3);
    cv::Mat squared = diff.mul(diff);
    squared.setTo(cv::Scalar::all(0), ~object);
    const cv::Scalar sum = cv::sum(squared);
    const double mse = (sum[0] + sum[1] + sum[2]) / (3.0 * std::max(1, cv::countNonZero(object)));
    const double psnr = 10 * std::log10(255.0 * 255.0 / std::max(mse, 1e-10));
    std::printf(
        "shot %zu: object covers %.1f %% of the frame; PSNR vs our renderer %.2f dB over "
        "the object\n",
        k, 100 * fraction, psnr);
    EXPECT_GT(psnr, 28.0) << "shot " << k;
  }
}

}  // namespace
}  // namespace carousel::publish
