#include "albedo_score.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/mesh_query.h"

namespace carousel::bench {
namespace {

double SrgbToLinear(double c) {
  return c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4);
}
double LinearToSrgb(double c) {
  return c <= 0.0031308 ? 12.92 * c : 1.055 * std::pow(c, 1.0 / 2.4) - 0.055;
}

// Barycentrics of `p` (in the triangle's plane) with respect to (a, b, c).
Eigen::Vector3d Barycentrics(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                             const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d e0 = b - a, e1 = c - a, d = p - a;
  const double d00 = e0.dot(e0), d01 = e0.dot(e1), d11 = e1.dot(e1);
  const double d20 = d.dot(e0), d21 = d.dot(e1);
  const double det = d00 * d11 - d01 * d01;
  if (!(std::abs(det) > 0.0)) return {1.0, 0.0, 0.0};  // degenerate: its first corner
  const double v = (d11 * d20 - d01 * d21) / det;
  const double w = (d00 * d21 - d01 * d20) / det;
  return {1.0 - v - w, v, w};
}

}  // namespace

void GainCompensatedPsnr::Add(const cv::Vec3d& ours, const cv::Vec3d& truth) {
  for (int k = 0; k < 3; ++k) {
    ours_truth_[k] += ours[k] * truth[k];
    ours_ours_[k] += ours[k] * ours[k];
    truth_truth_[k] += truth[k] * truth[k];
  }
  ++count_;
}

double GainCompensatedPsnr::Db() const {
  // Per channel, min over g of sum (g ours - truth)^2 = tt - ot^2 / oo.
  double sse = 0.0;
  for (int k = 0; k < 3; ++k) {
    sse += truth_truth_[k] -
           (ours_ours_[k] > 0.0 ? ours_truth_[k] * ours_truth_[k] / ours_ours_[k] : 0.0);
  }
  const double mse =
      std::max(sse / (3.0 * static_cast<double>(std::max<std::size_t>(count_, 1))), 1e-10);
  return 10.0 * std::log10(255.0 * 255.0 / mse);
}

cv::Vec3d SampleAtlas(const cv::Mat& texture, const Eigen::Vector2d& uv) {
  cv::Mat pixel;
  cv::getRectSubPix(texture, {1, 1},
                    cv::Point2f(static_cast<float>(uv.x() * texture.cols - 0.5),
                                static_cast<float>((1.0 - uv.y()) * texture.rows - 0.5)),
                    pixel, CV_32F);
  const cv::Vec3f value = pixel.at<cv::Vec3f>(0, 0);
  return {value[0], value[1], value[2]};
}

void FaceCorners(const Mesh& mesh, Mesh::FaceHandle f, std::array<Eigen::Vector3d, 3>* p,
                 std::array<Eigen::Vector2d, 3>* uv) {
  int k = 0;
  for (const auto h : mesh.fh_range(f)) {
    if (k == 3) break;
    const auto& q = mesh.point(mesh.to_vertex_handle(h));
    (*p)[k] = Eigen::Vector3d(q[0], q[1], q[2]);
    const auto t = mesh.uv(h);
    (*uv)[k] = Eigen::Vector2d(t[0], t[1]);
    ++k;
  }
}

