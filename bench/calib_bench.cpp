// The rig calibration on the simulated rig at full size, timed and scored against the ground
// truth (issue 10's targets: focal length within 0.2 %, principal point within 1 px, camera
// centre within 1 mm at about 1 m, axis direction within 0.05 degrees, reprojection RMS under
// 0.3 px). A ChArUco board stands on the turntable leaning back 30 and then 60 degrees; two
// cameras 15 and 40 degrees above the plate photograph it at every stop (noise, JPEG 95).
// With --pipeline, a one-button product session textured with the estimated calibration is
// compared (held-out PSNR) with the same session on the simulator's exact cameras, at the
// same size: issue 10 asks for at most 0.5 dB between them.
//
//   calib_bench [--width W] [--height H] [--stops N] [--distance M] [--pipeline]
//               [--work DIR]
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <numbers>
#include <optional>
#include <string>
#include <vector>

#include <opencv2/imgcodecs.hpp>

#include "bench_flags.h"
#include "carousel/calib/rig_calibration.h"
#include "carousel/core/parallel.h"
#include "carousel/core/progress.h"
#include "carousel/core/timer.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/studio/run_session.h"

using namespace carousel;  // NOLINT(google-build-using-namespace)

namespace {

double AngleDeg(const Eigen::Vector3d& a, const Eigen::Vector3d& b) {
  return std::acos(std::clamp(a.normalized().dot(b.normalized()), -1.0, 1.0)) * 180.0 /
         std::numbers::pi;
}

void Accuracy(int width, int height, int stops, double distance) {
  const calib::BoardSpec board = calib::BoardSpec::Parse("charuco:9x7:0.04:0.03:DICT_6X6_250");
  const calib::BoardImage drawn = calib::DrawBoard(board, 150, 75);
  std::vector<Rigid3d> placements;
  std::vector<sim::Scene> scenes;
  for (const double lean : {30.0, 60.0}) {
    placements.push_back(
        sim::StandCardOnTable(drawn.board_from_pixel, drawn.image.size(), lean, 0.0));
    scenes.push_back(
        sim::MakePrintedCardScene(drawn.image, drawn.board_from_pixel, placements.back()));
  }
  sim::SimRigOptions rig;
  rig.elevations_deg = {15.0, 40.0};
  rig.width = width;
  rig.height = height;
  rig.distance_m = distance;
  const std::vector<CameraModel> truth = sim::MakeSimRig(rig, scenes.front().Bounds());

  Stopwatch watch;
  std::vector<calib::RigPhoto> photos(2 * static_cast<std::size_t>(stops) * truth.size());
  // One photo at a time (the renderer itself uses every thread).
  for (std::size_t i = 0; i < photos.size(); ++i) {
    const int b = static_cast<int>(i / (stops * truth.size()));
    const int s = static_cast<int>(i / truth.size()) % stops;
    const int c = static_cast<int>(i % truth.size());
    const double angle = 2.0 * std::numbers::pi * s / stops;
    sim::RenderOptions options;
    options.noise_sigma = 1.5;
    options.seed = i;
    const cv::Mat image =
        sim::Render(scenes[b], sim::CameraAtTableAngle(truth[c], angle), angle, options).image;
    std::vector<std::uint8_t> jpeg;
    cv::imencode(".jpg", image, jpeg, {cv::IMWRITE_JPEG_QUALITY, 95});
    calib::RigPhoto& photo = photos[i];
    photo.camera = c;
    photo.stop = b * stops + s;
    photo.placement = b;
    photo.name = "cam" + std::to_string(c) + "_stop" + std::to_string(photo.stop);
    photo.table_angle_rad = angle;
    photo.image = cv::imdecode(jpeg, cv::IMREAD_GRAYSCALE);
  }
  const double seconds_render = watch.ElapsedSeconds();
  watch.Restart();
  calib::RigCalibrationOptions options;
  options.board_origin_height_m = (placements[0] * Eigen::Vector3d::Zero()).z();
  Progress progress;
  const calib::RigCalibrationResult result =
      calib::CalibrateRig(photos, board, {}, options, progress);
  const double seconds_calibrate = watch.ElapsedSeconds();
  const calib::RigCalibration& c = result.calibration;
  int used = 0;
  for (const calib::RigPhotoReport& p : result.photos) used += p.used;
  std::printf(
      "rig calibration at %dx%d, %zu cameras, 2 placements x %d stops: %d of %zu photos "
      "used, %d corners, RMS %.3f px (goal < 0.3)\n",
      width, height, truth.size(), stops, used, photos.size(), c.corners, c.rms_px);
  for (std::size_t i = 0; i < truth.size(); ++i) {
    const CameraModel& t = truth[i];
    const CameraModel& e = c.cameras[i].camera;
    std::printf(
        "  camera %zu (%.0f deg, %.3f m): fx %+.3f %% fy %+.3f %% (goal 0.2), cx %+.2f px "
        "cy %+.2f px (goal 1), centre %.3f mm (goal 1), axis %.4f deg (goal 0.05), "
        "RMS %.3f px\n",
        i, rig.elevations_deg[i], t.Centre().norm(), 100.0 * (e.fx / t.fx - 1.0),
        100.0 * (e.fy / t.fy - 1.0), e.cx - t.cx, e.cy - t.cy,
        (e.Centre() - t.Centre()).norm() * 1e3,
        AngleDeg(c.cameras[i].axis_direction_cam, t.cam_from_world.rotation.col(2)),
        c.cameras[i].rms_px);
  }
  std::printf("  table angles: observed/reported %.5f, largest deviation %.4f deg\n", c.angle_scale,
              c.angle_residual_max_deg);
  std::printf("  time: rendering %.1f s, calibration %.2f s (detection and adjustment)\n",
              seconds_render, seconds_calibrate);
}

void Pipeline(int width, int height, const std::filesystem::path& work) {
  std::filesystem::remove_all(work);
  std::filesystem::create_directories(work);
  Progress progress;
  studio::RunOptions base;
  base.out = work;
  base.sim.rig.width = width;
  base.sim.rig.height = height;
  base.sim.data_dir = CAROUSEL_DEFAULT_SHARED_DATA_DIR;
  Stopwatch watch;
  studio::RunOptions calibration = base;
  calibration.product = "calibration";
  calibration.sim.stops = 24;
  calibration.calibration = studio::CalibrationPlan{};
  const studio::RunResult calibrated = studio::RunSession(calibration, progress);
  const calib::RigCalibration& c = calibrated.calibration->result.calibration;
  std::printf(
      "calibration session (shoe framing, 1 camera, 2 placements x 24 stops): RMS %.3f "
      "px, %.1f s\n",
      c.rms_px, watch.ElapsedSeconds());
  double psnr[2] = {0, 0};
  for (int k = 0; k < 2; ++k) {
    studio::RunOptions product = base;
    product.product = k == 0 ? "truth" : "estimated";
    product.texture.grouping.exclude_views = {3, 11};
    if (k == 1) product.calibration_file = calibrated.calibration->file;
    watch.Restart();
    const studio::RunResult r = studio::RunSession(product, progress);
    psnr[k] = r.texture.mean_psnr_db;
    std::printf("product session with %s cameras: held-out PSNR %.2f dB, SSIM %.4f (%.1f s)\n",
                k == 0 ? "the exact" : "the calibrated", r.texture.mean_psnr_db,
                r.texture.mean_ssim, watch.ElapsedSeconds());
  }
  std::printf("PSNR difference: %.2f dB (goal <= 0.5)\n", psnr[1] - psnr[0]);
}

}  // namespace

int main(int argc, char** argv) {
  int width = 5184, height = 3456, stops = 24;
  double distance = 1.0;
  bool pipeline = false;
  std::filesystem::path work = std::filesystem::temp_directory_path() / "carousel_calib_bench";
  BenchFlags flags(
      argc, argv,
      "calib_bench: the rig calibration on the simulated rig, scored against the truth");
  flags.Option("--width", &width)
      .Option("--height", &height)
      .Option("--stops", &stops, "stops per board placement")
      .Option("--distance", &distance, "camera distance, metres")
      .Flag("--pipeline", &pipeline,
            "also texture a product session with the estimated calibration and compare")
      .Option("--work", &work, "folder for the pipeline's sessions");
  if (const std::optional<int> exit_code = flags.Parse(std::cout, std::cerr)) return *exit_code;
  try {
    Accuracy(width, height, stops, distance);
    if (pipeline) Pipeline(width, height, work);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "calib_bench: %s\n", e.what());
    return 1;
  }
  return 0;
}
