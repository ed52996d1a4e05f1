#include "carousel/calib/rig_calibration.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <memory>
#include <mutex>
#include <numbers>
#include <set>
#include <sstream>

#include <ceres/ceres.h>
#include <ceres/rotation.h>

#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <opencv2/calib3d.hpp>

#include "calib_internal.h"
#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/parallel.h"

namespace carousel::calib {
namespace {

using internal::BoardView;
using internal::Fixed;
using internal::Median;

constexpr double kDeg = 180.0 / std::numbers::pi;

// Intrinsics as the adjustment holds them: fx fy cx cy k1 k2 p1 p2 k3.
using Intrinsics = std::array<double, 9>;
// A pose as the adjustment holds it: angle-axis rotation, then translation.
using Pose = std::array<double, 6>;

Intrinsics ToIntrinsics(const CameraModel& c) {
  const Distortion& d = c.distortion;
  return {c.fx, c.fy, c.cx, c.cy, d.k1, d.k2, d.p1, d.p2, d.k3};
}

Pose ToPose(const Rigid3d& r) {
  Pose p{};
  const Eigen::Matrix3d m = r.rotation;  // column-major, as ceres expects
  ceres::RotationMatrixToAngleAxis(m.data(), p.data());
  p[3] = r.translation.x();
  p[4] = r.translation.y();
  p[5] = r.translation.z();
  return p;
}

Rigid3d FromPose(const Pose& p) {
  Rigid3d r;
  ceres::AngleAxisToRotationMatrix(p.data(), r.rotation.data());
  r.translation = Eigen::Vector3d(p[3], p[4], p[5]);
  return r;
}

Rigid3d FromCv(const cv::Vec3d& rvec, const cv::Vec3d& tvec) {
  Pose p = {rvec[0], rvec[1], rvec[2], tvec[0], tvec[1], tvec[2]};
  return FromPose(p);
}

// The mean of rotations close to each other (quaternion average) and of translations.
Rigid3d Average(const std::vector<Rigid3d>& poses) {
  Eigen::Vector4d sum = Eigen::Vector4d::Zero();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();
  const Eigen::Quaterniond first(poses.front().rotation);
  for (const Rigid3d& p : poses) {
    Eigen::Quaterniond q(p.rotation);
    if (q.dot(first) < 0) q.coeffs() = -q.coeffs();
    sum += q.coeffs();
    translation += p.translation;
  }
  Eigen::Quaterniond mean;
  mean.coeffs() = sum.normalized();
  return {mean.toRotationMatrix(), translation / static_cast<double>(poses.size())};
}

double WrapAngle(double a) { return std::remainder(a, 2.0 * std::numbers::pi); }

// The reprojection of one board corner in one photo.
struct CornerCost {
  CornerCost(const cv::Point3f& board_point, const cv::Point2f& observed, double reported_rad)
      : x_(board_point.x),
        y_(board_point.y),
        z_(board_point.z),
        u_(observed.x),
        v_(observed.y),
        reported_(reported_rad) {}

  template <typename T>
  bool operator()(const T* intrinsics, const T* cam_from_table, const T* table_from_board,
                  const T* angle_offset, T* residual) const {
    const T board[3] = {T(x_), T(y_), T(z_)};
    T table[3];
    ceres::AngleAxisRotatePoint(table_from_board, board, table);
    for (int i = 0; i < 3; ++i) table[i] += table_from_board[3 + i];
    // The table turned by its angle (the object appears rotated by +theta about +Z).
    using std::cos;
    using std::sin;
    const T theta = T(reported_) + angle_offset[0];
    const T c = cos(theta);
    const T s = sin(theta);
    const T turned[3] = {c * table[0] - s * table[1], s * table[0] + c * table[1], table[2]};
    T cam[3];
    ceres::AngleAxisRotatePoint(cam_from_table, turned, cam);
    for (int i = 0; i < 3; ++i) cam[i] += cam_from_table[3 + i];
    const T xn = cam[0] / cam[2];
    const T yn = cam[1] / cam[2];
    T xd;
    T yd;
    DistortNormalized(intrinsics[4], intrinsics[5], intrinsics[6], intrinsics[7], intrinsics[8], xn,
                      yn, &xd, &yd);
    residual[0] = intrinsics[0] * xd + intrinsics[2] - T(u_);
    residual[1] = intrinsics[1] * yd + intrinsics[3] - T(v_);
    return true;
  }