cv::Vec3d TrueColour(const sim::Scene& scene, std::size_t triangle, const Eigen::Vector3d& b) {
  const sim::Material& material =
      scene.materials[static_cast<std::size_t>(scene.triangle_material[triangle])];
  Eigen::Vector3d linear = material.base_color.cast<double>();  // RGB
  if (material.texture >= 0) {
    const cv::Mat& image =
        scene.textures[static_cast<std::size_t>(material.texture)]->levels().front();
    const Eigen::Vector3i& t = scene.triangles[triangle];
    Eigen::Vector2d uv = Eigen::Vector2d::Zero();
    for (int k = 0; k < 3; ++k)
      uv += b[k] * scene.uvs[static_cast<std::size_t>(t[k])].cast<double>();
    // Image convention, repeated; texel centres at (i + 0.5) / size.
    const double x = (uv.x() - std::floor(uv.x())) * image.cols - 0.5;
    const double y = (uv.y() - std::floor(uv.y())) * image.rows - 0.5;
    const double fx = std::floor(x), fy = std::floor(y);
    const double ax = x - fx, ay = y - fy;
    auto wrap = [](int i, int n) { return ((i % n) + n) % n; };
    const int x0 = wrap(static_cast<int>(fx), image.cols), x1 = wrap(x0 + 1, image.cols);
    const int y0 = wrap(static_cast<int>(fy), image.rows), y1 = wrap(y0 + 1, image.rows);
    auto texel = [&](int tx, int ty) {
      const cv::Vec3b& p = image.at<cv::Vec3b>(ty, tx);
      return Eigen::Vector3d(SrgbToLinear(p[2] / 255.0), SrgbToLinear(p[1] / 255.0),
                             SrgbToLinear(p[0] / 255.0));
    };
    const Eigen::Vector3d sampled = (1 - ay) * ((1 - ax) * texel(x0, y0) + ax * texel(x1, y0)) +
                                    ay * ((1 - ax) * texel(x0, y1) + ax * texel(x1, y1));
    linear = linear.cwiseProduct(sampled);
  }
  cv::Vec3d bgr;
  for (int c = 0; c < 3; ++c) bgr[2 - c] = 255.0 * LinearToSrgb(std::clamp(linear[c], 0.0, 1.0));
  return bgr;
}

std::vector<SurfacePoint> SampleScene(const sim::Scene& scene, int count, std::uint64_t seed) {
  std::vector<double> cumulative;
  std::vector<Eigen::Vector3d> normals;
  double total = 0.0;
  for (const Eigen::Vector3i& t : scene.triangles) {
    const Eigen::Vector3d& a = scene.positions[static_cast<std::size_t>(t[0])];
    const Eigen::Vector3d& b = scene.positions[static_cast<std::size_t>(t[1])];
    const Eigen::Vector3d& c = scene.positions[static_cast<std::size_t>(t[2])];
    const Eigen::Vector3d n = (b - a).cross(c - a);
    total += 0.5 * n.norm();
    cumulative.push_back(total);
    normals.push_back(n.normalized());
  }
  std::mt19937_64 random(seed);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::vector<SurfacePoint> points;
  points.reserve(static_cast<std::size_t>(std::max(count, 0)));
  for (int i = 0; i < count; ++i) {
    const double pick = uniform(random) * total;
    SurfacePoint p;
    p.triangle = static_cast<std::size_t>(std::min<std::ptrdiff_t>(
        std::lower_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin(),
        static_cast<std::ptrdiff_t>(cumulative.size()) - 1));
    const double r1 = std::sqrt(uniform(random)), r2 = uniform(random);  // uniform in it
    p.barycentrics = Eigen::Vector3d(1.0 - r1, r1 * (1.0 - r2), r1 * r2);
    const Eigen::Vector3i& corner = scene.triangles[p.triangle];
    p.point = Eigen::Vector3d::Zero();
    for (int k = 0; k < 3; ++k) {
      p.point += p.barycentrics[k] * scene.positions[static_cast<std::size_t>(corner[k])];
    }
    p.normal = normals[p.triangle];
    points.push_back(p);
  }
  return points;
}

