#include "carousel/recon/registration.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>
#include <random>

#include <Eigen/Cholesky>
#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/parallel.h"
#include "carousel/core/raster.h"
#include "carousel/core/timer.h"
#include "carousel/recon/visual_hull.h"

namespace carousel::recon {
namespace {

// Colour consistency (a tie between poses): photos reduced to this longest side, pixels; a
// view sees a point when it is at least this frontal; at least this many points seen by both
// passes; a pose wins when its correlation reaches kColourMinWin and beats every other tied
// pose's (kColourDistinctDeg away) by kColourMinMargin.
constexpr int kColourSide = 480;
constexpr double kColourMinCosine = 0.5;
constexpr int kColourMinPoints = 100;
constexpr double kColourMinWin = 0.5;
constexpr double kColourMinMargin = 0.1;
// Tied poses are tried turned about the vertical axis in steps of this many degrees, and the
// runner-up in colour is the best at least kColourDistinctDeg from the winner.
constexpr int kColourStepDeg = 5;
// Colours are compared less their mean over the points at the same height, in this many bands.
constexpr int kColourBins = 24;
constexpr double kColourDistinctDeg = 30.0;
// From the operator's pose the colours try the turns within this many degrees of it (the
// alternatives offered are kColourDistinctDeg apart, so one lies this close to the truth).
constexpr int kColourStartDeg = 30;
// The upright axis of a tied pose is found from its refined turns that are still turns about
// an axis within kUprightAxisMaxTilt of upright, by at least kUprightAxisMinTurn (radians), and
// is kept where it lies within this fraction of the product's size of the hull's centroid.
constexpr double kUprightAxisMaxTilt = 3.0 * std::numbers::pi / 180.0;
constexpr double kUprightAxisMinTurn = 30.0 * std::numbers::pi / 180.0;
constexpr double kUprightAxisMaxOffset = 0.1;
// Levenberg-Marquardt stops when a step lowers the cost by less than this fraction (its
// steps then move the pose by hundredths of a pixel).
constexpr double kRefineMinGain = 1e-4;
// At the finest level, candidates stop being refined once they fit this many times the
// ambiguity ratio worse than the best (the operator is never asked about them).
constexpr double kRefineOnRatio = 1.5;
// An ambiguous result lists at most this many poses for the operator.
constexpr int kMaxAlternatives = 12;

// One view at one level: its camera scaled to the level's mask, and per pixel the distance to
// the nearest object pixel (0 on the object).
struct LevelView {
  CameraModel camera;
  cv::Mat outside;  // CV_32FC1
};

struct Level {
  std::vector<LevelView> reference, pass;
  std::vector<Eigen::Vector3d> reference_points;  // object frame
  std::vector<Eigen::Vector3d> pass_points;       // the pass's table frame
  double truncation_m = 0.0;
  double pixel_m = 0.0;  // a level pixel at the product, metres (typical)
};

struct Pose {
  Rigid3d table_from_object;
  double cost = std::numeric_limits<double>::infinity();  // sum of squared residuals
  double rms = std::numeric_limits<double>::infinity();
};

LevelView MakeLevelView(const View& view, int max_side) {
  const cv::Mat mask = view.Mask();
  LevelView level;
  const double factor =
      std::min(1.0, static_cast<double>(max_side) / std::max(mask.cols, mask.rows));
  cv::Mat small = mask;
  if (factor < 1.0) {
    cv::resize(mask, small,
               cv::Size(std::max(1, static_cast<int>(std::lround(mask.cols * factor))),
                        std::max(1, static_cast<int>(std::lround(mask.rows * factor)))),
               0, 0, cv::INTER_AREA);
    level.camera = view.camera().Scaled(static_cast<double>(small.cols) / mask.cols);
  } else {
    level.camera = view.camera();
  }
  const cv::Mat background = small < 128;
  cv::distanceTransform(background, level.outside, cv::DIST_L2, cv::DIST_MASK_PRECISE);
  return level;
}

// Up to `count` views spread evenly over `views`.
std::vector<std::size_t> Spread(std::size_t size, std::size_t count) {
  std::vector<std::size_t> picked;
  count = std::min(count, size);
  for (std::size_t k = 0; k < count; ++k) picked.push_back(k * size / count);
  return picked;
}

// `count` of `points`, picked by a fixed shuffle (the same every run).
std::vector<Eigen::Vector3d> Subsample(const std::vector<Eigen::Vector3d>& points,
                                       std::size_t count) {
  if (points.size() <= count) return points;
  std::vector<std::size_t> order(points.size());
  std::iota(order.begin(), order.end(), 0);
  std::mt19937_64 random(0x5eed);
  std::shuffle(order.begin(), order.end(), random);
  std::vector<Eigen::Vector3d> picked;
  picked.reserve(count);
  for (std::size_t k = 0; k < count; ++k) picked.push_back(points[order[k]]);
  return picked;
}

// The derivative of the pixel that camera-frame point `cam` projects to, by `cam` (2x3), the
// lens's distortion included.
Eigen::Matrix<double, 2, 3> PixelByCam(const CameraModel& camera, const Eigen::Vector3d& cam) {
  const double inv_z = 1.0 / cam.z();
  const double x = cam.x() * inv_z, y = cam.y() * inv_z;
  Eigen::Matrix2d by_xy;  // distorted by undistorted normalised coordinates
  camera.distortion.Apply(Eigen::Vector2d(x, y), &by_xy);
  by_xy.row(0) *= camera.fx;
  by_xy.row(1) *= camera.fy;
  Eigen::Matrix<double, 2, 3> xy_by_cam;
  xy_by_cam << inv_z, 0.0, -x * inv_z, 0.0, inv_z, -y * inv_z;
  return by_xy * xy_by_cam;
}

// The truncated distance (metres at the point) of `world` outside view's silhouette: 0 inside
// and on the boundary, `truncation` where it lies behind the camera or outside the frame. With
// `gradient`, also its derivative by `world` there (zero where it is 0 or truncated).
double Outside(const LevelView& view, const Eigen::Vector3d& world, double truncation,
               Eigen::Vector3d* gradient = nullptr) {
  if (gradient) gradient->setZero();
  // Written out: under the sanitizers Eigen's product of a 3x3 matrix and a vector stays a
  // chain of calls, and was most of the registration's time there.
  const Eigen::Matrix3d& r = view.camera.cam_from_world.rotation;
  const Eigen::Vector3d& t = view.camera.cam_from_world.translation;
  const Eigen::Vector3d cam(
      r(0, 0) * world.x() + r(0, 1) * world.y() + r(0, 2) * world.z() + t.x(),
      r(1, 0) * world.x() + r(1, 1) * world.y() + r(1, 2) * world.z() + t.y(),
      r(2, 0) * world.x() + r(2, 1) * world.y() + r(2, 2) * world.z() + t.z());
  if (cam.z() <= 1e-6) return truncation;
  const Eigen::Vector2d pixel = view.camera.ProjectFromCam(cam);
  const int w = view.outside.cols, h = view.outside.rows;
  if (!(pixel.x() >= 0.0 && pixel.y() >= 0.0 && pixel.x() <= w - 1 && pixel.y() <= h - 1))
    return truncation;
  const int x0 = std::min(static_cast<int>(pixel.x()), w - 2 < 0 ? 0 : w - 2);
  const int y0 = std::min(static_cast<int>(pixel.y()), h - 2 < 0 ? 0 : h - 2);
  const double fx = pixel.x() - x0, fy = pixel.y() - y0;
  const int x1 = std::min(x0 + 1, w - 1), y1 = std::min(y0 + 1, h - 1);
  const float* r0 = view.outside.ptr<float>(y0);
  const float* r1 = view.outside.ptr<float>(y1);
  const double d =
      (1 - fy) * ((1 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1 - fx) * r1[x0] + fx * r1[x1]);
  // The transform measures to the nearest object pixel's centre: the boundary is half a
  // pixel nearer.
  const double px = std::max(0.0, d - 0.5);
  const double metres_per_px = cam.z() / view.camera.fx;
  const double outside = px * metres_per_px;
  if (outside >= truncation) return truncation;
  if (gradient && px > 0.0) {
    // The bilinear map's slope, through the projection; and the depth's share (a pixel
    // spans more metres further away).
    const Eigen::RowVector2d d_by_pixel((1 - fy) * (r0[x1] - r0[x0]) + fy * (r1[x1] - r1[x0]),
                                        (1 - fx) * (r1[x0] - r0[x0]) + fx * (r1[x1] - r0[x1]));
    Eigen::RowVector3d by_cam = metres_per_px * d_by_pixel * PixelByCam(view.camera, cam);
    by_cam.z() += px / view.camera.fx;
    *gradient = r.transpose() * by_cam.transpose();
  }
  return outside;
}

std::size_t ResidualCount(const Level& level) {
  return level.reference_points.size() * level.pass.size() +
         level.pass_points.size() * level.reference.size();
}

// Every residual of `pose` at `level`, into `out` (ResidualCount entries). With `jacobian`,
// also each residual's derivative by the pose's change as Moved() takes it about `centre`
// (table frame): six columns of ResidualCount entries.
void Residuals(const Level& level, const Rigid3d& table_from_object, int threads,
               std::vector<double>* out, std::array<std::vector<double>, 6>* jacobian = nullptr,
               const Eigen::Vector3d& centre = Eigen::Vector3d::Zero()) {
  const std::size_t count = ResidualCount(level);
  out->resize(count);
  if (jacobian)
    for (std::vector<double>& column : *jacobian) column.resize(count);
  const Rigid3d object_from_table = table_from_object.Inverse();
  const Eigen::Matrix3d& rotation = table_from_object.rotation;
  const std::size_t n1 = level.reference_points.size(), n2 = level.pass_points.size();
  const std::size_t m1 = level.reference.size(), m2 = level.pass.size();
  double* r = out->data();
  // A residual's derivatives by the rotation (about `centre`) and by the translation.
  auto store = [jacobian](std::size_t at, const Eigen::Vector3d& by_rotation,
                          const Eigen::Vector3d& by_translation) {
    for (int k = 0; k < 3; ++k) {
      (*jacobian)[k][at] = by_rotation[k];
      (*jacobian)[3 + k][at] = by_translation[k];
    }
  };
  ParallelFor(n1 + n2, 256, threads, [&](std::size_t begin, std::size_t end) {
    Eigen::Vector3d g;
    for (std::size_t i = begin; i < end; ++i) {
      if (i < n1) {
        // q = T p moves by the turn: dq = omega x (q - centre) + dt.
        const Eigen::Vector3d q = table_from_object * level.reference_points[i];
        for (std::size_t j = 0; j < m2; ++j) {
          const std::size_t at = i * m2 + j;
          if (!jacobian) {
            r[at] = Outside(level.pass[j], q, level.truncation_m);
            continue;
          }
          r[at] = Outside(level.pass[j], q, level.truncation_m, &g);
          store(at, (q - centre).cross(g), g);
        }
      } else {
        // x = T^-1 s moves the other way: dx = R^T ((s - centre) x omega - dt).
        const std::size_t k = i - n1;
        const Eigen::Vector3d& s = level.pass_points[k];
        const Eigen::Vector3d q = object_from_table * s;
        for (std::size_t j = 0; j < m1; ++j) {
          const std::size_t at = n1 * m2 + k * m1 + j;
          if (!jacobian) {
            r[at] = Outside(level.reference[j], q, level.truncation_m);
            continue;
          }
          r[at] = Outside(level.reference[j], q, level.truncation_m, &g);
          const Eigen::Vector3d turned = rotation * g;
          store(at, turned.cross(s - centre), -turned);
        }
      }
    }
  });
}

double SumOfSquares(const std::vector<double>& r) {
  double sum = 0.0;
  for (const double value : r) sum += value * value;
  return sum;
}

Pose Evaluate(const Level& level, const Rigid3d& table_from_object, int threads) {
  std::vector<double> r;
  Residuals(level, table_from_object, threads, &r);
  Pose pose;
  pose.table_from_object = table_from_object;
  pose.cost = SumOfSquares(r);
  pose.rms = std::sqrt(pose.cost / std::max<std::size_t>(1, r.size()));
  return pose;
}

// The fraction of the two hulls' points that lie further than `distance_m` outside some
// silhouette of the other pass at `pose`: what the other pass's photos say is not there.
double InconsistentFraction(const Level& level, const Rigid3d& table_from_object, double distance_m,
                            int threads) {
  std::vector<double> r;
  Residuals(level, table_from_object, threads, &r);
  const std::size_t n1 = level.reference_points.size(), n2 = level.pass_points.size();
  const std::size_t m1 = level.reference.size(), m2 = level.pass.size();
  std::size_t inconsistent = 0;
  for (std::size_t i = 0; i < n1; ++i)
    for (std::size_t j = 0; j < m2; ++j)
      if (r[i * m2 + j] > distance_m) {
        ++inconsistent;
        break;
      }
  for (std::size_t k = 0; k < n2; ++k)
    for (std::size_t j = 0; j < m1; ++j)
      if (r[n1 * m2 + k * m1 + j] > distance_m) {
        ++inconsistent;
        break;
      }
  return static_cast<double>(inconsistent) / static_cast<double>(std::max<std::size_t>(1, n1 + n2));
}

// The pose moved by delta: a rotation (angle-axis, first three) about `centre` (in the
// table frame) and a translation (last three).
Rigid3d Moved(const Rigid3d& pose, const Eigen::Matrix<double, 6, 1>& delta,
              const Eigen::Vector3d& centre) {
  const Eigen::Vector3d omega = delta.head<3>();
  const double angle = omega.norm();
  const Eigen::Matrix3d turn = angle > 0
                                   ? Eigen::AngleAxisd(angle, omega / angle).toRotationMatrix()
                                   : Eigen::Matrix3d::Identity();
  Rigid3d moved;
  moved.rotation = turn * pose.rotation;
  moved.translation = turn * (pose.translation - centre) + centre + delta.tail<3>();
  return moved;
}

// Levenberg-Marquardt on the pose at one level.
Pose Refine(const Level& level, const Pose& start, const Eigen::Vector3d& object_centre,
            int iterations, int threads, Progress& progress) {
  Pose best = start.cost < std::numeric_limits<double>::infinity()
                  ? start
                  : Evaluate(level, start.table_from_object, threads);
  double lambda = 1e-3;
  std::vector<double> r0;
  std::array<std::vector<double>, 6> columns;
  for (int iteration = 0; iteration < iterations; ++iteration) {
    progress.CheckCancelled();
    const Eigen::Vector3d centre = best.table_from_object * object_centre;
    Residuals(level, best.table_from_object, threads, &r0, &columns, centre);
    Eigen::Matrix<double, 6, 6> jtj = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> jtr = Eigen::Matrix<double, 6, 1>::Zero();
    for (std::size_t i = 0; i < r0.size(); ++i) {
      Eigen::Matrix<double, 6, 1> row;
      for (int k = 0; k < 6; ++k) row[k] = columns[k][i];
      if (row.isZero()) continue;
      jtj.selfadjointView<Eigen::Upper>().rankUpdate(row);
      jtr += row * r0[i];
    }
    jtj = jtj.selfadjointView<Eigen::Upper>();
    bool improved = false;
    for (int attempt = 0; attempt < 6 && !improved; ++attempt) {
      Eigen::Matrix<double, 6, 6> damped = jtj;
      for (int k = 0; k < 6; ++k) damped(k, k) += lambda * std::max(jtj(k, k), 1e-12) + 1e-12;
      const Eigen::Matrix<double, 6, 1> delta = -damped.ldlt().solve(jtr);
      if (!delta.allFinite()) break;
      const Pose trial = Evaluate(level, Moved(best.table_from_object, delta, centre), threads);
      if (trial.cost < best.cost) {
        const double gain = best.cost - trial.cost;
        best = trial;
        lambda = std::max(1e-7, lambda / 3.0);
        improved = true;
        if (gain < kRefineMinGain * best.cost) return best;
      } else {
        lambda *= 8.0;
      }
    }
    if (!improved) break;
  }
  return best;
}

// Compass search on the pose: each of the six directions (rotations about the product's centre,
// translations) tried both ways, the step halved when none improves, down to `min_steps`
// halvings. Slow but sure where the cost is flat and kinked (the hinge at the silhouettes'
// boundaries) and Levenberg-Marquardt stalls.
Pose CompassSearch(const Level& level, Pose best, const Eigen::Vector3d& object_centre,
                   double step_r, double step_t, int halvings, int threads, Progress& progress) {
  for (int halving = 0; halving < halvings; ++halving) {
    for (int round = 0; round < 4; ++round) {
      progress.CheckCancelled();
      bool improved = false;
      for (int k = 0; k < 6; ++k) {
        for (const double sign : {1.0, -1.0}) {
          Eigen::Matrix<double, 6, 1> delta = Eigen::Matrix<double, 6, 1>::Zero();
          delta[k] = sign * (k < 3 ? step_r : step_t);
          const Pose trial = Evaluate(
              level, Moved(best.table_from_object, delta, best.table_from_object * object_centre),
              threads);
          if (trial.cost < best.cost) {
            best = trial;
            improved = true;
            break;
          }
        }
      }
      if (!improved) break;
    }
    step_r *= 0.5;
    step_t *= 0.5;
  }
  return best;
}

// Uniformly distributed rotations (Shoemake's method with a fixed seed: the same every run).
std::vector<Eigen::Matrix3d> SampleRotations(int count) {
  std::vector<Eigen::Matrix3d> rotations;
  rotations.reserve(static_cast<std::size_t>(count));
  std::mt19937_64 random(0x0a11ce);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  rotations.push_back(Eigen::Matrix3d::Identity());
  while (static_cast<int>(rotations.size()) < count) {
    const double u1 = uniform(random), u2 = uniform(random), u3 = uniform(random);
    const double a = std::sqrt(1 - u1), b = std::sqrt(u1);
    const Eigen::Quaterniond q(
        b * std::cos(2 * std::numbers::pi * u3), a * std::sin(2 * std::numbers::pi * u2),
        a * std::cos(2 * std::numbers::pi * u2), b * std::sin(2 * std::numbers::pi * u3));
    rotations.push_back(q.normalized().toRotationMatrix());
  }
  return rotations;
}

// The views with their masks (and cameras) reduced to at most `max_side` pixels, in memory:
// what every level and the pass's hull are made from, so that the full-size masks are
// reduced once.
std::vector<View> Reduced(const std::vector<View>& full_size, int max_side, int threads) {
  std::vector<View> views(full_size.size());
  ParallelFor(views.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      const cv::Mat mask = full_size[i].Mask();
      const double factor =
          std::min(1.0, static_cast<double>(max_side) / std::max(mask.cols, mask.rows));
      if (factor >= 1.0) {
        views[i] = full_size[i];
        continue;
      }
      const CameraModel camera = full_size[i].camera().Scaled(factor);
      cv::Mat small;
      cv::resize(mask, small, cv::Size(camera.width, camera.height), 0, 0, cv::INTER_AREA);
      views[i] = View(camera, {});
      views[i].SetMask(small);
      views[i].set_name(full_size[i].name());
    }
  });
  return views;
}

