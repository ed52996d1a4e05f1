// The report page of a textured model, model/report.html: the faces-by-texels histogram (the
// texture paper's Fig. 12, as an inline SVG), the held-out views beside their renders with
// PSNR/SSIM (lossless and web GLB), the charts image, the texel-density image, the atlas's
// figures and the stage times. The page is static HTML with its images beside it.
//
// The model maps (charts, density) paint a per-triangle colour into the model's UV layout, so
// they can be shown flat (the atlas) or rendered on the model like its texture.
#pragma once

#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/texture/textured_model.h"

namespace carousel::publish {

// The UV island of each triangle: triangles that share a texture coordinate (bit for bit) are
// of one island; islands are numbered 0.. in the order of their first triangle. A chart of the
// atlas is one island or, where its flattening split it, several.
std::vector<int> ChartOfTriangle(const texture::TexturedModel& model);

// A texture of `side` x `side` (BGR) in `model`'s UV layout with triangle t filled with
// `colours[t]`, texels outside every triangle `background` except for a few texels' spill
// around each chart (so filtering at chart edges stays in the chart's colour).
// \throw InvalidArgument (colours and triangles disagree, side < 8).
cv::Mat PaintTriangles(const texture::TexturedModel& model, const std::vector<cv::Vec3b>& colours,
                       int side, cv::Vec3b background = {40, 40, 40}, int spill = 2);

// One colour per chart, distinct neighbours (a golden-ratio hue walk), per triangle.
std::vector<cv::Vec3b> ChartColours(const std::vector<int>& chart_of_triangle);

// `values` through a perceptual colour map (viridis) on a log2 scale clamped to [lo, hi]
// (both > 0); values <= 0 are grey.
std::vector<cv::Vec3b> DensityColours(const std::vector<double>& values, double lo, double hi);
// The colour map as a horizontal legend strip (BGR, width x height).
cv::Mat DensityLegend(int width, int height);

// Faces by texels per face as an SVG bar chart: bin i spans edges[i] ..
// edges[i + 1] - 1, the last is open. \throw InvalidArgument (sizes disagree).
std::string HistogramSvg(const std::vector<int>& edges, const std::vector<int>& counts,
                         int atlas_size);

struct ReportHeldOutRow {
  int view = 0;
  std::string image;                         // photo | render, relative to the page
  double psnr_db = 0.0, ssim = 0.0;          // the lossless GLB
  double psnr_db_web = 0.0, ssim_web = 0.0;  // the web GLB
};

struct ReportPageContent {
  std::string title;
  std::size_t faces = 0;
  int charts = 0, atlas_size = 0, views = 0;
  int islands = 0;              // connected pieces of the UV layout (ChartOfTriangle)
  double dense_fraction = 0.0;  // faces with >= 1 texel per photo pixel
  std::vector<int> histogram_edges, histogram_counts;
  std::vector<ReportHeldOutRow> held_out;
  std::string charts_image, charts_atlas_image;  // relative paths; empty: not shown
  std::string density_image, density_legend_image;
  double density_lo = 0.25, density_hi = 4.0;
  std::size_t lossless_bytes = 0, web_bytes = 0;
  std::vector<std::pair<std::string, double>> stage_seconds;  // in the order shown
};

// The page's HTML (every text escaped).
std::string ReportPageHtml(const ReportPageContent& content);

}  // namespace carousel::publish