SurfaceScore ScoreAgainstScene(const sim::Scene& truth, const std::vector<SurfacePoint>& points,
                               const Mesh& model, const cv::Mat& texture,
                               const std::vector<cv::Vec3d>* reference) {
  CAROUSEL_THROW_IF(!model.has_uvs(), InvalidArgument, "the model to score has no UVs");
  CAROUSEL_THROW_IF(points.empty(), InvalidArgument, "no point of the true surface to score");
  CAROUSEL_THROW_IF(reference != nullptr && reference->size() != points.size(), InvalidArgument,
                    "not one reference colour per point");
  std::vector<TriangleTree::Triangle> triangles;
  std::vector<std::array<Eigen::Vector2d, 3>> uvs;
  for (const auto f : model.faces()) {
    std::array<Eigen::Vector3d, 3> p;
    std::array<Eigen::Vector2d, 3> uv;
    FaceCorners(model, f, &p, &uv);
    triangles.push_back({p[0], p[1], p[2]});
    uvs.push_back(uv);
  }
  const TriangleTree tree(triangles);
  constexpr double kSideTolerance = 5e-4;  // metres
  GainCompensatedPsnr psnr;
  const std::vector<double> band_edges = {0.0, 0.05, 0.1, 0.2, 0.4, 0.8, 1e9};  // mm
  std::vector<GainCompensatedPsnr> band_psnr(band_edges.size() - 1),
      band_reference(band_edges.size() - 1);
  std::vector<double> distances, errors;
  std::vector<std::size_t> candidates;
  for (std::size_t i = 0; i < points.size(); ++i) {
    const SurfacePoint& point = points[i];
    TriangleTree::Hit hit = tree.ClosestPoint(point.point);
    // A thin shell's two sides (or a sheet modelled twice, once per side) are both about as
    // close: the side facing the way the true surface does is the one seen with it.
    const double reach = hit.distance + kSideTolerance;
    candidates.clear();
    tree.Overlapping(Eigen::AlignedBox3d(point.point - Eigen::Vector3d::Constant(reach),
                                         point.point + Eigen::Vector3d::Constant(reach)),
                     &candidates);
    double best = std::numeric_limits<double>::infinity();
    for (const std::size_t c : candidates) {
      const TriangleTree::Triangle& q = tree.triangles()[c];
      if ((q.b - q.a).cross(q.c - q.a).dot(point.normal) <= 0.0) continue;
      const Eigen::Vector3d on = ClosestPointOnTriangle(point.point, q.a, q.b, q.c);
      const double distance = (on - point.point).norm();
      if (distance <= reach && distance < best) {
        best = distance;
        hit = {on, distance, c};
      }
    }
    const TriangleTree::Triangle& on = tree.triangles()[hit.triangle];
    const Eigen::Vector3d w = Barycentrics(hit.point, on.a, on.b, on.c);
    const auto& uv = uvs[hit.triangle];
    const cv::Vec3d ours = SampleAtlas(texture, w[0] * uv[0] + w[1] * uv[1] + w[2] * uv[2]);
    const cv::Vec3d expected = TrueColour(truth, point.triangle, point.barycentrics);
    psnr.Add(ours, expected);
    const double mm = 1000.0 * hit.distance;
    for (std::size_t b = 0; b + 1 < band_edges.size(); ++b) {
      if (mm < band_edges[b] || mm >= band_edges[b + 1]) continue;
      band_psnr[b].Add(ours, expected);
      if (reference != nullptr) band_reference[b].Add((*reference)[i], expected);
    }
    errors.push_back(cv::norm(ours - expected, cv::NORM_L2SQR));
    distances.push_back(hit.distance);
  }
  SurfaceScore score;
  score.points = distances.size();
  score.psnr_db = psnr.Db();
  for (std::size_t b = 0; b < band_psnr.size(); ++b) {
    if (band_psnr[b].count() == 0) continue;
    score.bands.push_back({band_edges[b], band_edges[b + 1], band_psnr[b].count(),
                           band_psnr[b].Db(),
                           band_reference[b].count() > 0 ? band_reference[b].Db() : 0.0});
  }
  double total_error = 0.0;
  for (const double e : errors) total_error += e;
  const std::size_t worst = std::max<std::size_t>(errors.size() / 100, 1);
  std::nth_element(errors.begin(), errors.begin() + static_cast<std::ptrdiff_t>(worst),
                   errors.end(), std::greater<>());
  double worst_error = 0.0;
  for (std::size_t i = 0; i < worst; ++i) worst_error += errors[i];
  score.worst_percent_error_share = total_error > 0.0 ? worst_error / total_error : 0.0;
  double sum = 0.0;
  for (const double d : distances) sum += d;
  score.mean_distance_mm = 1000.0 * sum / static_cast<double>(distances.size());
  const std::size_t p95 = distances.size() * 95 / 100;
  std::nth_element(distances.begin(), distances.begin() + static_cast<std::ptrdiff_t>(p95),
                   distances.end());
  score.p95_distance_mm = 1000.0 * distances[p95];
  return score;
}

}  // namespace carousel::bench