// The pass's own visual hull (its own table frame), on a coarse grid, from masks of at most
// the registration's largest side (a grid of 96 cells needs no more).
Mesh PassHull(const std::vector<View>& reduced, int threads, Progress& progress) {
  VisualHullOptions options;
  options.resolution = 96;
  options.proxy_max_faces = 0;
  options.min_view_consistency = 0.0;
  options.threads = threads;
  return ComputeVisualHull(reduced, options, progress).mesh;
}

// Surface points of the pass's own visual hull (PassHull), with their normals on request.
std::vector<Eigen::Vector3d> HullPoints(const std::vector<View>& reduced, int threads,
                                        Progress& progress, Eigen::AlignedBox3d* box,
                                        std::vector<Eigen::Vector3d>* normals = nullptr) {
  Mesh mesh = PassHull(reduced, threads, progress);
  std::vector<Eigen::Vector3d> points;
  points.reserve(mesh.n_vertices());
  for (const auto vertex : mesh.vertices()) {
    const auto& p = mesh.point(vertex);
    points.emplace_back(p[0], p[1], p[2]);
  }
  if (normals != nullptr) {
    mesh.RecomputeNormals();
    normals->clear();
    for (const auto vertex : mesh.vertices()) {
      const auto& n = mesh.normal(vertex);
      normals->emplace_back(n[0], n[1], n[2]);
    }
  }
  *box = Eigen::AlignedBox3d();
  for (const Eigen::Vector3d& p : points) box->extend(p);
  return points;
}