  double x_, y_, z_, u_, v_, reported_;
};

struct Photo {
  std::size_t index;  // into the input
  int camera;
  int stop;
  int placement;
  double reported_rad;
  BoardView view;
  Rigid3d cam_from_board;  // initial, from the camera's own intrinsics
};

// Camera centre-independent initial geometry of the reference camera from its photos: the
// axis direction n from the relative rotations, the axis point o from the board centroid's
// circle, solved linearly with the reported angles.
Rigid3d InitialCamFromTable(const std::vector<const Photo*>& photos,
                            const Eigen::Vector3d& board_centroid) {
  Eigen::Vector3d n = Eigen::Vector3d::Zero();
  for (std::size_t j = 0; j < photos.size(); ++j) {
    for (std::size_t k = j + 1; k < photos.size(); ++k) {
      const double delta = WrapAngle(photos[j]->reported_rad - photos[k]->reported_rad);
      if (std::abs(delta) < 5.0 / kDeg) continue;
      const Eigen::AngleAxisd relative(photos[j]->cam_from_board.rotation *
                                       photos[k]->cam_from_board.rotation.transpose());
      if (relative.angle() < 1e-3) continue;
      const Eigen::Vector3d axis = delta > 0 ? relative.axis() : Eigen::Vector3d(-relative.axis());
      n += std::abs(std::sin(delta / 2.0)) * axis;
    }
  }
  CAROUSEL_THROW_IF(n.norm() < 1e-9, InvalidArgument,
                    "the board was photographed at too few distinct table angles to find the "
                    "turntable axis (at least two stops 5 degrees or more apart)");
  n.normalize();
  // p_j = o + R_n(theta_j) v: linear in (o, v); o slides along n, pinned by n.o = n.mean(p).
  const int rows = 3 * static_cast<int>(photos.size()) + 1;
  Eigen::MatrixXd a = Eigen::MatrixXd::Zero(rows, 6);
  Eigen::VectorXd b = Eigen::VectorXd::Zero(rows);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (std::size_t j = 0; j < photos.size(); ++j) {
    const Eigen::Vector3d p = photos[j]->cam_from_board * board_centroid;
    mean += p / static_cast<double>(photos.size());
    const Eigen::Matrix3d turn = Eigen::AngleAxisd(photos[j]->reported_rad, n).toRotationMatrix();
    const int r = 3 * static_cast<int>(j);
    a.block<3, 3>(r, 0) = Eigen::Matrix3d::Identity();
    a.block<3, 3>(r, 3) = turn;
    b.segment<3>(r) = p;
  }
  a.block<1, 3>(rows - 1, 0) = n.transpose();
  b(rows - 1) = n.dot(mean);
  const Eigen::VectorXd solution = a.colPivHouseholderQr().solve(b);
  const Eigen::Vector3d o = solution.head<3>();
  // Table axes in camera coordinates: z = n, x any perpendicular (the gauge is fixed later).
  Eigen::Vector3d x = n.unitOrthogonal();
  Eigen::Matrix3d table_in_cam;
  table_in_cam << x, n.cross(x), n;
  return {table_in_cam, o};
}

}  // namespace

const OptionTable<RigCalibrationOptions>& RigCalibrationOptions::Fields() {
  using O = RigCalibrationOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::fix_k3, {.name = "fix-k3",
                       .help = "k3 = 0 (free it for wide lenses with the board near every image "
                               "corner)",
                       .negative_name = "free-k3"});
    t.Add(&O::refine_intrinsics, {.name = "refine-intrinsics",
                                  .help = "refine the given intrinsics with the rig",
                                  .negative_name = "keep-intrinsics"});
    t.Add(&O::max_angle_error_deg,
          {.name = "max-angle-error",
           .help = "largest disagreement of a reported table angle with the board",
           .unit = "deg",
           .min = 0,
           .min_exclusive = true});
    t.Add(&O::max_rms_px, {.name = "max-rms",
                           .help = "largest final reprojection RMS",
                           .unit = "px",
                           .min = 0,
                           .min_exclusive = true,
                           .advanced = true});
    return t;
  }();
  return table;
}

