#include "carousel/sim/sim_rig.h"

#include <cmath>
#include <numbers>
#include <thread>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel::sim {
namespace {

using namespace std::chrono_literals;
constexpr double kDeg = std::numbers::pi / 180.0;

TEST(SimRigTest, DefaultStudioLooksAtTheObjectFromItsElevation) {
  const Scene sphere = MakeSphereScene(0.1, {0, 0, 0.1}, 3);
  SimRigOptions options;
  options.elevations_deg = {10, 30, 60};
  const std::vector<CameraModel> rig = MakeSimRig(options, sphere.Bounds());
  ASSERT_EQ(rig.size(), 3u);
  for (std::size_t i = 0; i < rig.size(); ++i) {
    const CameraModel& camera = rig[i];
    EXPECT_EQ(camera.width, 5184);
    EXPECT_NEAR(camera.fx, 50.0 / 22.3 * 5184, 1e-9);
    // Aimed at the object's centre, from the requested elevation.
    EXPECT_THAT(*camera.Project(Eigen::Vector3d(0, 0, 0.1)),
                testing::EigenNear(Eigen::Vector2d(camera.cx, camera.cy), 1e-6));
    const Eigen::Vector3d from_target = camera.Centre() - Eigen::Vector3d(0, 0, 0.1);
    EXPECT_NEAR(std::asin(from_target.normalized().z()) / kDeg, options.elevations_deg[i], 1e-9);
  }
  EXPECT_THROW(MakeSimRig({.elevations_deg = {}}, sphere.Bounds()), InvalidArgument);
  EXPECT_THROW(MakeSimRig({.elevations_deg = {95}}, sphere.Bounds()), InvalidArgument);
}

TEST(SimRigTest, TableAngleTurnsTheObjectCounterClockwise) {
  const Scene sphere = MakeSphereScene(0.1, {0, 0, 0.1}, 3);
  const CameraModel at_zero = MakeSimRig({}, sphere.Bounds()).front();
  // A point on the +X side of the object, turned by +90 deg, lies on +Y in the studio:
  // it appears where the studio point (0, r, z) appears at angle 0.
  const Eigen::Vector3d point(0.05, 0.0, 0.1);
  const CameraModel turned = CameraAtTableAngle(at_zero, 90 * kDeg);
  EXPECT_THAT(*turned.Project(point),
              testing::EigenNear(*at_zero.Project(Eigen::Vector3d(0.0, 0.05, 0.1)), 1e-9));
}

TEST(SimTurntableTest, MovesTakeTheTrapezoidalProfileTime) {
  SimTurntable table({.max_speed_deg_s = 90, .acceleration_deg_s2 = 180, .time_scale = 0.0});
  // 90 deg at 90 deg/s with 180 deg/s^2: 0.5 s ramps (45 deg) leave 45 deg at full speed.
  EXPECT_NEAR(table.MoveSeconds(90 * kDeg), 1.5, 1e-12);
  // 10 deg never reaches full speed: 2 * sqrt(10 / 180).
  EXPECT_NEAR(table.MoveSeconds(10 * kDeg), 2 * std::sqrt(10.0 / 180.0), 1e-12);
  table.MoveTo(45 * kDeg, 1s);
  EXPECT_NEAR(table.Status().angle_rad, 45 * kDeg, 1e-15);
  EXPECT_FALSE(table.Status().moving);
  EXPECT_FALSE(table.Status().homed);
  table.Home(1s);
  EXPECT_TRUE(table.Status().homed);
  EXPECT_EQ(table.Status().angle_rad, 0.0);
}

TEST(SimTurntableTest, RealTimeMoveIsObservableAndStops) {
  // Slow enough (1.1 s of wall time) that a test thread starved by a loaded machine still finds
  // the move under way.
  SimTurntable table({.max_speed_deg_s = 90, .acceleration_deg_s2 = 360, .time_scale = 0.5});
  table.StartMoveTo(180 * kDeg);  // 2.25 s simulated, 1.1 s of wall time
  std::this_thread::sleep_for(100ms);
  const rig::TurntableStatus moving = table.Status();
  EXPECT_TRUE(moving.moving);
  EXPECT_GT(moving.angle_rad, 0.0);
  EXPECT_LT(moving.angle_rad, 180 * kDeg);
  EXPECT_THROW(table.WaitUntilStopped(10ms), DeviceError);
  table.Stop(/*emergency=*/true);
  const double stopped_at = table.Status().angle_rad;
  EXPECT_FALSE(table.Status().moving);
  std::this_thread::sleep_for(50ms);
  EXPECT_EQ(table.Status().angle_rad, stopped_at);
}

TEST(SimTurntableTest, StopDeceleratesFromTheCurrentSpeed) {
  SimTurntable table({.max_speed_deg_s = 90, .acceleration_deg_s2 = 360, .time_scale = 0.5});
  table.StartMoveTo(360 * kDeg);       // 4.25 s simulated; full speed after 0.25 s
  std::this_thread::sleep_for(500ms);  // ~1 s simulated: cruising
  const double before = table.Status().angle_rad;
  table.Stop(/*emergency=*/false);
  table.WaitUntilStopped(2s);
  const rig::TurntableStatus after = table.Status();
  EXPECT_FALSE(after.moving);
  // Braking distance v^2 / 2a = 90^2 / 720 = 11.25 deg (give or take the time between calls).
  EXPECT_NEAR((after.angle_rad - before) / kDeg, 11.25, 3.0);
  EXPECT_LT(after.angle_rad, 360 * kDeg);
}

TEST(SimCameraTest, CapturesAndDownloadsAPhotoOfTheTurnedScene) {
  auto scene = std::make_shared<Scene>(MakeSphereScene(0.08, {0, 0, 0.08}, 3));
  auto table = std::make_shared<SimTurntable>(SimTurntableOptions{.time_scale = 0.0});
  SimRigOptions rig;
  rig.width = 320;
  rig.height = 240;
  SimCamera camera(scene, MakeSimRig(rig, scene->Bounds()).front(), table,
                   {.serial = "SIM42", .jpeg_quality = 90});
  EXPECT_EQ(camera.Identify().serial, "SIM42");
  testing::TempDir dir;
  const rig::CapturedPhoto photo = camera.Capture(5s);
  EXPECT_GT(photo.size_bytes, 1000u);
  camera.Download(photo, dir / "a.jpg", false, 5s);
  const cv::Mat image = ReadImage(dir / "a.jpg");
  EXPECT_EQ(image.cols, 320);
  EXPECT_EQ(image.rows, 240);
  // Never overwrites a file; the photo is still on the card and can be fetched elsewhere.
  EXPECT_THROW(camera.Download(photo, dir / "a.jpg", true, 5s), IoError);
  camera.Download(photo, dir / "b.jpg", true, 5s);
  EXPECT_THROW(camera.Download(photo, dir / "c.jpg", false, 5s), DeviceError);  // deleted
  EXPECT_EQ(camera.PreviewFrame(1s).cols, 640);
}

TEST(SimCameraTest, ExposureSettingsBrightenThePhoto) {
  auto scene = std::make_shared<Scene>(MakeSphereScene(0.08, {0, 0, 0.08}, 3, {0.3f, 0.3f, 0.3f}));
  auto table = std::make_shared<SimTurntable>(SimTurntableOptions{.time_scale = 0.0});
  SimRigOptions rig;
  rig.width = 160;
  rig.height = 120;
  SimCamera camera(scene, MakeSimRig(rig, scene->Bounds()).front(), table);
  testing::TempDir dir;
  camera.Download(camera.Capture(5s), dir / "iso100.jpg", true, 5s);
  camera.SetSetting(rig::kSettingIso, "200", 1s);
  EXPECT_DOUBLE_EQ(camera.ExposureGain(), 2.0);
  camera.Download(camera.Capture(5s), dir / "iso200.jpg", true, 5s);
  const cv::Point centre(80, 60);
  const double dark = cv::mean(ReadImage(dir / "iso100.jpg")(cv::Rect(centre, cv::Size(8, 8))))[1];
  const double bright =
      cv::mean(ReadImage(dir / "iso200.jpg")(cv::Rect(centre, cv::Size(8, 8))))[1];
  EXPECT_GT(bright, dark * 1.2);
  CAROUSEL_EXPECT_THROW_WITH(camera.SetSetting(rig::kSettingIso, "fast", 1s), InvalidArgument,
                             "not a valid value for iso");
  EXPECT_THROW(camera.SetSetting("zoom", "2", 1s), InvalidArgument);
  EXPECT_EQ(camera.Settings(1s).at(rig::kSettingIso), "200");
}

}  // namespace
}  // namespace carousel::sim