Level MakeLevel(const std::vector<View>& reference, const std::vector<View>& pass,
                const std::vector<Eigen::Vector3d>& reference_points,
                const std::vector<Eigen::Vector3d>& pass_points, std::size_t max_views,
                int max_side, std::size_t points, double truncation_m, double size_m, int threads) {
  Level level;
  const std::vector<std::size_t> r = Spread(reference.size(), max_views);
  const std::vector<std::size_t> p = Spread(pass.size(), max_views);
  level.reference.resize(r.size());
  level.pass.resize(p.size());
  ParallelFor(r.size() + p.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      if (i < r.size())
        level.reference[i] = MakeLevelView(reference[r[i]], max_side);
      else
        level.pass[i - r.size()] = MakeLevelView(pass[p[i - r.size()]], max_side);
    }
  });
  level.reference_points = Subsample(reference_points, points);
  level.pass_points = Subsample(pass_points, points);
  level.truncation_m = truncation_m;
  // A level pixel at the product: the median over the views of distance / focal length.
  std::vector<double> pixel;
  const Eigen::Vector3d centre =
      std::accumulate(reference_points.begin(), reference_points.end(), Eigen::Vector3d(0, 0, 0)) /
      std::max<std::size_t>(1, reference_points.size());
  for (const LevelView& v : level.reference)
    pixel.push_back((v.camera.cam_from_world * centre).z() / v.camera.fx);
  std::nth_element(pixel.begin(), pixel.begin() + pixel.size() / 2, pixel.end());
  level.pixel_m = pixel.empty() ? 1e-3 * size_m : pixel[pixel.size() / 2];
  return level;
}

