// The rig calibration against the simulated rig's ground truth: a ChArUco board standing on the
// simulated turntable, photographed by the simulated cameras (lens distortion, sensor noise,
// JPEG) at every stop; and the failures a bad calibration set must give.
#include "carousel/calib/rig_calibration.h"

#include <cmath>
#include <numbers>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel::calib {
namespace {

using ::testing::HasSubstr;
constexpr double kDeg = std::numbers::pi / 180.0;

struct SimulatedRig {
  BoardSpec board = BoardSpec::Parse("charuco:9x7:0.04:0.03:DICT_6X6_250");
  std::vector<CameraModel> cameras;  // cam_from_table at angle 0
  // The board's placements: leaning back 30 degrees, then 60.
  std::vector<Rigid3d> table_from_board;
  std::vector<sim::Scene> scenes;
};

// Two cameras 15 and 40 degrees above the plate, 1.1 m from the board, which stands on the
// table leaning back 30 degrees, and is then leant back to 60.
SimulatedRig MakeRig(int width, int height) {
  SimulatedRig rig;
  const BoardImage drawn = DrawBoard(rig.board, 100, 50);
  for (const double lean : {30.0, 60.0}) {
    // The board frame is the drawing's plane frame.
    rig.table_from_board.push_back(
        sim::StandCardOnTable(drawn.board_from_pixel, drawn.image.size(), lean, 0.0));
    rig.scenes.push_back(sim::MakePrintedCardScene(drawn.image, drawn.board_from_pixel,
                                                   rig.table_from_board.back()));
  }
  sim::SimRigOptions options;
  options.elevations_deg = {15.0, 40.0};
  options.width = width;
  options.height = height;
  options.distance_m = 1.1;
  rig.cameras = sim::MakeSimRig(options, rig.scenes.front().Bounds());
  return rig;
}

// Every camera at every stop of each placement; stops are numbered across placements.
std::vector<RigPhoto> Photograph(const SimulatedRig& rig, int stops, std::uint64_t seed,
                                 int placements = 2) {
  std::vector<RigPhoto> photos;
  for (int b = 0; b < placements; ++b) {
    for (int s = 0; s < stops; ++s) {
      const double angle = 2.0 * std::numbers::pi * s / stops;
      for (std::size_t c = 0; c < rig.cameras.size(); ++c) {
        sim::RenderOptions options;
        options.noise_sigma = 1.5;
        options.seed = seed * 100000 + b * 1000 + s * 10 + c;
        const CameraModel camera = sim::CameraAtTableAngle(rig.cameras[c], angle);
        const cv::Mat image = sim::Render(rig.scenes[b], camera, angle, options).image;
        std::vector<std::uint8_t> jpeg;
        cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95});
        RigPhoto photo;
        photo.camera = static_cast<int>(c);
        photo.stop = b * stops + s;
        photo.name = "cam" + std::to_string(c) + "_stop" + std::to_string(photo.stop);
        photo.placement = b;
        photo.table_angle_rad = angle;
        photo.image = cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE);
        photos.push_back(photo);
      }
    }
  }
  return photos;
}

double AngleBetweenDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) / kDeg;
}

