#include "carousel/studio/self_check.h"

#include <unistd.h>

#include <cmath>
#include <functional>
#include <random>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/mesh_primitives.h"

namespace carousel::studio {
namespace {

using Status = SelfCheckItem::Status;

SelfCheckItem CheckCameraModel(int points) {
  std::mt19937 rng(20261122);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  double max_projection_error = 0.0;
  double max_round_trip_error = 0.0;
  int round_trips = 0;
  for (int camera_index = 0; camera_index < 10; ++camera_index) {
    CameraModel camera;
    camera.width = 1296;
    camera.height = 864;
    camera.fx = 1500.0 + 200.0 * unit(rng);
    camera.fy = camera.fx * (1.0 + 0.01 * unit(rng));
    camera.cx = 648.0 + 20.0 * unit(rng);
    camera.cy = 432.0 + 20.0 * unit(rng);
    camera.distortion = {0.1 * unit(rng), 0.05 * unit(rng), 0.001 * unit(rng), 0.001 * unit(rng),
                         0.01 * unit(rng)};
    const Eigen::Vector3d eye(unit(rng), unit(rng), 0.5 + 0.3 * unit(rng));
    camera.cam_from_world = Rigid3d::LookAt(eye.normalized(), Eigen::Vector3d(0, 0, 0.1));
    std::vector<cv::Point3d> world;
    std::vector<Eigen::Vector2d> ours;
    for (int i = 0; i < points / 10; ++i) {
      const Eigen::Vector3d p(0.2 * unit(rng), 0.2 * unit(rng), 0.1 + 0.1 * unit(rng));
      const std::optional<Eigen::Vector2d> pixel = camera.Project(p);
      if (!pixel) continue;
      world.emplace_back(p.x(), p.y(), p.z());
      ours.push_back(*pixel);
      if (camera.InImage(*pixel)) {
        const double depth = (camera.cam_from_world * p).z();
        const std::optional<Eigen::Vector3d> back = camera.Unproject(*pixel, depth);
        if (back) {
          max_round_trip_error =
              std::max(max_round_trip_error, (*camera.Project(*back) - *pixel).norm());
          ++round_trips;
        }
      }
    }
    cv::Vec3d rvec, tvec;
    camera.CvPose(&rvec, &tvec);
    std::vector<cv::Point2d> theirs;
    cv::projectPoints(world, rvec, tvec, camera.CvCameraMatrix(), camera.CvDistCoeffs(), theirs);
    for (std::size_t i = 0; i < theirs.size(); ++i) {
      max_projection_error = std::max(
          max_projection_error, std::hypot(ours[i].x() - theirs[i].x, ours[i].y() - theirs[i].y));
    }
  }
  std::ostringstream detail;
  detail << "max |Project - cv::projectPoints| = " << max_projection_error
         << " px; max unproject round trip = " << max_round_trip_error << " px over " << round_trips
         << " pixels";
  const bool ok = max_projection_error < 1e-9 && max_round_trip_error < 1e-6 && round_trips > 0;
  return {"camera model vs OpenCV", ok ? Status::kPassed : Status::kFailed, detail.str()};
}

SelfCheckItem CheckImageFiles(const std::filesystem::path& scratch) {
  cv::Mat image(48, 64, CV_8UC3);
  cv::randu(image, cv::Scalar::all(0), cv::Scalar::all(255));
  const std::filesystem::path png = scratch / "check.png";
  const std::filesystem::path jpg = scratch / "check.jpg";
  WriteImage(png, image);
  WriteImage(jpg, cv::Mat(48, 64, CV_8UC3, cv::Scalar(40, 120, 200)));
  const cv::Mat png_back = ReadImage(png);
  const cv::Mat jpg_back = ReadImage(jpg);
  const double png_diff = cv::norm(png_back, image, cv::NORM_INF);
  const double jpg_diff =
      cv::norm(jpg_back, cv::Mat(48, 64, CV_8UC3, cv::Scalar(40, 120, 200)), cv::NORM_INF);
  // A truncated copy must be refused.
  std::vector<std::uint8_t> bytes = ReadFileBytes(jpg);
  bytes.resize(bytes.size() / 2);
  const std::filesystem::path truncated = scratch / "truncated.jpg";
  WriteFileAtomic(truncated, bytes);
  bool refused = false;
  try {
    ReadImage(truncated);
  } catch (const FormatError&) {
    refused = true;
  }
  std::ostringstream detail;
  detail << "PNG round trip max error " << png_diff << ", JPEG flat colour max error " << jpg_diff
         << ", truncated JPEG " << (refused ? "refused" : "NOT refused");
  const bool ok = png_diff == 0 && jpg_diff <= 4 && refused;
  return {"image files (PNG, JPEG)", ok ? Status::kPassed : Status::kFailed, detail.str()};
}

SelfCheckItem CheckMeshFiles(const std::filesystem::path& scratch) {
  const Mesh sphere = MakeIcosphere(0.1, 3);
  double max_error = 0.0;
  std::ostringstream detail;
  bool ok = true;
  for (const char* extension : {".obj", ".ply", ".off"}) {
    const std::filesystem::path path = scratch / (std::string("sphere") + extension);
    WriteMesh(sphere, path);
    const Mesh back = ReadMesh(path);
    if (back.n_vertices() != sphere.n_vertices() || back.n_faces() != sphere.n_faces()) {
      ok = false;
      detail << extension << ": " << back.n_faces() << " faces read, " << sphere.n_faces()
             << " written; ";
      continue;
    }
    for (Mesh::VertexHandle v : sphere.vertices()) {
      max_error = std::max(max_error, (sphere.point(v) - back.point(v)).norm());
    }
  }
  detail << sphere.n_faces() << "-face sphere through OBJ/PLY/OFF, max vertex error " << max_error
         << " m";
  ok = ok && max_error < 1e-6;
  return {"mesh files (OBJ, PLY, OFF)", ok ? Status::kPassed : Status::kFailed, detail.str()};
}

SelfCheckItem CheckTestData(const std::filesystem::path& data_dir) {
  if (data_dir.empty() || !std::filesystem::is_directory(data_dir)) {
    return {"shared test data", Status::kSkipped,
            data_dir.empty() ? "no data folder given"
                             : "no folder " + data_dir.string() + " (shared/data)"};
  }
  std::ostringstream detail;
  const Mesh duck = ReadMesh(data_dir / "models/Duck/obj_derived/Duck.obj");
  const cv::Mat board = ReadImage(data_dir / "calib/images/left01.jpg");
  detail << "Duck OBJ: " << duck.n_faces() << " faces; calibration photo left01.jpg: " << board.cols
         << "x" << board.rows;
  const bool ok = duck.n_faces() > 4000 && board.cols == 640 && board.rows == 480;
  return {"shared test data", ok ? Status::kPassed : Status::kFailed, detail.str()};
}

}  // namespace

const OptionTable<SelfCheckOptions>& SelfCheckOptions::Fields() {
  using O = SelfCheckOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::data_dir,
          {.name = "data", .help = "shared test data folder (default: $CAROUSEL_SHARED_DATA_DIR)"});
    t.Add(&O::scratch_dir,
          {.name = "scratch", .help = "folder for temporary files (default: the system's)"});
    t.Add(&O::points,
          {.name = "points", .help = "random points in the camera-model check", .min = 1});
    return t;
  }();
  return table;
}