// The level with its truncation narrowed to `pixels` of its pixels at the product.
Level Narrowed(const Level& level, double pixels) {
  Level narrowed = level;
  narrowed.truncation_m = std::min(level.truncation_m, pixels * level.pixel_m);
  return narrowed;
}

Eigen::Vector3d Centroid(const std::vector<Eigen::Vector3d>& points) {
  Eigen::Vector3d sum = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& p : points) sum += p;
  return sum / std::max<std::size_t>(1, points.size());
}

// `pose` turned about the object's upright axis through `centre` (object frame) so that its
// turn about that axis is `reference`'s, the rest of it (a tilt) kept: a swing-twist split of
// the rotation between them.
Rigid3d WithTurnOf(const Rigid3d& pose, const Rigid3d& reference, const Eigen::Vector3d& centre) {
  const Eigen::Quaterniond between(Eigen::Matrix3d(reference.rotation.transpose() * pose.rotation));
  Eigen::Quaterniond twist(between.w(), 0.0, 0.0, between.z());
  if (twist.norm() < 1e-12) return pose;
  twist.normalize();
  const Eigen::Matrix3d undo = twist.conjugate().toRotationMatrix();
  return pose * Rigid3d(undo, centre - undo * centre);
}

// `pose` turned by `deg` about the object's upright axis through `axis` (object frame).
Rigid3d TurnedAbout(const Rigid3d& pose, double deg, const Eigen::Vector3d& axis) {
  const Eigen::Matrix3d r =
      Eigen::AngleAxisd(deg * std::numbers::pi / 180.0, Eigen::Vector3d::UnitZ())
          .toRotationMatrix();
  return pose * Rigid3d(r, axis - r * axis);
}

// A point on the upright axis that `pose` is best turned about (object frame, at `centre`'s
// height). The hull's centroid lies only near the axis of a product symmetric about it, and a
// turn about a line a millimetre off moves the product by up to two: the silhouettes then tell
// against a turn that is right (a bottle turned half round fitted twice as badly as it was).
// So the pose is turned by a quarter, a half and three quarters and each turn refined; every
// refined turn that the silhouettes fit as well as the pose (within `ratio`) and that is still
// a turn about the upright axis, T(x) = R (x - p) + p, says where the axis is: T's translation
// is (I - R) p. Where no turn fits (not a product symmetric about its upright axis), `centre`.
Eigen::Vector3d UprightAxis(const Level& coarse, const Level& middle, const Rigid3d& pose,
                            const Eigen::Vector3d& centre, double size, double ratio, int threads,
                            Progress& progress) {
  const double pose_rms = Evaluate(middle, pose, threads).rms;
  Eigen::Matrix2d ata = Eigen::Matrix2d::Zero();
  Eigen::Vector2d atb = Eigen::Vector2d::Zero();
  for (const double deg : {90.0, 180.0, 270.0}) {
    Pose refined = Refine(coarse, Evaluate(coarse, TurnedAbout(pose, deg, centre), threads), centre,
                          5, threads, progress);
    refined = Refine(middle, Evaluate(middle, refined.table_from_object, threads), centre, 5,
                     threads, progress);
    if (refined.rms >= ratio * pose_rms) continue;
    const Rigid3d turn = pose.Inverse() * refined.table_from_object;
    const Eigen::AngleAxisd angle_axis(turn.rotation);
    if (angle_axis.angle() < kUprightAxisMinTurn ||
        std::abs(angle_axis.axis().z()) < std::cos(kUprightAxisMaxTilt))
      continue;
    const Eigen::Matrix2d a = Eigen::Matrix2d::Identity() - turn.rotation.topLeftCorner<2, 2>();
    ata += a.transpose() * a;
    atb += a.transpose() * turn.translation.head<2>();
  }
  if (ata.determinant() < 1e-3) return centre;
  const Eigen::Vector2d xy = ata.ldlt().solve(atb);
  // Far from the hull's centre the refinements found no common axis (not a symmetric product).
  if ((xy - centre.head<2>()).norm() > kUprightAxisMaxOffset * size) return centre;
  return {xy.x(), xy.y(), centre.z()};
}

// The poses, best first, keeping only those at least `min_deg` from every better one.
std::vector<Pose> Distinct(std::vector<Pose> poses, double min_deg, std::size_t count) {
  std::sort(poses.begin(), poses.end(),
            [](const Pose& a, const Pose& b) { return a.cost < b.cost; });
  std::vector<Pose> kept;
  for (const Pose& pose : poses) {
    if (kept.size() >= count) break;
    const bool near = std::any_of(kept.begin(), kept.end(), [&](const Pose& k) {
      return RotationDistanceDeg(k.table_from_object.rotation, pose.table_from_object.rotation) <
             min_deg;
    });
    if (!near) kept.push_back(pose);
  }
  return kept;
}

// ---- colour consistency: what breaks a tie between poses the silhouettes fit alike ----------

// A pass's photos, reduced, with their cameras and masks shrunk to where colours are the
// object's own.
struct ColourView {
  CameraModel camera;
  cv::Mat image;  // CV_8UC3
  cv::Mat inner;  // CV_8UC1, the mask eroded
};

// The pass's photos at most `side` long, their silhouettes from `masks` (the same views, their
// masks at any size: Reduced's shrink faster than the full-size ones).
std::vector<ColourView> ColourViews(const std::vector<View>& views, const std::vector<View>& masks,
                                    int threads, int side = kColourSide) {
  std::vector<ColourView> out(views.size());
  ParallelFor(views.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      // Decoded reduced where the photo is not in memory: most of the time this takes.
      const cv::Mat image = views[i].ImageAtLeast(side);
      const CameraModel& camera = views[i].camera();
      const double factor =
          std::min(1.0, static_cast<double>(side) / std::max(camera.width, camera.height));
      ColourView& view = out[i];
      view.camera = camera.Scaled(factor);
      const cv::Size size(view.camera.width, view.camera.height);
      cv::resize(image, view.image, size, 0, 0, cv::INTER_AREA);
      cv::Mat mask;
      cv::resize(masks[i].Mask(), mask, size, 0, 0, cv::INTER_AREA);
      cv::erode(mask >= 128, view.inner, cv::Mat(), cv::Point(-1, -1), 2);
      views[i].ReleasePixels();
    }
  });
  return out;
}