void RigCalibrationOptions::Validate() const {
  detect.Validate();
  Fields().Check(*this);
  CAROUSEL_THROW_IF(!(board_origin_height_m >= 0) || board_origin_height_m > 1.0, InvalidArgument,
                    "board_origin_height_m must be in [0, 1] m");
  CAROUSEL_THROW_IF(min_views_per_camera < 3, InvalidArgument, "min_views_per_camera must be >= 3");
  CAROUSEL_THROW_IF(!(huber_px > 0), InvalidArgument, "huber_px must be > 0");
  CAROUSEL_THROW_IF(!(outlier_factor > 0) || !(outlier_floor_px > 0), InvalidArgument,
                    "outlier_factor and outlier_floor_px must be > 0");
  CAROUSEL_THROW_IF(!(max_angle_error_deg > 0), InvalidArgument, "max_angle_error_deg must be > 0");
  CAROUSEL_THROW_IF(!(max_rms_px > 0), InvalidArgument, "max_rms_px must be > 0");
}

CameraModel RigCalibration::CameraAt(int index, double table_angle_rad) const {
  CAROUSEL_THROW_IF(
      index < 0 || index >= static_cast<int>(cameras.size()), InvalidArgument,
      "the rig calibration has " << cameras.size() << " camera(s), not a camera " << index);
  CameraModel camera = cameras[static_cast<std::size_t>(index)].camera;
  camera.cam_from_world = camera.cam_from_world * Rigid3d::RotationZ(table_angle_rad);
  return camera;
}

