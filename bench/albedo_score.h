// A textured model scored against the true albedo of what was photographed: issue 26's
// "gain-compensated PSNR vs the true albedo", shared by the blob scene (blob_scene.h) and the
// paper's case on the simulator's products (texture_bench --faces).
//
// Colours are sRGB BGR 0..255, as an unlit photo of the albedo shows them. One least-squares
// gain per channel is fitted before the error is taken: the photos' common level (exposure,
// white balance) is arbitrary and not what the texture is judged on.
#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "carousel/core/mesh.h"
#include "carousel/sim/scene.h"

namespace carousel::bench {

// Accumulates pairs (ours, truth) and gives the PSNR after the per-channel gain.
class GainCompensatedPsnr {
 public:
  void Add(const cv::Vec3d& ours, const cv::Vec3d& truth);
  std::size_t count() const { return count_; }
  // 10 log10(255^2 / MSE) with MSE over all channels of all pairs; \pre count() > 0.
  double Db() const;

 private:
  double ours_truth_[3] = {0, 0, 0}, ours_ours_[3] = {0, 0, 0}, truth_truth_[3] = {0, 0, 0};
  std::size_t count_ = 0;
};

// The atlas `texture` (8-bit BGR) at `uv` (our meshes' convention: v up), bilinear.
cv::Vec3d SampleAtlas(const cv::Mat& texture, const Eigen::Vector2d& uv);

// A face's corners and UVs (corner k at its k-th halfedge's target).
void FaceCorners(const Mesh& mesh, Mesh::FaceHandle f, std::array<Eigen::Vector3d, 3>* p,
                 std::array<Eigen::Vector2d, 3>* uv);

// The colour of `scene`'s triangle at barycentrics `b` as an unlit photo at exposure 1 shows
// it: the material's base colour times its texture (bilinear at full size), encoded as sRGB.
cv::Vec3d TrueColour(const sim::Scene& scene, std::size_t triangle, const Eigen::Vector3d& b);

// A point of a scene's surface: where it is, its triangle's outward unit normal, the triangle
// and the point's barycentrics in it.
struct SurfacePoint {
  Eigen::Vector3d point, normal;
  std::size_t triangle = 0;
  Eigen::Vector3d barycentrics;
};

// `count` points spread over `scene`'s surface with probability proportional to area; the
// same for a given seed.
std::vector<SurfacePoint> SampleScene(const sim::Scene& scene, int count, std::uint64_t seed);

struct SurfaceScore {
  double psnr_db = 0.0;
  std::size_t points = 0;
  double mean_distance_mm = 0.0;  // from the true surface to the model
  double p95_distance_mm = 0.0;
  // The same score over the points at a distance from the model in [from, to) mm: where the
  // geometry is off, a photo's colour lands beside the point it belongs to.
  struct Band {
    double from_mm = 0.0, to_mm = 0.0;
    std::size_t points = 0;
    double psnr_db = 0.0;
    double reference_db = 0.0;  // of the reference colours at the same points, if given
  };
  std::vector<Band> bands;
  double worst_percent_error_share = 0.0;  // of the squared error, in the worst 1 % of points
};

// Each of `points` (of `truth`'s surface) is matched to the closest point of `model` (with
// UVs) on a face turned the same way (among those within 0.5 mm of the closest), whose
// `texture` is sampled there and compared with the true colour. `reference`, if given, holds
// one colour per point (e.g. the photos' own), scored by band beside the model.
// \throw InvalidArgument if the model has no UVs, `points` is empty or `reference` is not one
// colour per point.
SurfaceScore ScoreAgainstScene(const sim::Scene& truth, const std::vector<SurfacePoint>& points,
                               const Mesh& model, const cv::Mat& texture,
                               const std::vector<cv::Vec3d>* reference = nullptr);

}  // namespace carousel::bench