// The colour a pass's most frontal view shows at `point` (normal `normal`, both in the pass's
// frame), if some view sees it within kColourMinCosine of frontal and inside its mask.
std::optional<cv::Vec3f> ColourAt(const std::vector<ColourView>& views,
                                  const Eigen::Vector3d& point, const Eigen::Vector3d& normal) {
  double best = kColourMinCosine;
  std::optional<cv::Vec3f> colour;
  for (const ColourView& view : views) {
    const Eigen::Vector3d towards = (view.camera.Centre() - point).normalized();
    const double cosine = towards.dot(normal);
    if (cosine < best) continue;
    const auto pixel = view.camera.Project(point);
    if (!pixel) continue;
    const int x = static_cast<int>(std::lround(pixel->x()));
    const int y = static_cast<int>(std::lround(pixel->y()));
    if (x < 0 || y < 0 || x >= view.inner.cols || y >= view.inner.rows ||
        !view.inner.at<std::uint8_t>(y, x))
      continue;
    best = cosine;
    const cv::Vec3b& c = view.image.at<cv::Vec3b>(y, x);
    colour = cv::Vec3f(c[0], c[1], c[2]);
  }
  return colour;
}

// ColourAt at each of `points` (normals `normals`, the reference pass's frame) moved into the
// pass's frame by `table_from_object`.
std::vector<std::optional<cv::Vec3f>> ColoursAt(const std::vector<ColourView>& views,
                                                const std::vector<Eigen::Vector3d>& points,
                                                const std::vector<Eigen::Vector3d>& normals,
                                                const Rigid3d& table_from_object, int threads) {
  std::vector<std::optional<cv::Vec3f>> colours(points.size());
  ParallelFor(points.size(), 256, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      colours[i] =
          ColourAt(views, table_from_object * points[i], table_from_object.rotation * normals[i]);
  });
  return colours;
}

// How well the passes' photos agree in colour at the reference hull's points with the pass
// laid as `table_from_object` says, from the points' colours in the reference's photos
// (`reference`: ColoursAt, unmoved): the Pearson correlation per channel over the points both
// passes see frontally, averaged over the channels (a gain and an offset per pass, the light
// changed with the pose, do not count), and the points it took. -1 when fewer than
// kColourMinPoints.
std::pair<double, int> ColourCorrelation(const std::vector<std::optional<cv::Vec3f>>& reference,
                                         const std::vector<ColourView>& pass,
                                         const std::vector<Eigen::Vector3d>& points,
                                         const std::vector<Eigen::Vector3d>& normals,
                                         const Rigid3d& table_from_object, int threads) {
  const std::vector<std::optional<cv::Vec3f>> moved =
      ColoursAt(pass, points, normals, table_from_object, threads);
  std::vector<cv::Vec3f> a, b;
  std::vector<double> height;
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!reference[i] || !moved[i]) continue;
    // Chromaticity: the light's direction scales a point's channels alike.
    auto chroma = [](const cv::Vec3f& c) { return c / (c[0] + c[1] + c[2] + 30.0f); };
    a.push_back(chroma(*reference[i]));
    b.push_back(chroma(*moved[i]));
    height.push_back(points[i].z());
  }
  const int n = static_cast<int>(a.size());
  if (n < kColourMinPoints) return {-1.0, n};
  // What changes with the height alone (a cap, a band) is the same at every turn about the
  // upright axis: only what is left of each pass's colours at its height is compared.
  const auto [low, high] = std::minmax_element(height.begin(), height.end());
  const double span = std::max(1e-9, *high - *low);
  std::vector<int> bin(n);
  std::vector<cv::Vec3d> mean_a(kColourBins, cv::Vec3d(0, 0, 0)), mean_b = mean_a;
  std::vector<int> count(kColourBins, 0);
  for (int i = 0; i < n; ++i) {
    bin[i] = std::min(kColourBins - 1, static_cast<int>((height[i] - *low) / span * kColourBins));
    mean_a[bin[i]] += cv::Vec3d(a[i]);
    mean_b[bin[i]] += cv::Vec3d(b[i]);
    ++count[bin[i]];
  }
  for (int i = 0; i < n; ++i) {
    a[i] -= cv::Vec3f(mean_a[bin[i]] / count[bin[i]]);
    b[i] -= cv::Vec3f(mean_b[bin[i]] / count[bin[i]]);
  }
  double sum = 0.0;
  for (int ch = 0; ch < 3; ++ch) {
    double ma = 0.0, mb = 0.0;
    for (int i = 0; i < n; ++i) {
      ma += a[i][ch];
      mb += b[i][ch];
    }
    ma /= n;
    mb /= n;
    double sab = 0.0, saa = 0.0, sbb = 0.0;
    for (int i = 0; i < n; ++i) {
      const double da = a[i][ch] - ma, db = b[i][ch] - mb;
      sab += da * db;
      saa += da * da;
      sbb += db * db;
    }
    // A channel without contrast in either pass says nothing.
    sum += saa > 1e-9 && sbb > 1e-9 ? sab / std::sqrt(saa * sbb) : 0.0;
  }
  return {sum / 3.0, n};
}

}  // namespace

double RotationDistanceDeg(const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
  const double c = std::clamp(0.5 * ((a.transpose() * b).trace() - 1.0), -1.0, 1.0);
  return std::acos(c) * 180.0 / std::numbers::pi;
}

const OptionTable<RegistrationOptions>& RegistrationOptions::Fields() {
  using O = RegistrationOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::rotations, {.name = "registration-rotations",
                          .help = "rotations a later pass's coarse search scores",
                          .min = 100,
                          .max = 200000,
                          .advanced = true});
    t.Add(&O::candidates, {.name = "registration-candidates",
                           .help = "distinct coarse poses refined",
                           .min = 1,
                           .max = 64,
                           .advanced = true});
    t.Add(&O::distinct_deg, {.name = "registration-distinct",
                             .help = "poses whose rotations differ by more are distinct",
                             .unit = "deg",
                             .min = 0,
                             .max = 90,
                             .min_exclusive = true,
                             .advanced = true});
    t.Add(&O::ambiguity_ratio,
          {.name = "ambiguity-ratio",
           .help = "a distinct pose whose residual is within this factor of the best's makes a "
                   "pass's pose ambiguous",
           .min = 1,
           .min_exclusive = true,
           .advanced = true});
    t.Add(&O::colour,
          {.name = "pose-by-colour",
           .help = "poses a symmetric product's silhouettes fit alike are told apart by where "
                   "the two passes' photos agree in colour",
           .advanced = true});
    t.Add(&O::max_inconsistent,
          {.name = "max-inconsistent",
           .help = "a pass whose best pose leaves more of the hulls' points outside the other "
                   "pass's silhouettes does not show the same product",
           .min = 0,
           .max = 1,
           .advanced = true});
    t.Add(&O::points, {.name = "registration-points",
                       .help = "surface points per hull at the finest level",
                       .min = 100,
                       .max = 100000,
                       .advanced = true});
    t.Add(&O::max_side_px, {.name = "registration-max-side",
                            .help = "the finest level's masks are at most this long",
                            .unit = "px",
                            .min = 256,
                            .max = 20000,
                            .advanced = true});
    return t;
  }();
  return table;
}