TEST(RigCalibrationTest, RecoversTheSimulatedRigsCamerasAxisAndBoard) {
  const SimulatedRig rig = MakeRig(1296, 864);
  const std::vector<RigPhoto> photos = Photograph(rig, 24, 1);
  RigCalibrationOptions options;
  options.board_origin_height_m = (rig.table_from_board[0] * Eigen::Vector3d::Zero()).z();
  Progress progress;
  const RigCalibrationResult result = CalibrateRig(photos, rig.board, {}, options, progress);
  const RigCalibration& calibration = result.calibration;
  ASSERT_EQ(calibration.cameras.size(), 2U);
  int used = 0;
  for (const RigPhotoReport& p : result.photos) used += p.used;
  EXPECT_GE(used, 40);  // the board turned away in the others
  EXPECT_LT(calibration.rms_px, 0.3);
  // The gauge (the board's x along +X) matches the simulator's: the board's x is its image's x.
  ASSERT_EQ(result.table_from_board.size(), 2U);
  for (std::size_t b = 0; b < 2; ++b) {
    EXPECT_LT((result.table_from_board[b].translation - rig.table_from_board[b].translation).norm(),
              2e-3)
        << b;
  }
  for (std::size_t c = 0; c < 2; ++c) {
    const CameraModel& truth = rig.cameras[c];
    const CameraModel& got = calibration.cameras[c].camera;
    const double centre_mm = (got.Centre() - truth.Centre()).norm() * 1e3;
    const double axis_deg = AngleBetweenDeg(calibration.cameras[c].axis_direction_cam,
                                            truth.cam_from_world.rotation.col(2));
    std::printf(
        "camera %zu (%d views): fx %.2f (%.2f, %+.3f %%) fy %.2f (%.2f) cx %.2f (%.2f) "
        "cy %.2f (%.2f) k1 %.4f (%.4f); centre off %.2f mm at %.3f m; axis off %.4f deg; "
        "RMS %.3f px\n",
        c, calibration.cameras[c].views, got.fx, truth.fx, 100.0 * (got.fx / truth.fx - 1), got.fy,
        truth.fy, got.cx, truth.cx, got.cy, truth.cy, got.distortion.k1, truth.distortion.k1,
        centre_mm, truth.Centre().norm(), axis_deg, calibration.cameras[c].rms_px);
    // Bounds looser than the targets (those hold at full size, see the benchmark).
    EXPECT_NEAR(got.fx / truth.fx, 1.0, 0.005) << c;
    EXPECT_NEAR(got.fy / truth.fy, 1.0, 0.005) << c;
    EXPECT_NEAR(got.cx, truth.cx, 2.0) << c;
    EXPECT_NEAR(got.cy, truth.cy, 2.0) << c;
    EXPECT_LT(centre_mm, 3.0) << c;
    EXPECT_LT(axis_deg, 0.15) << c;
    // The photos' poses follow from the table angle alone.
    const CameraModel at_100 = calibration.CameraAt(static_cast<int>(c), 100.0 * kDeg);
    const CameraModel truth_100 = sim::CameraAtTableAngle(truth, 100.0 * kDeg);
    EXPECT_LT((at_100.Centre() - truth_100.Centre()).norm(), 3e-3) << c;
  }
  // The simulated table turns exactly as it reports.
  EXPECT_NEAR(calibration.angle_scale, 1.0, 1e-3);
  for (const StopAngle& a : calibration.angles) EXPECT_NEAR(a.observed_deg, a.reported_deg, 0.1);

  // Written and read back.
  testing::TempDir dir;
  RigCalibration dated = calibration;
  dated.created_utc = "2026-12-01T00:00:00Z";
  WriteRigCalibration(dir / "rig.json", dated);
  const RigCalibration back = ReadRigCalibration(dir / "rig.json");
  EXPECT_EQ(back.cameras.size(), 2U);
  EXPECT_DOUBLE_EQ(back.cameras[1].camera.fx, calibration.cameras[1].camera.fx);
  EXPECT_EQ(back.cameras[1].camera.cam_from_world.translation,
            calibration.cameras[1].camera.cam_from_world.translation);
  EXPECT_EQ(back.angles.size(), calibration.angles.size());
  EXPECT_EQ(back.board, rig.board.ToString());
}

// The table's reported angles are checked against the board's rotation: a stop that lost
// steps and a wrong gear ratio are failures naming the stops, never a silently bad result.
TEST(RigCalibrationTest, AnglesThatDisagreeWithTheBoardAreAClearFailure) {
  const SimulatedRig rig = MakeRig(960, 640);
  const std::vector<RigPhoto> photos = Photograph(rig, 16, 2, 1);
  RigCalibrationOptions options;
  options.board_origin_height_m = (rig.table_from_board[0] * Eigen::Vector3d::Zero()).z();
  Progress progress;
  // Lost steps at stop 2: the table believes it is 3 degrees further than it is.
  std::vector<RigPhoto> lost = photos;
  for (RigPhoto& p : lost) {
    if (p.stop >= 2) p.table_angle_rad += 3.0 * kDeg;
  }
  EXPECT_THAT([&] { CalibrateRig(lost, rig.board, {}, options, progress); },
              ::testing::ThrowsMessage<InvalidArgument>(
                  ::testing::AllOf(HasSubstr("disagree with the board's rotation"),
                                   HasSubstr("stop 0: the table said 0.00 deg"))));
  // A gear ratio 2 % off: the observed rotation is 1/1.02 of the reported one.
  std::vector<RigPhoto> geared = photos;
  for (RigPhoto& p : geared) p.table_angle_rad *= 1.02;
  try {
    CalibrateRig(geared, rig.board, {}, options, progress);
    FAIL() << "calibrated with a wrong gear ratio";
  } catch (const InvalidArgument& e) {
    EXPECT_THAT(e.what(), HasSubstr("wrong gear ratio"));
    EXPECT_THAT(e.what(), HasSubstr("observed/reported 0.98"));
  }
  // Tolerated when the disagreement is within the bound; the scale is reported.
  options.max_angle_error_deg = 10.0;
  const RigCalibrationResult tolerated = CalibrateRig(geared, rig.board, {}, options, progress);
  EXPECT_NEAR(tolerated.calibration.angle_scale, 1.0 / 1.02, 2e-3);
}

