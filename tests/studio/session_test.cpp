#include "carousel/studio/session.h"

#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

using testing::TempDir;

SimCaptureOptions SmallCapture() {
  SimCaptureOptions options;
  options.scene = "duck";
  options.data_dir = testing::SharedDataDir();
  options.stops = 4;
  options.rig.width = 240;
  options.rig.height = 160;
  options.rig.elevations_deg = {15, 40};
  options.placement.target_height_m = 0.12;
  return options;
}

bool SameCamera(const CameraModel& a, const CameraModel& b) {
  return a.width == b.width && a.height == b.height && a.fx == b.fx && a.fy == b.fy &&
         a.cx == b.cx && a.cy == b.cy && a.distortion.k1 == b.distortion.k1 &&
         a.distortion.k2 == b.distortion.k2 && a.distortion.p1 == b.distortion.p1 &&
         a.distortion.p2 == b.distortion.p2 && a.distortion.k3 == b.distortion.k3 &&
         a.cam_from_world.rotation == b.cam_from_world.rotation &&
         a.cam_from_world.translation == b.cam_from_world.translation;
}

TEST(SimCaptureTest, SessionRoundTripsThroughTheLoaderExactly) {
  TempDir dir;
  Progress progress;
  const SimCaptureOptions options = SmallCapture();
  const SimCaptureResult result = SimulateCapture(options, dir / "duck", progress);
  EXPECT_EQ(result.views, 8);
  const Session session = ReadSession(dir / "duck");
  ASSERT_EQ(session.views.size(), 8u);
  EXPECT_EQ(session.frame, "turntable");
  EXPECT_EQ(session.product, "duck");
  EXPECT_EQ(session.stages.at("capture"), "done");

  // The exact cameras: rebuild the rig the way the capture did and compare every number.
  sim::Scene scene = sim::LoadScene(testing::SharedDataFile("models/Duck/glTF/Duck.gltf"));
  sim::PlaceOnTurntable(scene, options.placement);
  const std::vector<CameraModel> rig = sim::MakeSimRig(options.rig, scene.Bounds());
  for (const SessionView& view : session.views) {
    const double angle_deg = 360.0 * view.stop / options.stops;
    EXPECT_EQ(view.table_angle_deg, angle_deg);
    const CameraModel expected =
        sim::CameraAtTableAngle(rig.at(view.camera), angle_deg * std::numbers::pi / 180.0);
    EXPECT_TRUE(SameCamera(view.camera_model, expected)) << view.image;
  }
  // Views load as core Views with their photos; the ground truth sits apart.
  const std::vector<View> views = SessionViews(dir / "duck", session);
  ASSERT_EQ(views.size(), 8u);
  EXPECT_EQ(views[3].Image().cols, 240);
  EXPECT_FALSE(views[3].HasMask()) << "the pipeline makes its own masks";
  ASSERT_EQ(session.ground_truth.masks.size(), 8u);
  const cv::Mat truth = ReadMask(dir / "duck" / session.ground_truth.masks[3]);
  EXPECT_GT(cv::countNonZero(truth), 1000);
  const cv::Mat depth =
      ReadImage(dir / "duck" / session.ground_truth.depth[3], ImageReadMode::kUnchanged);
  EXPECT_EQ(depth.type(), CV_16UC1);
  EXPECT_EQ(cv::countNonZero(depth), cv::countNonZero(truth));
  EXPECT_EQ(ReadMesh(dir / "duck" / session.ground_truth.mesh).n_faces(), 4212u);
}

