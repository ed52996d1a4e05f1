// carousel-studio's command line (through the options descriptions), frame-time figures, and
// the model view's data and camera, without a window.
#include <gtest/gtest.h>

#include <cmath>

#include "carousel/core/error.h"
#include "carousel/gui/model_view.h"
#include "carousel/gui/studio_args.h"
#include "carousel/studio/rig_config.h"
#include "carousel/testing/testing.h"

namespace carousel::gui {
namespace {

TEST(StudioArgsTest, CaptureFlagsMeanWhatTheyMeanInCarouselRun) {
  const StudioArgs args = ParseStudioArgs({"--sim",
                                           "--scene",
                                           "bottle",
                                           "--product",
                                           "sku 1",
                                           "--out",
                                           "/tmp/x",
                                           "--size",
                                           "480x320",
                                           "--views",
                                           "8",
                                           "--exclude-views",
                                           "2,5",
                                           "--no-publish",
                                           "--autorun",
                                           "--screenshot-dir",
                                           "shots",
                                           "--frame-log=frames.txt",
                                           "--quit-when-done",
                                           "--spin-size",
                                           "240"});
  EXPECT_EQ(args.run.sim.scene, "bottle");
  EXPECT_EQ(args.run.product, "sku 1");
  EXPECT_EQ(args.run.out, "/tmp/x");
  EXPECT_EQ(args.run.sim.rig.width, 480);
  EXPECT_EQ(args.run.sim.rig.height, 320);
  EXPECT_EQ(args.run.sim.stops, 8);
  EXPECT_EQ(args.run.texture.grouping.exclude_views, (std::vector<int>{2, 5}));
  EXPECT_FALSE(args.run.publish_model);
  EXPECT_EQ(args.run.publish.spin_size, 240);
  EXPECT_TRUE(args.autorun);
  EXPECT_TRUE(args.quit_when_done);
  EXPECT_EQ(args.screenshot_dir, "shots");
  EXPECT_EQ(args.frame_log, "frames.txt");
  EXPECT_FALSE(args.operator_mode);
  EXPECT_FALSE(args.run.sim.data_dir.empty());
}

TEST(StudioArgsTest, MistakesNameTheFlag) {
  EXPECT_THAT(
      [] {
        ParseStudioArgs({"--views", "many"});
      },
      ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("--views")));
  EXPECT_THAT(
      [] {
        ParseStudioArgs({"--views", "0", "--product", "a"});
      },
      ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("--views")));
  EXPECT_THAT([] { ParseStudioArgs({"--frobnicate"}); },
              ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("--frobnicate")));
  EXPECT_THAT([] { ParseStudioArgs({"--out"}); }, ::testing::ThrowsMessage<InvalidArgument>(
                                                      ::testing::HasSubstr("--out needs a value")));
  EXPECT_THAT([] { ParseStudioArgs({"--autorun"}); },
              ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("--product")));
  EXPECT_THAT(
      [] {
        ParseStudioArgs({"--product", "a", "--product", "b"});
      },
      ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("--operator")));
  EXPECT_THAT(
      [] {
        ParseStudioArgs({"--sim", "--rig", "rig.json"});
      },
      ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("exclude")));
  EXPECT_THAT([] { ParseStudioArgs({"shoe"}); },
              ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("'shoe'")));
  // The operator presses once per product.
  const StudioArgs op = ParseStudioArgs({"--operator", "--product", "a", "--product", "b"});
  EXPECT_EQ(op.products, (std::vector<std::string>{"a", "b"}));
  // Usage lists the described options with their ranges.
  const std::string usage = StudioUsage();
  EXPECT_NE(usage.find("--exclude-views"), std::string::npos);
  EXPECT_NE(usage.find("--spin-size"), std::string::npos);
  EXPECT_NE(usage.find("--operator"), std::string::npos);
}