void RegistrationOptions::Validate() const { Fields().Check(*this); }

RegistrationResult RegisterPass(const std::vector<View>& reference, const std::vector<View>& pass,
                                const RegistrationOptions& options, Progress& progress,
                                const std::optional<Rigid3d>& start) {
  options.Validate();
  CAROUSEL_THROW_IF(reference.size() < 2 || pass.size() < 2, InvalidArgument,
                    "registration needs at least 2 views in each pass, got "
                        << reference.size() << " and " << pass.size());
  Stopwatch total;
  RegistrationResult result;
  result.started = start.has_value();
  const int threads = options.threads;

  Stopwatch watch;
  Eigen::AlignedBox3d reference_box, pass_box;
  std::vector<Eigen::Vector3d> reference_normals;
  // The silhouettes, reduced once to the finest level's size.
  const std::vector<View> reference_masks = Reduced(reference, options.max_side_px, threads);
  const std::vector<View> pass_masks = Reduced(pass, options.max_side_px, threads);
  const std::vector<Eigen::Vector3d> reference_points =
      HullPoints(reference_masks, threads, progress, &reference_box, &reference_normals);
  const std::vector<Eigen::Vector3d> pass_points =
      HullPoints(pass_masks, threads, progress, &pass_box);
  result.size_m = reference_box.sizes().norm();
  result.points_reference = static_cast<int>(reference_points.size());
  result.points_pass = static_cast<int>(pass_points.size());
  result.seconds_hulls = watch.ElapsedSeconds();
  const double size = result.size_m;
  const Eigen::Vector3d c1 = Centroid(reference_points), c2 = Centroid(pass_points);

  // Coarse: every sampled rotation, with the centroids laid on each other (or the operator's
  // pose alone).
  watch.Restart();
  const Level coarse = MakeLevel(reference_masks, pass_masks, reference_points, pass_points, 8, 192,
                                 300, 0.08 * size, size, threads);
  std::vector<Pose> candidates;
  if (start) {
    candidates.push_back(Evaluate(coarse, *start, threads));
  } else {
    const std::vector<Eigen::Matrix3d> rotations = SampleRotations(options.rotations);
    std::vector<Pose> scored(rotations.size());
    ParallelFor(rotations.size(), 16, threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        progress.CheckCancelled();
        const Rigid3d pose(rotations[i], c2 - rotations[i] * c1);
        scored[i] = Evaluate(coarse, pose, 1);
      }
    });
    result.rotations_scored = static_cast<int>(rotations.size());
    candidates = Distinct(scored, 20.0, static_cast<std::size_t>(options.candidates));
  }
  result.seconds_search = watch.ElapsedSeconds();

  // Refinement: every candidate at the coarse and the middle level, the best three distinct
  // at the finest.
  watch.Restart();
  const Level middle = MakeLevel(reference_masks, pass_masks, reference_points, pass_points, 12,
                                 480, 1000, 0.03 * size, size, threads);
  for (Pose& candidate : candidates) {
    candidate = Refine(coarse, candidate, c1, 10, threads, progress);
    candidate = Refine(middle, Evaluate(middle, candidate.table_from_object, threads), c1, 10,
                       threads, progress);
  }
  candidates = Distinct(candidates, options.distinct_deg, 3);
  const Level fine =
      MakeLevel(reference_masks, pass_masks, reference_points, pass_points,
                std::numeric_limits<std::size_t>::max(), options.max_side_px,
                static_cast<std::size_t>(options.points), 0.012 * size, size, threads);
  // At the finest level the truncation narrows from 8 to 1.5 pixels: what a hull has too
  // much (the underside its pass did not see) lies further out than that at the right pose,
  // and stops pulling once it is cut off. A candidate that fits clearly worse than the best
  // at 8 pixels is not refined further: its ratio to the best then stays within a few per
  // cent of where the narrower truncations would leave it.
  std::vector<bool> refining(candidates.size(), true);
  for (const double pixels : {8.0, 3.0, 1.5}) {
    const Level narrowed = Narrowed(fine, pixels);
    double best_rms = std::numeric_limits<double>::infinity();
    for (std::size_t k = 0; k < candidates.size(); ++k) {
      if (!refining[k]) continue;
      candidates[k] = Refine(narrowed, Evaluate(narrowed, candidates[k].table_from_object, threads),
                             c1, 12, threads, progress);
      best_rms = std::min(best_rms, candidates[k].rms);
    }
    for (std::size_t k = 0; k < candidates.size(); ++k)
      refining[k] =
          refining[k] && candidates[k].rms < kRefineOnRatio * options.ambiguity_ratio * best_rms;
  }
  for (Pose& candidate : candidates)
    candidate = Evaluate(fine, candidate.table_from_object, threads);
  std::sort(candidates.begin(), candidates.end(),
            [](const Pose& a, const Pose& b) { return a.cost < b.cost; });
  // The runner-up is judged against the best as both were refined alike (wherever it could
  // tie).
  double best_refined_rms = candidates.front().rms;
  // Poses the silhouettes fit alike (a symmetric product): the photos' colours decide, when
  // they agree at one pose clearly better than at every other. A product symmetric about its
  // upright axis (a bottle) fits alike turned about it, so each tied pose is tried turned about
  // the first pass's vertical axis too, wherever the silhouettes still fit. From the
  // operator's pose, only the turns within kColourStartDeg of it are tried.
  struct Tried {
    Rigid3d pose;
    double rms = 0.0;
    double correlation = -1.0;
    Eigen::Vector3d axis = Eigen::Vector3d::Zero();  // the upright axis it was turned about
  };
  std::vector<Tried> tried;
  std::optional<Rigid3d> turn_set;  // a pose whose turn about the upright axis the colours set
  Eigen::Vector3d turn_axis = c1;   // and the axis it is turned about
  {
    std::vector<std::size_t> tied = {0};
    for (std::size_t k = 1; k < candidates.size() && !start; ++k)
      if (candidates[k].rms < options.ambiguity_ratio * best_refined_rms &&
          RotationDistanceDeg(candidates.front().table_from_object.rotation,
                              candidates[k].table_from_object.rotation) >= options.distinct_deg)
        tied.push_back(k);
    if (tied.size() > 1 || (start && options.colour)) {
      Stopwatch colour_watch;
      std::vector<ColourView> pass_colours;
      std::vector<std::optional<cv::Vec3f>> reference_colours;
      std::vector<Eigen::Vector3d> points, normals;
      if (options.colour) {
        pass_colours = ColourViews(pass, pass_masks, threads);
        for (const std::size_t i : Spread(reference_points.size(), 3000)) {
          points.push_back(reference_points[i]);
          normals.push_back(reference_normals[i]);
        }
        reference_colours = ColoursAt(ColourViews(reference, reference_masks, threads), points,
                                      normals, Rigid3d(), threads);
      }
      auto correlation = [&](const Rigid3d& pose) {
        if (!options.colour) return std::pair<double, int>(-1.0, 0);
        const auto found =
            ColourCorrelation(reference_colours, pass_colours, points, normals, pose, threads);
        result.colour_points = std::max(result.colour_points, found.second);
        return found;
      };
      const int first_step = start ? -kColourStartDeg / kColourStepDeg : 0;
      const int last_step = start ? kColourStartDeg / kColourStepDeg : 360 / kColourStepDeg - 1;
      for (const std::size_t k : tied) {
        const Eigen::Vector3d axis =
            UprightAxis(coarse, middle, candidates[k].table_from_object, c1, size,
                        options.ambiguity_ratio, threads, progress);
        for (int step = first_step; step <= last_step; ++step) {
          const Rigid3d pose =
              TurnedAbout(candidates[k].table_from_object, step * kColourStepDeg, axis);
          const double rms = step == 0 ? candidates[k].rms : Evaluate(fine, pose, threads).rms;
          if (rms >= options.ambiguity_ratio * best_refined_rms) continue;
          tried.push_back({pose, rms, correlation(pose).first, axis});
        }
      }
      if (options.colour && !tried.empty()) {
        std::size_t win = 0;
        for (std::size_t t = 1; t < tried.size(); ++t)
          if (tried[t].correlation > tried[win].correlation) win = t;
        double second = -1.0;
        for (const Tried& t : tried)
          if (RotationDistanceDeg(t.pose.rotation, tried[win].pose.rotation) >= kColourDistinctDeg)
            second = std::max(second, t.correlation);
        // Within a step of the winner: by the degree, then the peak of a parabola through the
        // best degree and its neighbours.
        turn_axis = tried[win].axis;
        std::vector<double> by_degree(2 * kColourStepDeg + 1);
        for (int deg = -kColourStepDeg; deg <= kColourStepDeg; ++deg)
          by_degree[deg + kColourStepDeg] =
              deg == 0 ? tried[win].correlation
                       : correlation(TurnedAbout(tried[win].pose, deg, turn_axis)).first;
        const auto peak = static_cast<int>(
            std::max_element(by_degree.begin() + 1, by_degree.end() - 1) - by_degree.begin());
        const double left = by_degree[peak - 1], centre = by_degree[peak],
                     right = by_degree[peak + 1];
        const double curvature = left - 2.0 * centre + right;
        const double offset =
            curvature < 0.0 ? std::clamp(0.5 * (left - right) / curvature, -0.5, 0.5) : 0.0;
        const Rigid3d chosen =
            TurnedAbout(tried[win].pose, peak - kColourStepDeg + offset, turn_axis);
        result.colour_correlation = correlation(chosen).first;
        result.runner_up_colour_correlation = second;
        result.colour_decided = !start && result.colour_correlation >= kColourMinWin &&
                                result.colour_correlation - second >= kColourMinMargin;
        // From the operator's pose the colours place the turn whenever they are known there.
        if (result.colour_decided || (start && result.colour_correlation > -1.0)) {
          // Refined by the silhouettes from there, ahead of the poses it was chosen over. Where
          // the silhouettes fit the pose turned a little either way too (a bottle), they cannot
          // tell its turn, and their residual's slight slope would carry it off: the turn stays
          // the colours'.
          const double chosen_rms = Evaluate(fine, chosen, threads).rms;
          bool free_turn = true;
          for (const double deg : {-10.0, 10.0})
            free_turn =
                free_turn && Evaluate(fine, TurnedAbout(chosen, deg, turn_axis), threads).rms <
                                 options.ambiguity_ratio * chosen_rms;
          if (free_turn) turn_set = chosen;
          Pose pose = Evaluate(fine, chosen, threads);
          for (const double pixels : {3.0, 1.5}) {
            const Level narrowed = Narrowed(fine, pixels);
            pose = Refine(narrowed, Evaluate(narrowed, pose.table_from_object, threads), c1, 12,
                          threads, progress);
          }
          pose = Evaluate(fine,
                          turn_set ? WithTurnOf(pose.table_from_object, *turn_set, turn_axis)
                                   : pose.table_from_object,
                          threads);
          // A pose the colours chose that the silhouettes fit clearly worse than their best is
          // not taken: the pass stays ambiguous, and the operator is asked.
          if (result.colour_decided && pose.rms >= options.ambiguity_ratio * best_refined_rms) {
            result.colour_decided = false;
            turn_set.reset();
          } else {
            candidates.insert(candidates.begin(), pose);
            best_refined_rms = pose.rms;
          }
        }
      }
      result.seconds_colour = colour_watch.ElapsedSeconds();
    }
  }
  // The best: on to the bottom of its flat valley by compass search.
  {
    const Level narrowed = Narrowed(fine, 1.5);
    const double radius = 0.5 * size;
    Pose& best = candidates.front();
    best = CompassSearch(narrowed, Evaluate(narrowed, best.table_from_object, threads), c1,
                         2.0 * fine.pixel_m / radius, 2.0 * fine.pixel_m, 6, threads, progress);
    best = Evaluate(fine,
                    turn_set ? WithTurnOf(best.table_from_object, *turn_set, turn_axis)
                             : best.table_from_object,
                    threads);
  }
  result.seconds_refine = watch.ElapsedSeconds();

  const Pose& best = candidates.front();
  result.table_from_object = best.table_from_object;
  result.residual_m = best.rms;
  // In full-size pixels: the level's pixel at the product, over its scale.
  const double full_pixel_m =
      fine.pixel_m *
      (fine.pass.empty() ? 1.0 : fine.pass.front().camera.fx / pass.front().camera().fx);
  result.residual_px = best.rms / std::max(1e-12, full_pixel_m);
  {
    Level untruncated = fine;
    untruncated.truncation_m = size;
    result.inconsistent_fraction =
        InconsistentFraction(untruncated, best.table_from_object, 3.0 * fine.pixel_m, threads);
  }
  result.matches = result.inconsistent_fraction <= options.max_inconsistent;
  for (std::size_t k = 1; k < candidates.size() && !start; ++k) {
    const double deg = RotationDistanceDeg(best.table_from_object.rotation,
                                           candidates[k].table_from_object.rotation);
    if (deg < options.distinct_deg) continue;
    result.runner_up = candidates[k].table_from_object;
    result.runner_up_deg = deg;
    result.runner_up_ratio = candidates[k].rms / std::max(1e-12, best_refined_rms);
    result.ambiguous = result.runner_up_ratio < options.ambiguity_ratio && !result.colour_decided;
    break;
  }
  if (result.ambiguous) {
    // For the operator: the tied poses, the likeliest first, each at least kColourDistinctDeg
    // from every one before.
    std::stable_sort(tried.begin(), tried.end(), [](const Tried& a, const Tried& b) {
      return a.correlation != b.correlation ? a.correlation > b.correlation : a.rms < b.rms;
    });
    if (tried.empty()) tried.push_back({best.table_from_object, best.rms, -1.0, c1});
    for (const Tried& t : tried) {
      if (static_cast<int>(result.alternatives.size()) >= kMaxAlternatives) break;
      const bool near = std::any_of(
          result.alternatives.begin(), result.alternatives.end(), [&](const PoseAlternative& a) {
            return RotationDistanceDeg(a.table_from_object.rotation, t.pose.rotation) <
                   kColourDistinctDeg;
          });
      if (!near)
        result.alternatives.push_back(
            {t.pose, t.rms / std::max(1e-12, best_refined_rms), t.correlation});
    }
  }
  result.seconds_total = total.ElapsedSeconds();
  return result;
}

