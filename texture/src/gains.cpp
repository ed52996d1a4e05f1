// Per-view colour gains of TransferTexture (texture_map.h): exposure and white balance that
// differ between photos evened out, so that seams between front images do not show.
//
// A face usable in several views gives one observation per view: the log of its mean colour
// there (over the face's sample points; faces nearly black or saturated in a view are left
// out). The log colour is modelled as the face's true log colour plus the view's log gain;
// alternating least squares (true colours given the gains, gains given the true colours, the
// gains' mean fixed at 0) runs 20 rounds.
#include <algorithm>
#include <cmath>

#include "texture_map_steps.h"

namespace carousel::texture::internal {
namespace {

struct Observation {
  int face, view;
  cv::Vec3d log_colour;
};

std::vector<Observation> ObserveFaces(const std::vector<FaceData>& faces,
                                      const GroupingResult& grouping, const ViewSampler& sampler) {
  const std::size_t nf = faces.size();
  const int nv = grouping.views;
  std::vector<Observation> observations;
  for (std::size_t f = 0; f < nf; ++f) {
    int count = 0;
    for (int v = 0; v < nv; ++v) count += grouping.usable[f * nv + v];
    if (count < 2) continue;
    for (int v = 0; v < nv; ++v) {
      if (!grouping.usable[f * nv + v]) continue;
      cv::Vec3d sum(0, 0, 0);
      int n = 0;
      for (const auto& b : kSamples) {
        cv::Vec3d c;
        if (sampler.Sample(v, At(faces[f], b), &c)) {
          sum += c;
          ++n;
        }
      }
      if (n == 0) continue;
      sum /= n;
      if (std::min({sum[0], sum[1], sum[2]}) < 12.0 || std::max({sum[0], sum[1], sum[2]}) > 243.0)
        continue;
      observations.push_back({static_cast<int>(f), v,
                              cv::Vec3d(std::log(sum[0]), std::log(sum[1]), std::log(sum[2]))});
    }
  }
  return observations;
}

}  // namespace

std::vector<cv::Vec3d> EstimateGains(const std::vector<FaceData>& faces,
                                     const GroupingResult& grouping, const ViewSampler& sampler) {
  const std::size_t nf = faces.size();
  const int nv = grouping.views;
  const std::vector<Observation> observations = ObserveFaces(faces, grouping, sampler);
  std::vector<cv::Vec3d> log_gain(nv, cv::Vec3d(0, 0, 0));
  std::vector<cv::Vec3d> log_true(nf, cv::Vec3d(0, 0, 0));
  for (int iteration = 0; iteration < 20 && !observations.empty(); ++iteration) {
    std::vector<cv::Vec3d> sum_f(nf, cv::Vec3d(0, 0, 0));
    std::vector<int> n_f(nf, 0);
    for (const auto& o : observations) {
      sum_f[o.face] += o.log_colour - log_gain[o.view];
      ++n_f[o.face];
    }
    for (std::size_t f = 0; f < nf; ++f)
      if (n_f[f] > 0) log_true[f] = sum_f[f] / n_f[f];
    std::vector<cv::Vec3d> sum_v(nv, cv::Vec3d(0, 0, 0));
    std::vector<int> n_v(nv, 0);
    for (const auto& o : observations) {
      sum_v[o.view] += o.log_colour - log_true[o.face];
      ++n_v[o.view];
    }
    cv::Vec3d mean(0, 0, 0);
    int used = 0;
    for (int v = 0; v < nv; ++v)
      if (n_v[v] > 0) {
        log_gain[v] = sum_v[v] / n_v[v];
        mean += log_gain[v];
        ++used;
      }
    if (used > 0) mean /= used;
    for (int v = 0; v < nv; ++v)
      if (n_v[v] > 0) log_gain[v] -= mean;
  }
  // Colours are divided by the view's gain to bring every view to the common level.
  std::vector<cv::Vec3d> gains(nv, cv::Vec3d(1, 1, 1));
  for (int v = 0; v < nv; ++v)
    for (int k = 0; k < 3; ++k) gains[v][k] = std::exp(-log_gain[v][k]);
  return gains;
}

}  // namespace carousel::texture::internal
