#include "carousel/texture/quality_report.h"

#include <algorithm>
#include <array>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"

namespace carousel::texture {

std::vector<int> DefaultTexelHistogramEdges() { return {0, 1, 11, 51, 101, 501, 1001, 5001}; }

TexelHistogram FacesByTexels(const std::vector<int>& texels_per_face,
                             const std::vector<int>& edges) {
  CAROUSEL_THROW_IF(edges.empty() || edges[0] != 0, InvalidArgument,
                    "FacesByTexels: the bin edges must start at 0");
  for (std::size_t i = 1; i < edges.size(); ++i)
    CAROUSEL_THROW_IF(edges[i] <= edges[i - 1], InvalidArgument,
                      "FacesByTexels: the bin edges must increase strictly");
  TexelHistogram histogram{edges, std::vector<int>(edges.size(), 0)};
  for (const int texels : texels_per_face) {
    const auto bin = std::upper_bound(edges.begin(), edges.end(), texels) - edges.begin() - 1;
    ++histogram.counts[std::max<std::ptrdiff_t>(bin, 0)];
  }
  return histogram;
}

cv::Mat PlotTexelHistogram(const TexelHistogram& histogram, int atlas_size) {
  const std::vector<int>& edges = histogram.edges;
  const std::vector<int>& counts = histogram.counts;
  CAROUSEL_THROW_IF(counts.empty() || counts.size() != edges.size(), InvalidArgument,
                    "PlotTexelHistogram: one count per bin edge is needed");
  const int width = 900, height = 420, left = 70, bottom = 70, top = 50;
  cv::Mat plot(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  const int peak = std::max(1, *std::max_element(counts.begin(), counts.end()));
  const int bars = static_cast<int>(counts.size());
  const double bar_width = static_cast<double>(width - left - 20) / bars;
  // OpenCV's Hershey fonts have no '^': the size is written out.
  const std::string side = std::to_string(atlas_size);
  cv::putText(plot, "faces by texels per face (" + side + " x " + side + " atlas)", {left, 30},
              cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  for (int i = 0; i < bars; ++i) {
    const int h = static_cast<int>((height - top - bottom) * static_cast<double>(counts[i]) / peak);
    const int x0 = left + static_cast<int>(i * bar_width) + 2;
    const int x1 = left + static_cast<int>((i + 1) * bar_width) - 2;
    cv::rectangle(plot, {x0, height - bottom - h}, {x1, height - bottom}, cv::Scalar(180, 110, 40),
                  cv::FILLED);
    cv::putText(plot, std::to_string(counts[i]), {x0, height - bottom - h - 5},
                cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    const std::string label =
        i + 1 < bars ? std::to_string(edges[i]) + "-" + std::to_string(edges[i + 1] - 1)
                     : ">=" + std::to_string(edges[i]);
    cv::putText(plot, label, {x0, height - bottom + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.35,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  cv::line(plot, {left, height - bottom}, {width - 10, height - bottom}, cv::Scalar(0, 0, 0));
  cv::putText(plot, "texels per face", {width / 2 - 60, height - 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return plot;
}

QualityReport SummarizeTexture(const GroupingResult& grouping, const TextureMap& map) {
  QualityReport report;
  report.unseen_faces = grouping.unseen_faces;
  report.corrected_faces = grouping.corrected_faces;
  report.uncorrectable_faces = grouping.uncorrectable_faces;
  report.island_faces_switched = grouping.island_faces_switched;
  report.coherence_faces_switched = grouping.coherence_faces_switched;
  report.patches = grouping.patches;
  report.mean_patch_faces = grouping.mean_patch_faces;
  report.filled_faces = map.filled_faces;
  report.blended_texels = map.blended_texels;
  report.corrected_texels = map.corrected_texels;
  report.occluded_texels = map.occluded_texels;
  report.inpainted_texels = map.inpainted_texels;
  report.density_ratio = map.density_ratio;
  report.histogram = FacesByTexels(map.texels_per_face);
  report.view_gains_bgr = map.gains;
  int dense = 0, seen = 0;
  for (std::size_t f = 0; f < grouping.front_view.size() && f < map.density_ratio.size(); ++f)
    if (grouping.front_view[f] >= 0) {
      ++seen;
      if (map.density_ratio[f] >= 1.0) ++dense;
    }
  report.dense_fraction = seen > 0 ? static_cast<double>(dense) / seen : 0.0;
  return report;
}

nlohmann::json QualityReportJson(const QualityReport& r) {
  nlohmann::json report;
  report["faces"] = r.faces;
  report["views"] = r.views;
  report["excluded_views"] = r.excluded_views;
  report["charts"] = r.charts;
  report["atlas_size"] = r.atlas_size;
  report["grouping"] = {{"unseen_faces", r.unseen_faces},
                        {"corrected_faces", r.corrected_faces},
                        {"uncorrectable_faces", r.uncorrectable_faces},
                        {"island_faces_switched", r.island_faces_switched},
                        {"coherence_faces_switched", r.coherence_faces_switched},
                        {"patches", r.patches},
                        {"mean_patch_faces", r.mean_patch_faces}};
  report["filled_faces"] = r.filled_faces;
  report["blended_texels"] = r.blended_texels;
  report["corrected_texels"] = r.corrected_texels;
  report["occluded_texels"] = r.occluded_texels;
  report["inpainted_texels"] = r.inpainted_texels;
  report["texel_density"] = {{"faces_with_at_least_one_texel_per_photo_pixel", r.dense_fraction},
                             {"per_face", r.density_ratio}};
  report["histogram"] = {{"texels_per_face_bin_starts", r.histogram.edges},
                         {"faces", r.histogram.counts}};
  std::vector<std::array<double, 3>> gains;
  for (const cv::Vec3d& g : r.view_gains_bgr) gains.push_back({g[0], g[1], g[2]});
  report["view_gains_bgr"] = gains;
  report["options"] = {
      {"blend", r.blend}, {"correction", r.correction}, {"gain", r.gain}, {"packing", r.packing}};
  report["warnings"] = r.warnings;
  if (!r.held_out.empty()) {
    nlohmann::json scores = nlohmann::json::array();
    for (const HeldOutScore& h : r.held_out)
      scores.push_back({{"view", h.view},
                        {"psnr_db", h.psnr_db},
                        {"ssim", h.ssim},
                        {"silhouette_iou", h.has_reference ? nlohmann::json(h.mask_agreement)
                                                           : nlohmann::json(nullptr)}});
    report["held_out"] = {{"views", scores},
                          {"mean_psnr_db", MeanPsnrDb(r.held_out)},
                          {"mean_ssim", MeanSsim(r.held_out)}};
  }
  const QualityReport::Seconds& s = r.seconds;
  report["seconds"] = {{"grouping", s.grouping},
                       {"atlas", s.atlas},
                       {"transfer", s.transfer},
                       {"export", s.export_model},
                       {"evaluation", s.evaluation},
                       {"png", s.png},
                       {"glb", s.glb},
                       {"total", s.total}};
  return report;
}

void WriteQualityReport(const QualityReport& report, const std::filesystem::path& folder) {
  WriteImage(folder / "report.png", PlotTexelHistogram(report.histogram, report.atlas_size));
  WriteFileAtomic(folder / "report.json", QualityReportJson(report).dump(2));
}

}  // namespace carousel::texture