std::vector<cv::Mat> PosePreviews(const std::vector<View>& reference, const std::vector<View>& pass,
                                  const std::vector<Rigid3d>& poses, int side, int threads,
                                  Progress& progress) {
  CAROUSEL_THROW_IF(reference.size() < 2 || pass.size() < 2, InvalidArgument,
                    "pose pictures need at least 2 views in each pass, got "
                        << reference.size() << " and " << pass.size());
  CAROUSEL_THROW_IF(side < 64, InvalidArgument, "pose pictures of " << side << " px: at least 64");
  const Mesh hull =
      PassHull(Reduced(reference, RegistrationOptions().max_side_px, threads), threads, progress);
  std::vector<Eigen::Vector3d> positions;
  positions.reserve(hull.n_vertices());
  for (const auto vertex : hull.vertices()) {
    const auto& p = hull.point(vertex);
    positions.emplace_back(p[0], p[1], p[2]);
  }
  std::vector<Eigen::Vector3i> triangles;
  std::vector<Eigen::Vector3d> face_normals;
  for (const auto face : hull.faces()) {
    Eigen::Vector3i t;
    int corner = 0;
    for (const auto vertex : hull.fv_range(face)) t[corner++] = vertex.idx();
    const Eigen::Vector3d n =
        (positions[t[1]] - positions[t[0]]).cross(positions[t[2]] - positions[t[0]]);
    triangles.push_back(t);
    face_normals.push_back(n.norm() > 0.0 ? Eigen::Vector3d(n.normalized()) : n);
  }
  // Two photos of the reference from opposite sides, at four times the pictures' detail: each
  // picture shows the product's box, enlarged.
  const int detail = 4 * side;
  const std::vector<View> shown_views = {reference.front(), reference[reference.size() / 2]};
  const std::vector<ColourView> shown = ColourViews(shown_views, shown_views, threads, detail);
  const std::vector<ColourView> pass_colours = ColourViews(pass, pass, threads, detail);
  // Per shown photo, the product's box in it, and the hull's surface point and normal under
  // each pixel of the box (none: NaN).
  struct Surface {
    cv::Rect box;
    cv::Mat point, normal;  // CV_64FC3, the box's size
  };
  std::vector<Surface> surfaces;
  for (const ColourView& view : shown) {
    progress.CheckCancelled();
    Eigen::AlignedBox2d bounds;
    for (const Eigen::Vector3d& p : positions)
      if (const auto pixel = view.camera.Project(p)) bounds.extend(*pixel);
    cv::Rect box(0, 0, view.image.cols, view.image.rows);
    if (!bounds.isEmpty()) {
      const double margin = 0.08 * bounds.sizes().maxCoeff() + 2.0;
      box &= cv::Rect(cv::Point(static_cast<int>(std::floor(bounds.min().x() - margin)),
                                static_cast<int>(std::floor(bounds.min().y() - margin))),
                      cv::Point(static_cast<int>(std::ceil(bounds.max().x() + margin)),
                                static_cast<int>(std::ceil(bounds.max().y() + margin))));
    }
    if (box.empty()) box = cv::Rect(0, 0, view.image.cols, view.image.rows);
    MeshRasterOptions raster_options;
    raster_options.threads = threads;
    const MeshRaster raster = RasterizeMesh(positions, triangles, view.camera, raster_options);
    Surface surface{box, cv::Mat(box.size(), CV_64FC3, cv::Scalar::all(std::nan(""))),
                    cv::Mat(box.size(), CV_64FC3, cv::Scalar::all(0.0))};
    const cv::Mat ids = raster.FaceIds();
    for (int y = box.y; y < box.y + box.height; ++y) {
      for (int x = box.x; x < box.x + box.width; ++x) {
        const int face = ids.at<int>(y, x);
        if (face < 0) continue;
        for (const RasterFragment& f : raster.Fragments(x, y)) {
          if (f.face != face) continue;
          const Eigen::Vector3i& t = triangles[static_cast<std::size_t>(face)];
          const Eigen::Vector3d point = f.barycentric.x() * positions[t[0]] +
                                        f.barycentric.y() * positions[t[1]] +
                                        f.barycentric.z() * positions[t[2]];
          const Eigen::Vector3d& n = face_normals[static_cast<std::size_t>(face)];
          surface.point.at<cv::Vec3d>(y - box.y, x - box.x) =
              cv::Vec3d(point.x(), point.y(), point.z());
          surface.normal.at<cv::Vec3d>(y - box.y, x - box.x) = cv::Vec3d(n.x(), n.y(), n.z());
          break;
        }
      }
    }
    surfaces.push_back(surface);
  }
  // An image fitted into a side x side tile (the off-hull grey around it).
  auto tile = [side](const cv::Mat& image) {
    cv::Mat out(side, side, CV_8UC3, cv::Scalar::all(48));
    const double scale = static_cast<double>(side) / std::max(image.cols, image.rows);
    const cv::Size size(std::clamp(static_cast<int>(std::lround(image.cols * scale)), 1, side),
                        std::clamp(static_cast<int>(std::lround(image.rows * scale)), 1, side));
    cv::Mat resized;
    cv::resize(image, resized, size, 0, 0, scale < 1.0 ? cv::INTER_AREA : cv::INTER_LINEAR);
    resized.copyTo(
        out(cv::Rect((side - size.width) / 2, (side - size.height) / 2, size.width, size.height)));
    return out;
  };
  std::vector<cv::Mat> previews(poses.size());
  ParallelFor(poses.size(), 1, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t k = begin; k < end; ++k) {
      std::vector<cv::Mat> rows;
      for (std::size_t v = 0; v < shown.size(); ++v) {
        const Surface& surface = surfaces[v];
        cv::Mat laid(surface.box.size(), CV_8UC3, cv::Scalar::all(48));
        for (int y = 0; y < laid.rows; ++y) {
          for (int x = 0; x < laid.cols; ++x) {
            const cv::Vec3d& p = surface.point.at<cv::Vec3d>(y, x);
            if (std::isnan(p[0])) continue;
            const cv::Vec3d& n = surface.normal.at<cv::Vec3d>(y, x);
            const auto colour = ColourAt(pass_colours, poses[k] * Eigen::Vector3d(p[0], p[1], p[2]),
                                         poses[k].rotation * Eigen::Vector3d(n[0], n[1], n[2]));
            cv::Vec3b& out = laid.at<cv::Vec3b>(y, x);
            out = cv::Vec3b(96, 96, 96);
            if (colour)
              for (int c = 0; c < 3; ++c) out[c] = cv::saturate_cast<std::uint8_t>((*colour)[c]);
          }
        }
        cv::Mat row;
        cv::hconcat(tile(shown[v].image(surface.box)), tile(laid), row);
        rows.push_back(row);
      }
      cv::vconcat(rows, previews[k]);
    }
  });
  return previews;
}

}  // namespace carousel::recon