TEST(OptionTextTest, FieldsReadBackWhatTheyWrite) {
  struct Sample {
    int count = 3;
    double scale = 0.5;
    bool on = true;
    std::vector<int> views = {1, 2};
    std::string name = "x";
  };
  OptionTable<Sample> table;
  table.Add(&Sample::count, {.name = "count", .min = 1});
  table.Add(&Sample::scale, {.name = "scale"});
  table.Add(&Sample::on, {.name = "on"});
  table.Add(&Sample::views, {.name = "views"});
  table.Add(&Sample::name, {.name = "name"});
  Sample s;
  EXPECT_EQ(GetOptionText(table.Find("views"), s), "1,2");
  EXPECT_EQ(GetOptionText(table.Find("scale"), s), "0.5");
  EXPECT_EQ(GetOptionText(table.Find("on"), s), "true");
  SetOptionText(table.Find("count"), s, " 12 ");
  SetOptionText(table.Find("scale"), s, "1e-3");
  SetOptionText(table.Find("on"), s, "off");
  SetOptionText(table.Find("views"), s, "4, 7,9");
  SetOptionText(table.Find("name"), s, "a b");
  EXPECT_EQ(s.count, 12);
  EXPECT_DOUBLE_EQ(s.scale, 1e-3);
  EXPECT_FALSE(s.on);
  EXPECT_EQ(s.views, (std::vector<int>{4, 7, 9}));
  EXPECT_EQ(s.name, "a b");
  SetOptionText(table.Find("views"), s, "");
  EXPECT_TRUE(s.views.empty());
  for (const char* bad : {"12abc", "", "1.5", "99999999999"})
    EXPECT_THROW(SetOptionText(table.Find("count"), s, bad), InvalidArgument) << bad;
  EXPECT_THROW(SetOptionText(table.Find("scale"), s, "nan"), InvalidArgument);
  EXPECT_THROW(SetOptionText(table.Find("on"), s, "maybe"), InvalidArgument);
  EXPECT_THROW(SetOptionText(table.Find("views"), s, "1,,2"), InvalidArgument);
}

TEST(CapturePlanFieldsTest, TheHardwarePlanIsEditedThroughItsDescription) {
  studio::CapturePlan plan;
  const OptionTable<studio::CapturePlan>& table = studio::CapturePlan::Fields();
  SetOptionText(table.Find("stops"), plan, "24");
  SetOptionText(table.Find("settle-ms"), plan, "150");
  SetOptionText(table.Find("shutter"), plan, "controller");
  SetOptionText(table.Find("mask-shots"), plan, "backlit");
  table.Check(plan);
  plan.Validate();
  EXPECT_EQ(plan.stops, 24);
  EXPECT_EQ(plan.settle_ms, 150);
  EXPECT_EQ(plan.shutter, "controller");
  EXPECT_EQ(plan.mask_shots, "backlit");
  studio::CapturePlan bad = plan;
  SetOptionText(table.Find("shutter"), bad, "remote");
  EXPECT_THAT([&] { table.Check(bad); },
              ::testing::ThrowsMessage<InvalidArgument>(::testing::HasSubstr("--shutter")));
  SetOptionText(table.Find("stops"), bad, "0");
  EXPECT_THROW(table.Check(bad), InvalidArgument);
  EXPECT_TRUE(table.Find("delete-from-camera").info.advanced);
}

TEST(FrameStatsTest, PercentilesOfTheLoggedFrames) {
  std::vector<double> ms(200, 16.0);
  ms[10] = 40.0;
  ms[20] = 90.0;
  ms[30] = 40.0;
  const FrameStats stats = SummarizeFrameTimes(ms);
  EXPECT_EQ(stats.frames, 200);
  EXPECT_DOUBLE_EQ(stats.p50_ms, 16.0);
  EXPECT_DOUBLE_EQ(stats.p99_ms, 40.0);  // the 198th of 200 sorted (nearest rank)
  EXPECT_DOUBLE_EQ(stats.max_ms, 90.0);
  EXPECT_EQ(SummarizeFrameTimes({}).frames, 0);
  testing::TempDir dir;
  testing::WriteBytes(dir / "frames.txt", "16.5\n17\n\n");
  EXPECT_EQ(ReadFrameLog(dir / "frames.txt"), (std::vector<double>{16.5, 17.0}));
  testing::WriteBytes(dir / "bad.txt", "16.5\nslow\n");
  EXPECT_THAT([&] { ReadFrameLog(dir / "bad.txt"); },
              ::testing::ThrowsMessage<FormatError>(::testing::HasSubstr("line 2")));
}

// Two unit squares in the z = 0 plane, 1 mm apart, each its own UV island: the left one on a
// quarter of the texture, the right one on a sixteenth.
texture::TexturedModel TwoSquares() {
  texture::TexturedModel model;
  const double s = 0.001;  // 1 mm
  for (int k = 0; k < 2; ++k) {
    const double x0 = k * 2 * s;
    const float u = k == 0 ? 0.5f : 0.25f;
    const int base = static_cast<int>(model.positions.size());
    model.positions.insert(model.positions.end(),
                           {{x0, 0, 0}, {x0 + s, 0, 0}, {x0 + s, s, 0}, {x0, s, 0}});
    model.uvs.insert(model.uvs.end(), {{0, u}, {u, u}, {u, 0}, {0, 0}});
    model.triangles.push_back({base, base + 1, base + 2});
    model.triangles.push_back({base, base + 2, base + 3});
  }
  model.texture = cv::Mat(64, 64, CV_8UC3, cv::Scalar(10, 20, 30));
  return model;
}

