// Per-view colour gains of TransferTexture (texture_map.h): exposure and white balance that
// differ between photos evened out, so that seams between front images do not show.
//
// A face usable in several views gives one observation per view: the log of its mean colour
// there (over the face's sample points). Left out: faces nearly black or saturated in a view,
// and faces on an edge of the texture there (their samples disagree: a boundary a little
// misplaced by the geometry or the registration puts another colour under them in some views
// and not in others). The log colour is modelled as the face's true log colour plus the view's
// log gain and solved by alternating least squares (true colours given the gains, gains given
// the true colours, the gains' mean fixed at 0), weighted per channel by the inverse variance
// of a log (a dark channel's log is noisy) and, after the first rounds, by Huber weights on the
// residuals, so that faces whose colour changes between views for other reasons (a highlight,
// a shadow, light that a second pass lays differently) do not drag whole views along.
#include <algorithm>
#include <cmath>

#include "texture_map_steps.h"

namespace carousel::texture::internal {
namespace {

struct Observation {
  int face, view;
  cv::Vec3d log_colour;
  cv::Vec3d weight;  // per channel: 1 / the log's variance, relative
};

// A face's samples in one view that differ by more than this (relative to their mean
// brightness, plus a little for noise) lie across an edge of the texture.
constexpr double kEdgeSpread = 0.2;
constexpr double kNoiseLevels = 8.0;
// Huber's threshold on log residuals (about 5 %).
constexpr double kHuberDelta = 0.05;

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
      double low = 1e9, high = -1e9;
      int n = 0;
      for (const auto& b : kSamples) {
        cv::Vec3d c;
        if (sampler.Sample(v, At(faces[f], b), &c)) {
          sum += c;
          const double brightness = c[0] + c[1] + c[2];
          low = std::min(low, brightness);
          high = std::max(high, brightness);
          ++n;
        }
      }
      if (n == 0) continue;
      sum /= n;
      if (std::min({sum[0], sum[1], sum[2]}) < 12.0 || std::max({sum[0], sum[1], sum[2]}) > 243.0)
        continue;
      if (high - low > kEdgeSpread * (sum[0] + sum[1] + sum[2]) + 3.0 * kNoiseLevels) continue;
      Observation o{static_cast<int>(f),
                    v,
                    cv::Vec3d(std::log(sum[0]), std::log(sum[1]), std::log(sum[2])),
                    {}};
      for (int k = 0; k < 3; ++k) o.weight[k] = (sum[k] / 128.0) * (sum[k] / 128.0);
      observations.push_back(o);
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
  std::vector<cv::Vec3d> robust(observations.size(), cv::Vec3d(1, 1, 1));
  // Per face (true colours given the gains) or per view (gains given the true colours): the
  // weighted mean of the observations' log colours less the other term.
  const auto weighted_means = [&](bool per_face, std::size_t n, std::vector<cv::Vec3d>* means,
                                  std::vector<cv::Vec3d>* weights) {
    std::vector<cv::Vec3d> sum(n, cv::Vec3d(0, 0, 0));
    weights->assign(n, cv::Vec3d(0, 0, 0));
    for (std::size_t i = 0; i < observations.size(); ++i) {
      const Observation& o = observations[i];
      const int at = per_face ? o.face : o.view;
      const cv::Vec3d& other = per_face ? log_gain[o.view] : log_true[o.face];
      for (int k = 0; k < 3; ++k) {
        const double w = o.weight[k] * robust[i][k];
        sum[at][k] += w * (o.log_colour[k] - other[k]);
        (*weights)[at][k] += w;
      }
    }
    for (std::size_t j = 0; j < n; ++j)
      for (int k = 0; k < 3; ++k)
        if ((*weights)[j][k] > 0) (*means)[j][k] = sum[j][k] / (*weights)[j][k];
  };
  for (int iteration = 0; iteration < 30 && !observations.empty(); ++iteration) {
    // Huber weights from the residuals once the first rounds have settled the solution.
    if (iteration >= 5)
      for (std::size_t i = 0; i < observations.size(); ++i) {
        const Observation& o = observations[i];
        for (int k = 0; k < 3; ++k) {
          const double r = std::abs(o.log_colour[k] - log_true[o.face][k] - log_gain[o.view][k]);
          robust[i][k] = r <= kHuberDelta ? 1.0 : kHuberDelta / r;
        }
      }
    std::vector<cv::Vec3d> w_f, w_v;
    weighted_means(true, nf, &log_true, &w_f);
    weighted_means(false, static_cast<std::size_t>(nv), &log_gain, &w_v);
    cv::Vec3d mean(0, 0, 0);
    int used = 0;
    for (int v = 0; v < nv; ++v)
      if (w_v[v][0] > 0 && w_v[v][1] > 0 && w_v[v][2] > 0) {
        mean += log_gain[v];
        ++used;
      }
    if (used > 0) mean /= used;
    for (int v = 0; v < nv; ++v)
      if (w_v[v][0] > 0 && w_v[v][1] > 0 && w_v[v][2] > 0) log_gain[v] -= mean;
  }
  // Colours are divided by the view's gain to bring every view to the common level.
  std::vector<cv::Vec3d> gains(nv, cv::Vec3d(1, 1, 1));
  for (int v = 0; v < nv; ++v)
    for (int k = 0; k < 3; ++k) gains[v][k] = std::exp(-log_gain[v][k]);
  return gains;
}

}  // namespace carousel::texture::internal