RigCalibrationResult CalibrateRig(const std::vector<RigPhoto>& inputs, const BoardSpec& board,
                                  const std::vector<std::optional<CameraModel>>& intrinsics,
                                  const RigCalibrationOptions& options, Progress& progress) {
  board.Validate();
  options.Validate();
  CAROUSEL_THROW_IF(inputs.empty(), InvalidArgument, "no photos to calibrate the rig from");
  RigCalibrationResult result;
  result.photos.resize(inputs.size());
  int camera_count = 0;
  for (const RigPhoto& p : inputs) {
    CAROUSEL_THROW_IF(p.camera < 0 || p.stop < 0 || p.placement < 0, InvalidArgument,
                      p.name << ": camera, stop and placement must be >= 0");
    CAROUSEL_THROW_IF(!std::isfinite(p.table_angle_rad), InvalidArgument,
                      p.name << ": the table angle is not a number");
    camera_count = std::max(camera_count, p.camera + 1);
  }
  for (std::size_t i = 0; i < intrinsics.size() && i < static_cast<std::size_t>(camera_count);
       ++i) {
    if (intrinsics[i]) intrinsics[i]->Validate();
  }

  // ---- the board in every photo ----
  progress.BeginStage("find the board");
  std::vector<BoardDetection> detections(inputs.size());
  std::vector<cv::Size> sizes(inputs.size());
  std::vector<std::string> unreadable(inputs.size());
  std::size_t finished = 0;
  std::mutex finished_mutex;
  ParallelFor(inputs.size(), 1, options.threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      cv::Mat image = inputs[i].image;
      if (image.empty()) {
        try {
          image = ReadImage(inputs[i].path, ImageReadMode::kGray);
        } catch (const IoError& e) {
          unreadable[i] = std::string("cannot be read: ") + e.reason();
        }
      }
      if (!image.empty()) {
        sizes[i] = image.size();
        detections[i] = DetectBoard(image, board, options.detect);
      }
      std::lock_guard<std::mutex> lock(finished_mutex);
      progress.Report(++finished, inputs.size());
    }
  });

  std::vector<Photo> photos;
  std::vector<cv::Size> camera_size(static_cast<std::size_t>(camera_count));
  const std::vector<cv::Point3f> object = board.ObjectPoints();
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    RigPhotoReport& report = result.photos[i];
    report.name = inputs[i].name;
    report.camera = inputs[i].camera;
    report.stop = inputs[i].stop;
    cv::Size& size = camera_size[static_cast<std::size_t>(inputs[i].camera)];
    if (!unreadable[i].empty()) {
      report.reason = unreadable[i];
    } else if (!detections[i].found) {
      report.reason = detections[i].reason;
    } else if (!size.empty() && sizes[i] != size) {
      report.reason = "its size " + std::to_string(sizes[i].width) + "x" +
                      std::to_string(sizes[i].height) +
                      " differs from the camera's other photos (" + std::to_string(size.width) +
                      "x" + std::to_string(size.height) + ")";
    } else {
      size = sizes[i];
      report.corners = static_cast<int>(detections[i].corners.size());
      photos.push_back({i, inputs[i].camera, inputs[i].stop, inputs[i].placement,
                        inputs[i].table_angle_rad, internal::MakeBoardView(board, detections[i]),
                        Rigid3d()});
    }
  }
  const auto fail = [&](const std::string& why) {
    std::ostringstream message;
    message << why;
    for (const RigPhotoReport& r : result.photos) {
      if (!r.used && !r.reason.empty()) message << "\n  " << r.name << ": " << r.reason;
    }
    throw InvalidArgument(message.str());
  };
  const auto views_of = [&](int camera) {
    std::vector<Photo*> of;
    for (Photo& p : photos) {
      if (p.camera == camera) of.push_back(&p);
    }
    return of;
  };
  for (int c = 0; c < camera_count; ++c) {
    const std::size_t n = views_of(c).size();
    if (static_cast<int>(n) < options.min_views_per_camera) {
      std::ostringstream why;
      why << "cannot calibrate the rig: camera " << c
          << (n == 0 ? " never sees the board" : " sees the board in too few photos") << " (" << n
          << " usable, at least " << options.min_views_per_camera << " needed)";
      fail(why.str());
    }
  }

  // A camera whose photos never show the board near the image corners cannot tell k3 from
  // k1 and k2 there: k3 is held at 0 for it; one that sees the board in fewer than 6 of the
  // image's 3 x 3 cells holds k2 at 0 too (and says so): an unconstrained r^4 term fits the
  // middle and wrecks the corners.
  std::vector<bool> fix_k3(static_cast<std::size_t>(camera_count), options.fix_k3);
  std::vector<bool> fix_k2(static_cast<std::size_t>(camera_count), false);
  for (int c = 0; c < camera_count; ++c) {
    const cv::Size& size = camera_size[static_cast<std::size_t>(c)];
    std::array<bool, 9> seen{};
    for (const Photo* p : views_of(c)) {
      for (const cv::Point2f& q : p->view.image) {
        const int x = std::clamp(static_cast<int>(3.0 * q.x / size.width), 0, 2);
        const int y = std::clamp(static_cast<int>(3.0 * q.y / size.height), 0, 2);
        seen[3 * static_cast<std::size_t>(y) + static_cast<std::size_t>(x)] = true;
      }
    }
    const int cells = static_cast<int>(std::count(seen.begin(), seen.end(), true));
    const bool given = static_cast<std::size_t>(c) < intrinsics.size() && intrinsics[c];
    if (given) continue;  // a lens calibrated beforehand keeps its model
    if (cells < 6) {
      fix_k2[static_cast<std::size_t>(c)] = true;
      fix_k3[static_cast<std::size_t>(c)] = true;
      result.warnings.push_back("camera " + std::to_string(c) + " saw the board in only " +
                                std::to_string(cells) +
                                " of the image's 9 cells: its k2 and k3 are held at 0 (calibrate "
                                "its intrinsics with a board held near the image corners)");
    } else if (!options.fix_k3 && !(seen[0] && seen[2] && seen[6] && seen[8])) {
      fix_k3[static_cast<std::size_t>(c)] = true;
      result.warnings.push_back("camera " + std::to_string(c) +
                                " never saw the board in every image corner: its k3 is held at 0 "
                                "(the distortion near the corners is extrapolated)");
    }
  }

  // ---- initial values: intrinsics, board poses, axis, camera poses ----
  progress.BeginStage("initial poses");
  std::vector<Intrinsics> intr(static_cast<std::size_t>(camera_count));
  for (int c = 0; c < camera_count; ++c) {
    int flags = 0;
    if (fix_k3[static_cast<std::size_t>(c)]) flags |= cv::CALIB_FIX_K3;
    if (fix_k2[static_cast<std::size_t>(c)]) flags |= cv::CALIB_FIX_K2;
    if (options.zero_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
    std::vector<Photo*> of = views_of(c);
    const bool given = static_cast<std::size_t>(c) < intrinsics.size() && intrinsics[c];
    if (given) {
      const CameraModel& known = *intrinsics[c];
      const cv::Size& size = camera_size[static_cast<std::size_t>(c)];
      CAROUSEL_THROW_IF(known.width != size.width || known.height != size.height, InvalidArgument,
                        "camera " << c << "'s intrinsics are for " << known.width << "x"
                                  << known.height << " photos, its photos are " << size.width << "x"
                                  << size.height);
      intr[static_cast<std::size_t>(c)] = ToIntrinsics(known);
      const cv::Matx33d k = known.CvCameraMatrix();
      const cv::Vec<double, 5> d = known.CvDistCoeffs();
      for (Photo* p : of) {
        cv::Vec3d rvec;
        cv::Vec3d tvec;
        cv::solvePnP(p->view.object, p->view.image, k, d, rvec, tvec);
        p->cam_from_board = FromCv(rvec, tvec);
      }
    } else {
      std::vector<BoardView> views;
      views.reserve(of.size());
      for (const Photo* p : of) views.push_back(p->view);
      const internal::ViewsCalibration calibrated =
          internal::CalibrateViews(views, camera_size[static_cast<std::size_t>(c)], flags);
      intr[static_cast<std::size_t>(c)] = ToIntrinsics(internal::CameraFromCv(
          calibrated.k, calibrated.d, camera_size[static_cast<std::size_t>(c)]));
      for (std::size_t j = 0; j < of.size(); ++j) {
        of[j]->cam_from_board = FromCv(calibrated.rvecs[j], calibrated.tvecs[j]);
      }
    }
  }
  // The reference camera (most photos) gives the axis and the board's place on the table.
  int reference = 0;
  for (int c = 1; c < camera_count; ++c) {
    if (views_of(c).size() > views_of(reference).size()) reference = c;
  }
  Eigen::Vector3d centroid = Eigen::Vector3d::Zero();
  for (const cv::Point3f& p : object) {
    centroid += Eigen::Vector3d(p.x, p.y, p.z) / static_cast<double>(object.size());
  }
  // The reference camera's photos of the best-seen placement give the axis.
  std::map<int, int> per_placement;
  for (const Photo* p : views_of(reference)) ++per_placement[p->placement];
  const int axis_placement =
      std::max_element(per_placement.begin(), per_placement.end(),
                       [](const auto& a, const auto& b) { return a.second < b.second; })
          ->first;
  std::vector<const Photo*> reference_photos;
  for (const Photo* p : views_of(reference)) {
    if (p->placement == axis_placement) reference_photos.push_back(p);
  }
  std::vector<Rigid3d> cam_from_table(static_cast<std::size_t>(camera_count));
  cam_from_table[static_cast<std::size_t>(reference)] =
      InitialCamFromTable(reference_photos, centroid);
  // Each placement's board from the reference camera where it saw it, else from any camera
  // placed already; then every camera from the boards.
  std::map<int, Rigid3d> boards;
  std::set<int> placed_cameras = {reference};
  for (int pass = 0; pass < camera_count + 1; ++pass) {
    std::map<int, std::vector<Rigid3d>> board_estimates;
    for (const Photo& p : photos) {
      if (!placed_cameras.count(p.camera) || boards.count(p.placement)) continue;
      board_estimates[p.placement].push_back(
          (cam_from_table[static_cast<std::size_t>(p.camera)] * Rigid3d::RotationZ(p.reported_rad))
              .Inverse() *
          p.cam_from_board);
    }
    for (const auto& [placement, estimates] : board_estimates)
      boards[placement] = Average(estimates);
    std::map<int, std::vector<Rigid3d>> camera_estimates;
    for (const Photo& p : photos) {
      if (placed_cameras.count(p.camera) || !boards.count(p.placement)) continue;
      camera_estimates[p.camera].push_back(p.cam_from_board * boards[p.placement].Inverse() *
                                           Rigid3d::RotationZ(-p.reported_rad));
    }
    for (const auto& [camera, estimates] : camera_estimates) {
      cam_from_table[static_cast<std::size_t>(camera)] = Average(estimates);
      placed_cameras.insert(camera);
    }
  }
  for (const Photo& p : photos) {
    CAROUSEL_THROW_IF(
        !boards.count(p.placement) || !placed_cameras.count(p.camera), InvalidArgument,
        "cannot calibrate the rig: camera " << p.camera << " and board placement " << p.placement
                                            << " are not linked to the others by "
                                               "any photo");
  }

  // ---- bundle adjustment, with outlier photos dropped ----
  std::vector<Pose> cams(static_cast<std::size_t>(camera_count));
  for (int c = 0; c < camera_count; ++c) cams[c] = ToPose(cam_from_table[c]);
  std::map<int, Pose> board_poses;
  for (const auto& [placement, pose] : boards) board_poses[placement] = ToPose(pose);
  std::map<int, double> offsets;  // per stop, radians
  std::vector<bool> dropped(photos.size(), false);
  std::vector<double> photo_rms(photos.size(), 0.0);
  ceres::Solver::Summary summary;
  progress.BeginStage("bundle adjustment");
  for (int round = 0; round < 4; ++round) {
    ceres::Problem problem;
    std::set<int> stops;
    for (std::size_t j = 0; j < photos.size(); ++j) {
      if (!dropped[j]) stops.insert(photos[j].stop);
    }
    for (const int s : stops) offsets.try_emplace(s, 0.0);
    for (std::size_t j = 0; j < photos.size(); ++j) {
      if (dropped[j]) continue;
      const Photo& p = photos[j];
      for (std::size_t k = 0; k < p.view.object.size(); ++k) {
        auto* cost = new ceres::AutoDiffCostFunction<CornerCost, 2, 9, 6, 6, 1>(
            new CornerCost(p.view.object[k], p.view.image[k], p.reported_rad));
        problem.AddResidualBlock(cost, new ceres::HuberLoss(options.huber_px),
                                 intr[static_cast<std::size_t>(p.camera)].data(),
                                 cams[static_cast<std::size_t>(p.camera)].data(),
                                 board_poses[p.placement].data(), &offsets[p.stop]);
      }
    }
    // Gauge: the angle offsets are relative to the first stop's.
    problem.SetParameterBlockConstant(&offsets[*stops.begin()]);
    for (int c = 0; c < camera_count; ++c) {
      double* block = intr[static_cast<std::size_t>(c)].data();
      const bool given = static_cast<std::size_t>(c) < intrinsics.size() && intrinsics[c];
      if (given && !options.refine_intrinsics) {
        problem.SetParameterBlockConstant(block);
        continue;
      }
      std::vector<int> fixed;
      fixed.reserve(4);
      if (options.zero_tangential) {
        fixed.push_back(6);
        fixed.push_back(7);
      }
      if (fix_k2[static_cast<std::size_t>(c)]) {
        intr[static_cast<std::size_t>(c)][5] = 0.0;
        fixed.push_back(5);
      }
      if (fix_k3[static_cast<std::size_t>(c)]) {
        intr[static_cast<std::size_t>(c)][8] = 0.0;
        fixed.push_back(8);
      }
      if (!fixed.empty()) problem.SetManifold(block, new ceres::SubsetManifold(9, fixed));
    }
    ceres::Solver::Options solver;
    solver.linear_solver_type = ceres::DENSE_QR;
    solver.max_num_iterations = 200;
    solver.function_tolerance = 1e-12;
    solver.gradient_tolerance = 1e-12;
    solver.parameter_tolerance = 1e-12;
    solver.num_threads = ResolveThreadCount(options.threads);
    solver.logging_type = ceres::SILENT;
    ceres::Solve(solver, &problem, &summary);
    progress.CheckCancelled();

    // Per-photo RMS; drop the outliers and adjust again.
    std::vector<double> used_rms;
    for (std::size_t j = 0; j < photos.size(); ++j) {
      if (dropped[j]) continue;
      const Photo& p = photos[j];
      double sum = 0.0;
      for (std::size_t k = 0; k < p.view.object.size(); ++k) {
        const CornerCost cost(p.view.object[k], p.view.image[k], p.reported_rad);
        double r[2];
        cost(intr[static_cast<std::size_t>(p.camera)].data(),
             cams[static_cast<std::size_t>(p.camera)].data(), board_poses[p.placement].data(),
             &offsets[p.stop], r);
        sum += r[0] * r[0] + r[1] * r[1];
      }
      photo_rms[j] = std::sqrt(sum / static_cast<double>(p.view.object.size()));
      used_rms.push_back(photo_rms[j]);
    }
    const double limit =
        std::max(options.outlier_factor * Median(used_rms), options.outlier_floor_px);
    bool dropped_any = false;
    for (std::size_t j = 0; j < photos.size(); ++j) {
      if (dropped[j] || photo_rms[j] <= limit) continue;
      dropped[j] = true;
      dropped_any = true;
      result.photos[photos[j].index].reason =
          "a reprojection outlier (" + Fixed(photo_rms[j], 2) + " px RMS, the others' median " +
          Fixed(Median(used_rms), 2) + " px): the board moved, or a wrong detection";
    }
    if (!dropped_any) break;
    for (int c = 0; c < camera_count; ++c) {
      int left = 0;
      for (std::size_t j = 0; j < photos.size(); ++j) left += !dropped[j] && photos[j].camera == c;
      if (left < options.min_views_per_camera) {
        fail("cannot calibrate the rig: camera " + std::to_string(c) +
             " has too few photos left after dropping reprojection outliers");
      }
    }
  }
  result.iterations = static_cast<int>(summary.iterations.size());
  progress.Report(1.0);

  // ---- the gauge: placement 0's board x axis along +X at angle 0, its origin at its height --
  const int gauge_placement = boards.begin()->first;
  const Rigid3d first_board = FromPose(board_poses[gauge_placement]);
  Eigen::Vector3d along = first_board.rotation.col(0);
  if (std::abs(along.z()) > 0.9) along = first_board.rotation.col(1);
  const double yaw = std::atan2(along.y(), along.x());
  Rigid3d gauge = Rigid3d::RotationZ(-yaw);
  gauge.translation.z() = options.board_origin_height_m - first_board.translation.z();
  for (const auto& [placement, pose] : board_poses) {
    if (static_cast<int>(result.table_from_board.size()) <= placement)
      result.table_from_board.resize(static_cast<std::size_t>(placement) + 1);
    result.table_from_board[static_cast<std::size_t>(placement)] = gauge * FromPose(pose);
  }

  // ---- the table's angles against the board's rotation ----
  RigCalibration& calibration = result.calibration;
  std::map<int, double> reported_of;
  for (std::size_t j = 0; j < photos.size(); ++j) {
    if (!dropped[j]) reported_of[photos[j].stop] = photos[j].reported_rad;
  }
  // The common offset is the median: a few stops that lost steps stand out against it.
  std::vector<double> stop_offsets;
  stop_offsets.reserve(reported_of.size());
  for (const auto& [stop, reported] : reported_of) stop_offsets.push_back(offsets[stop]);
  const double mean_offset = Median(stop_offsets);
  // observed = scale * reported + offset, least squares.
  double sr = 0, so = 0, srr = 0, sro = 0;
  const double count = static_cast<double>(reported_of.size());
  for (const auto& [stop, reported] : reported_of) {
    const double observed = reported + offsets[stop] - mean_offset;
    calibration.angles.push_back({stop, reported * kDeg, observed * kDeg});
    sr += reported;
    so += observed;
    srr += reported * reported;
    sro += reported * observed;
  }
  const double denominator = count * srr - sr * sr;
  calibration.angle_scale = denominator > 1e-12 ? (count * sro - sr * so) / denominator : 1.0;
  const double intercept = (so - calibration.angle_scale * sr) / count;
  std::vector<std::string> bad_stops;
  for (const StopAngle& a : calibration.angles) {
    const double fit_residual =
        a.observed_deg - (calibration.angle_scale * a.reported_deg + intercept * kDeg);
    calibration.angle_residual_max_deg =
        std::max(calibration.angle_residual_max_deg, std::abs(fit_residual));
    if (std::abs(a.observed_deg - a.reported_deg) > options.max_angle_error_deg) {
      bad_stops.push_back("stop " + std::to_string(a.stop) + ": the table said " +
                          Fixed(a.reported_deg, 2) + " deg, the board turned " +
                          Fixed(a.observed_deg, 2) + " deg");
    }
  }
  if (!bad_stops.empty()) {
    std::ostringstream why;
    why << "cannot calibrate the rig: the turntable's angles disagree with the board's rotation "
           "by more than "
        << Fixed(options.max_angle_error_deg, 2) << " deg (observed/reported "
        << Fixed(calibration.angle_scale, 4)
        << ": a scale other than 1 is a wrong gear ratio, a jump a lost step)";
    for (const std::string& s : bad_stops) why << "\n  " << s;
    throw InvalidArgument(why.str());
  }

  // ---- the result ----
  calibration.board = board.ToString();
  calibration.board_origin_height_m = options.board_origin_height_m;
  double total = 0.0;
  int corners = 0;
  for (int c = 0; c < camera_count; ++c) {
    RigCameraCalibration camera;
    camera.name = "cam" + std::to_string(c);
    const Intrinsics& k = intr[static_cast<std::size_t>(c)];
    CameraModel& model = camera.camera;
    model.width = camera_size[static_cast<std::size_t>(c)].width;
    model.height = camera_size[static_cast<std::size_t>(c)].height;
    model.fx = k[0];
    model.fy = k[1];
    model.cx = k[2];
    model.cy = k[3];
    model.distortion = {k[4], k[5], k[6], k[7], k[8]};
    model.cam_from_world = FromPose(cams[static_cast<std::size_t>(c)]) * gauge.Inverse();
    model.Validate();
    camera.axis_direction_cam = model.cam_from_world.rotation.col(2);
    camera.axis_point_cam = model.cam_from_world.translation;
    double sum = 0.0;
    int n = 0;
    for (std::size_t j = 0; j < photos.size(); ++j) {
      if (dropped[j] || photos[j].camera != c) continue;
      RigPhotoReport& report = result.photos[photos[j].index];
      report.used = true;
      report.rms_px = photo_rms[j];
      ++camera.views;
      const double squared = photo_rms[j] * photo_rms[j] * photos[j].view.object.size();
      sum += squared;
      n += static_cast<int>(photos[j].view.object.size());
    }
    camera.rms_px = std::sqrt(sum / std::max(n, 1));
    total += sum;
    corners += n;
    calibration.cameras.push_back(camera);
  }
  calibration.corners = corners;
  calibration.rms_px = std::sqrt(total / std::max(corners, 1));
  if (!(calibration.rms_px <= options.max_rms_px)) {
    std::ostringstream why;
    why << "cannot calibrate the rig: the board reprojects " << Fixed(calibration.rms_px, 3)
        << " px RMS, more than " << Fixed(options.max_rms_px, 3)
        << " px allowed (a board that is not flat, a moving board, or a lens the model cannot "
           "describe)";
    throw InvalidArgument(why.str());
  }
  if (calibration.angle_residual_max_deg > 0.5 * options.max_angle_error_deg) {
    result.warnings.push_back("the table's angles deviate from the board's rotation by up to " +
                              Fixed(calibration.angle_residual_max_deg, 3) + " deg");
  }
  CAROUSEL_LOG_INFO("rig calibration: " << camera_count << " camera(s), " << corners << " corners, "
                                        << Fixed(calibration.rms_px, 3) << " px RMS, "
                                        << result.iterations << " iterations");
  return result;
}

}  // namespace carousel::calib