TEST(ModelViewTest, ChartsAndTexelDensityPerTriangle) {
  const texture::TexturedModel model = TwoSquares();
  int charts = 0;
  EXPECT_EQ(TriangleCharts(model, &charts), (std::vector<int>{0, 0, 1, 1}));
  EXPECT_EQ(charts, 2);
  const ModelMesh mesh = PrepareModelMesh(model);
  EXPECT_EQ(mesh.triangles, 4);
  EXPECT_EQ(mesh.charts, 2);
  EXPECT_EQ(mesh.positions.size(), 4u * 9u);
  EXPECT_EQ(mesh.uvs.size(), 4u * 6u);
  // 32 x 32 texels on 1 mm^2 and 16 x 16: 32 and 16 texels per mm.
  EXPECT_NEAR(mesh.density_p10, 16.0, 1e-3);
  EXPECT_NEAR(mesh.density_p90, 32.0, 1e-3);
  // The dense square (the first) is red, the sparse one blue; the charts differ in colour.
  EXPECT_GT(mesh.density_rgb[0], 0.9f);
  EXPECT_GT(mesh.density_rgb[9 * 2 + 2], 0.9f);
  EXPECT_NE(mesh.chart_rgb[0], mesh.chart_rgb[9 * 2]);
  EXPECT_EQ(mesh.texture_rgba.type(), CV_8UC4);
  EXPECT_EQ(mesh.texture_rgba.at<cv::Vec4b>(0, 0), cv::Vec4b(30, 20, 10, 255));  // RGBA
  ASSERT_EQ(mesh.texture_mips.size(), 6u);  // 32, 16, 8, 4, 2, 1
  EXPECT_EQ(mesh.texture_mips.back().size(), cv::Size(1, 1));
  EXPECT_NEAR(mesh.radius, std::sqrt(0.0015 * 0.0015 + 0.0005 * 0.0005), 1e-6);
  texture::TexturedModel broken = TwoSquares();
  broken.triangles.push_back({0, 1, 99});
  EXPECT_THROW(PrepareModelMesh(broken), InvalidArgument);
}

TEST(OrbitCameraTest, FramesOrbitsPansAndZooms) {
  OrbitCamera camera;
  camera.Frame({0.1f, 0.2f, 0.3f}, 0.5f);
  // The target sits on the optical axis at the camera's distance.
  Eigen::Vector4f target(0.1f, 0.2f, 0.3f, 1.0f);
  Eigen::Vector4f in_view = camera.ViewMatrix() * target;
  EXPECT_NEAR(in_view.x(), 0.0f, 1e-5f);
  EXPECT_NEAR(in_view.y(), 0.0f, 1e-5f);
  EXPECT_NEAR(in_view.z(), -camera.distance, 1e-5f);
  // The framed sphere fits the view: its top edge projects inside [-1, 1].
  const Eigen::Matrix4f p = camera.ProjectionMatrix(1.0f, 0.01f, 10.0f);
  const Eigen::Vector4f clip = p * Eigen::Vector4f(0.0f, 0.5f, -camera.distance, 1.0f);
  EXPECT_GT(clip.y() / clip.w(), 0.7f);
  EXPECT_LT(clip.y() / clip.w(), 0.9f);
  // World up stays up on screen.
  const Eigen::Vector4f above = camera.ViewMatrix() * Eigen::Vector4f(0.1f, 0.2f, 0.4f, 1.0f);
  EXPECT_GT(above.y(), 0.0f);
  camera.Orbit(0.0f, 1000.0f);
  EXPECT_LE(camera.pitch_deg, 89.0f);
  const float before = camera.distance;
  camera.Zoom(2.0f);
  EXPECT_NEAR(camera.distance, before * 0.81f, 1e-4f);
  const Eigen::Vector3f old_target = camera.target;
  camera.Pan(100.0f, 0.0f, 500.0f);
  EXPECT_GT((camera.target - old_target).norm(), 0.0f);
  // A pan moves the target along the view plane: its depth stays.
  EXPECT_NEAR((camera.ViewMatrix() *
               Eigen::Vector4f(camera.target.x(), camera.target.y(), camera.target.z(), 1.0f))
                  .z(),
              -camera.distance, 1e-4f);
}

}  // namespace
}  // namespace carousel::gui