void SelfCheckOptions::Validate() const { Fields().Check(*this); }

bool SelfCheckResult::AllPassed() const {
  for (const SelfCheckItem& item : items) {
    if (item.status == SelfCheckItem::Status::kFailed) return false;
  }
  return true;
}

SelfCheckResult RunSelfCheck(const SelfCheckOptions& options, Progress& progress) {
  options.Validate();
  // A folder of our own inside the scratch location; only it is removed afterwards.
  const std::filesystem::path parent =
      options.scratch_dir.empty() ? std::filesystem::temp_directory_path() : options.scratch_dir;
  const std::filesystem::path scratch =
      parent / ("carousel-self-check-" + std::to_string(::getpid()));
  std::error_code ec;
  std::filesystem::create_directories(scratch, ec);
  if (ec) throw IoError(scratch, "cannot create scratch folder: " + ec.message());

  using Check = std::function<SelfCheckItem()>;
  const std::vector<std::pair<std::string, Check>> checks = {
      {"camera model vs OpenCV", [&] { return CheckCameraModel(options.points); }},
      {"image files (PNG, JPEG)", [&] { return CheckImageFiles(scratch); }},
      {"mesh files (OBJ, PLY, OFF)", [&] { return CheckMeshFiles(scratch); }},
      {"shared test data", [&] { return CheckTestData(options.data_dir); }},
  };
  SelfCheckResult result;
  progress.BeginStage("self-check");
  for (std::size_t i = 0; i < checks.size(); ++i) {
    try {
      result.items.push_back(checks[i].second());
    } catch (const Cancelled&) {
      throw;
    } catch (const std::exception& e) {
      result.items.push_back({checks[i].first, Status::kFailed, e.what()});
    }
    progress.Report(i + 1, checks.size());
  }
  progress.EndStage();
  std::filesystem::remove_all(scratch, ec);
  return result;
}

}  // namespace carousel::studio