TEST(SimCaptureTest, NeverReplacesASessionWithoutForceAndLeavesNothingOnFailure) {
  TempDir dir;
  Progress progress;
  SimCaptureOptions options = SmallCapture();
  options.stops = 1;
  SimulateCapture(options, dir / "s", progress);
  const std::string manifest = testing::ReadBytes(dir / "s" / kManifestName);
  CAROUSEL_EXPECT_THROW_WITH(SimulateCapture(options, dir / "s", progress), IoError, "--force");
  EXPECT_EQ(testing::ReadBytes(dir / "s" / kManifestName), manifest);
  // A scene that cannot be loaded: no folder, no staging leftovers.
  options.scene = (dir / "missing.gltf").string();
  EXPECT_THROW(SimulateCapture(options, dir / "t", progress), IoError);
  EXPECT_FALSE(std::filesystem::exists(dir / "t"));
  // Cancelled half-way: nothing left either.
  CancellationToken token;
  int reports = 0;
  Progress cancelling(
      [&](const ProgressUpdate& update) {
        if (update.stage == "render views" && update.fraction > 0 && ++reports == 1) token.Cancel();
      },
      token);
  options = SmallCapture();
  EXPECT_THROW(SimulateCapture(options, dir / "u", cancelling), Cancelled);
  EXPECT_FALSE(std::filesystem::exists(dir / "u"));
  std::size_t entries = 0;
  for ([[maybe_unused]] const auto& entry : std::filesystem::directory_iterator(dir.path()))
    ++entries;
  EXPECT_EQ(entries, 1u) << "only the first session may exist";
  // --force replaces it with the new one.
  options.stops = 2;
  options.overwrite = true;
  SimulateCapture(options, dir / "s", progress);
  EXPECT_EQ(ReadSession(dir / "s").views.size(), 4u);
}

TEST(SimCaptureTest, ForceNeverReplacesAFolderThatIsNotASession) {
  TempDir dir;
  std::filesystem::create_directories(dir / "photos");
  testing::WriteBytes(dir / "photos/precious.jpg", "not a session");
  SimCaptureOptions options = SmallCapture();
  options.stops = 1;
  options.overwrite = true;
  Progress progress;
  CAROUSEL_EXPECT_THROW_WITH(SimulateCapture(options, dir / "photos", progress), IoError,
                             "not a Carousel session folder");
  EXPECT_EQ(testing::ReadBytes(dir / "photos/precious.jpg"), "not a session");
}

TEST(SessionTest, ReaderNamesTheProblem) {
  TempDir dir;
  const auto write = [&](const std::string& text) {
    testing::WriteBytes(dir / kManifestName, text);
  };
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), IoError, "no such file");
  write("{ not json");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError, "not valid JSON");
  write(R"({"format": "something-else"})");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError, "not a Carousel session");
  write(R"({"format": "carousel-session", "version": 99, "product": "x", "frame": "turntable",
            "views": []})");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError, "version 99");
  write(R"({"format": "carousel-session", "version": 1, "product": "x", "frame": "turntable",
            "views": [{"image": "/etc/passwd", "camera": 0, "stop": 0, "table_angle_deg": 0}]})");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError, "absolute path");
  write(R"({"format": "carousel-session", "version": 1, "product": "x", "frame": "turntable",
            "views": [{"image": "../x.jpg", "camera": 0, "stop": 0, "table_angle_deg": 0}]})");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError, "leaves the session folder");
  write(R"({"format": "carousel-session", "version": 1, "product": "x", "frame": "turntable",
            "views": [{"image": "images/a.jpg", "camera": 0, "stop": 0,
                       "table_angle_deg": "ten"}]})");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError,
                             "views[0].table_angle_deg is not a number");
}

// A number that does not fit (1e999 overflows a double; nlohmann reports it as out_of_range,
// not as a parse error): a FormatError naming session.json and the field, like any other.
TEST(SessionTest, ANumberOutOfRangeNamesTheManifestAndTheField) {
  TempDir dir;
  const std::string manifest = (dir / kManifestName).string();
  const auto write_view = [&](const std::string& fields) {
    testing::WriteBytes(dir / kManifestName,
                        R"({"format": "carousel-session", "version": 1, "product": "x",
                            "frame": "turntable", "views": [{"image": "images/a.jpg", )" +
                            fields + "}]}");
  };
  write_view(R"("camera": 0, "stop": 0, "table_angle_deg": 1e999)");
  EXPECT_THAT(
      [&] { ReadSession(dir.path()); },
      ::testing::ThrowsMessage<FormatError>(::testing::AllOf(
          ::testing::HasSubstr(manifest), ::testing::HasSubstr("views[0].table_angle_deg"))));
  // An integer too large for the field's int.
  write_view(R"("camera": 3000000000, "stop": 0, "table_angle_deg": 0)");
  CAROUSEL_EXPECT_THROW_WITH(ReadSession(dir.path()), FormatError,
                             "views[0].camera is out of range");
}

}  // namespace
}  // namespace carousel::studio
