// The quality report of a textured model (texture paper, Fig. 12 and section 6): faces by
// texels per face, the texel-to-photo-pixel density, the grouping and transfer counts, the
// held-out scores (held_out.h) and the time per phase. Written beside the model as
// report.json (the figures) and report.png (the histogram as a bar chart).
//
// report.json fields: faces, views, excluded_views, charts, atlas_size, grouping
// {unseen_faces, corrected_faces, uncorrectable_faces, island_faces_switched}, filled_faces,
// blended_texels, corrected_texels, occluded_texels, inpainted_texels, texel_density
// {faces_with_at_least_one_texel_per_photo_pixel, per_face}, histogram
// {texels_per_face_bin_starts, faces}, view_gains_bgr, options {blend, correction, gain,
// packing}, held_out {views [{view, psnr_db, ssim, silhouette_iou}], mean_psnr_db, mean_ssim}
// (only when views were held out), seconds {grouping, atlas, transfer, export, evaluation,
// png, glb, total}.
#pragma once

#include <cstddef>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "carousel/texture/held_out.h"
#include "carousel/texture/texture_map.h"

namespace carousel::texture {

// Faces by texels per face: bin i counts the faces with edges[i] <= texels < edges[i + 1];
// the last bin is open (>= edges.back()).
struct TexelHistogram {
  std::vector<int> edges;
  std::vector<int> counts;
};

// The report's bins: 0, 1-10, 11-50, 51-100, 101-500, 501-1000, 1001-5000, >= 5001.
std::vector<int> DefaultTexelHistogramEdges();

// \throw InvalidArgument unless `edges` is non-empty, strictly increasing and starts at 0.
TexelHistogram FacesByTexels(const std::vector<int>& texels_per_face,
                             const std::vector<int>& edges = DefaultTexelHistogramEdges());

// The histogram as a bar chart (CV_8UC3 BGR, 900 x 420), titled with the atlas size
// ("faces by texels per face (1536 x 1536 atlas)").
cv::Mat PlotTexelHistogram(const TexelHistogram& histogram, int atlas_size);

struct QualityReport {
  std::size_t faces = 0;
  int views = 0;
  std::vector<int> excluded_views;
  int charts = 0;
  int atlas_size = 0;  // texels per side
  // From the grouping (GroupingResult).
  int unseen_faces = 0;
  int corrected_faces = 0;
  int uncorrectable_faces = 0;
  int island_faces_switched = 0;
  int coherence_faces_switched = 0;
  int patches = 0;  // connected groups of faces with one front view
  double mean_patch_faces = 0.0;
  // From the transfer (TextureMap).
  int filled_faces = 0;
  int blended_texels = 0;
  int corrected_texels = 0;
  int occluded_texels = 0;
  int inpainted_texels = 0;
  // Fraction of the faces some view sees that get at least one texel per front-photo pixel.
  double dense_fraction = 0.0;
  std::vector<double> density_ratio;  // per face: texels per front-photo pixel
  TexelHistogram histogram;
  std::vector<cv::Vec3d> view_gains_bgr;  // per view
  // The options that shaped the texture.
  bool blend = true;
  bool correction = true;
  bool gain = true;
  std::string packing;  // PackingModeName()
  // What the stage could not do as asked (a correction skipped for want of masks).
  std::vector<std::string> warnings;
  // One per held-out view; none when no view was held out.
  std::vector<HeldOutScore> held_out;
  struct Seconds {
    double grouping = 0.0, atlas = 0.0, transfer = 0.0, export_model = 0.0, evaluation = 0.0,
           png = 0.0, glb = 0.0, total = 0.0;
  } seconds;
};

// The figures of a grouping and the transfer that used it: counts, density, the histogram
// (default bins) and the gains; the caller fills in the rest.
QualityReport SummarizeTexture(const GroupingResult& grouping, const TextureMap& map);

// report.json's content.
nlohmann::json QualityReportJson(const QualityReport& report);

// Writes `folder`/report.png (the histogram) and `folder`/report.json (atomically).
// \throw IoError naming the file.
void WriteQualityReport(const QualityReport& report, const std::filesystem::path& folder);

}  // namespace carousel::texture