TEST(RigCalibrationTest, CamerasWithoutTheBoardAndBadPhotosAreNamedWithTheirReasons) {
  const SimulatedRig rig = MakeRig(960, 640);
  std::vector<RigPhoto> photos = Photograph(rig, 16, 3, 1);
  RigCalibrationOptions options;
  Progress progress;
  // A third camera that only ever photographed the empty room.
  for (int s = 0; s < 16; ++s) {
    RigPhoto blank;
    blank.name = "cam2_stop" + std::to_string(s);
    blank.camera = 2;
    blank.stop = s;
    blank.table_angle_rad = 2.0 * std::numbers::pi * s / 16;
    blank.image = cv::Mat(640, 960, CV_8UC1, cv::Scalar(200));
    photos.push_back(blank);
  }
  // A photo that is not there, and one with the board mostly out of the picture.
  photos[0].image = cv::Mat();
  photos[0].path = "/nonexistent/cam0_stop0.jpg";
  photos[2].image = photos[2].image.clone();
  photos[2].image.colRange(0, photos[2].image.cols * 4 / 5).setTo(cv::Scalar(200));
  try {
    CalibrateRig(photos, rig.board, {}, options, progress);
    FAIL() << "calibrated a camera that never saw the board";
  } catch (const InvalidArgument& e) {
    const std::string what = e.what();
    EXPECT_THAT(what, HasSubstr("camera 2 never sees the board"));
    EXPECT_THAT(what, HasSubstr("cam2_stop3: no marker of the ChArUco board found"));
    EXPECT_THAT(what, HasSubstr("cam0_stop0: cannot be read"));
    EXPECT_THAT(
        what, ::testing::AnyOf(HasSubstr("cam0_stop1: only "), HasSubstr("cam0_stop1: no marker")));
  }
  // Without the third camera the others calibrate, with every refused photo explained.
  photos.resize(32);
  const RigCalibrationResult r = CalibrateRig(photos, rig.board, {}, options, progress);
  EXPECT_FALSE(r.photos[0].used);
  EXPECT_THAT(r.photos[0].reason, HasSubstr("cannot be read"));
  EXPECT_FALSE(r.photos[2].used);
  EXPECT_THAT(r.photos[2].reason, ::testing::AnyOf(HasSubstr("only "), HasSubstr("no marker")));
  for (const RigPhotoReport& p : r.photos) {
    EXPECT_TRUE(p.used || !p.reason.empty()) << p.name;
  }
  // Intrinsics from elsewhere, held fixed, must fit the photos' size.
  CameraModel wrong = rig.cameras[0];
  wrong.width = 640;
  EXPECT_THAT([&] { CalibrateRig(photos, rig.board, {wrong}, options, progress); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("intrinsics are for 640x")));
  // A file that is not a calibration.
  testing::TempDir dir;
  testing::WriteBytes(dir / "bad.json",
                      "{\"format\": \"carousel-rig-calibration\", \"version\": 1}");
  EXPECT_THAT([&] { ReadRigCalibration(dir / "bad.json"); },
              ::testing::ThrowsMessage<FormatError>(HasSubstr("created_utc")));
  EXPECT_THROW(ReadRigCalibration(dir / "none.json"), IoError);
}

}  // namespace
}  // namespace carousel::calib
