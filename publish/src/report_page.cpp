#include "carousel/publish/report_page.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <iomanip>
#include <sstream>
#include <unordered_map>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/publish/viewer_page.h"

namespace carousel::publish {

namespace {

int Find(std::vector<int>& parent, int i) {
  while (parent[i] != i) {
    parent[i] = parent[parent[i]];
    i = parent[i];
  }
  return i;
}

std::uint64_t UvKey(const Eigen::Vector2f& uv) {
  std::uint32_t u = 0, v = 0;
  std::memcpy(&u, &uv.x(), sizeof u);
  std::memcpy(&v, &uv.y(), sizeof v);
  return (static_cast<std::uint64_t>(u) << 32) | v;
}

std::string Fixed(double value, int digits) {
  std::ostringstream s;
  s << std::fixed << std::setprecision(digits) << value;
  return s.str();
}

std::string Megabytes(std::size_t bytes) { return Fixed(static_cast<double>(bytes) / 1e6, 2); }

}  // namespace

std::vector<int> ChartOfTriangle(const texture::TexturedModel& model) {
  const int n = static_cast<int>(model.triangles.size());
  std::vector<int> parent(static_cast<std::size_t>(n));
  for (int t = 0; t < n; ++t) parent[t] = t;
  std::unordered_map<std::uint64_t, int> first_triangle;
  first_triangle.reserve(model.uvs.size());
  for (int t = 0; t < n; ++t)
    for (int k = 0; k < 3; ++k) {
      const auto [it, added] =
          first_triangle.emplace(UvKey(model.uvs.at(model.triangles[t][k])), t);
      if (!added) {
        const int a = Find(parent, it->second), b = Find(parent, t);
        if (a != b) parent[std::max(a, b)] = std::min(a, b);
      }
    }
  std::vector<int> chart(static_cast<std::size_t>(n), -1);
  std::vector<int> number(static_cast<std::size_t>(n), -1);
  int charts = 0;
  for (int t = 0; t < n; ++t) {
    const int root = Find(parent, t);
    if (number[root] < 0) number[root] = charts++;
    chart[t] = number[root];
  }
  return chart;
}

cv::Mat PaintTriangles(const texture::TexturedModel& model, const std::vector<cv::Vec3b>& colours,
                       int side, cv::Vec3b background, int spill) {
  CAROUSEL_THROW_IF(
      colours.size() != model.triangles.size(), InvalidArgument,
      "paint: " << colours.size() << " colours for " << model.triangles.size() << " triangles");
  CAROUSEL_THROW_IF(side < 8, InvalidArgument, "paint: the side must be >= 8");
  cv::Mat image(side, side, CV_8UC3, cv::Scalar(background[0], background[1], background[2]));
  cv::Mat painted(side, side, CV_8UC1, cv::Scalar(0));
  constexpr int kShift = 4;
  const double scale = side * static_cast<double>(1 << kShift);
  for (std::size_t t = 0; t < model.triangles.size(); ++t) {
    cv::Point corners[3];
    for (int k = 0; k < 3; ++k) {
      // UV (0,0) is the texture's top-left corner; texel centres at +0.5.
      const Eigen::Vector2f& uv = model.uvs[model.triangles[t][k]];
      corners[k] = cv::Point(static_cast<int>(std::lround(uv.x() * scale - 0.5 * (1 << kShift))),
                             static_cast<int>(std::lround(uv.y() * scale - 0.5 * (1 << kShift))));
    }
    const cv::Vec3b c = colours[t];
    cv::fillConvexPoly(image, corners, 3, cv::Scalar(c[0], c[1], c[2]), cv::LINE_8, kShift);
    cv::fillConvexPoly(painted, corners, 3, cv::Scalar(255), cv::LINE_8, kShift);
  }
  // Spill: unpainted texels take a painted neighbour's colour, `spill` rings deep.
  const cv::Mat kernel = cv::getStructuringElement(cv::MORPH_RECT, {3, 3});
  for (int ring = 0; ring < spill; ++ring) {
    cv::Mat grown, grown_mask;
    cv::dilate(image, grown, kernel);
    cv::dilate(painted, grown_mask, kernel);
    grown.copyTo(image, grown_mask & ~painted);
    painted = grown_mask;
  }
  return image;
}

std::vector<cv::Vec3b> ChartColours(const std::vector<int>& chart_of_triangle) {
  int charts = 0;
  for (const int c : chart_of_triangle) charts = std::max(charts, c + 1);
  cv::Mat hsv(1, std::max(charts, 1), CV_8UC3);
  for (int c = 0; c < charts; ++c) {
    const double hue = std::fmod(c * 0.618033988749895, 1.0);
    hsv.at<cv::Vec3b>(0, c) = cv::Vec3b(static_cast<std::uint8_t>(hue * 179.0),
                                        static_cast<std::uint8_t>(c % 3 == 0 ? 200 : 150),
                                        static_cast<std::uint8_t>(c % 2 == 0 ? 235 : 190));
  }
  cv::Mat bgr;
  cv::cvtColor(hsv, bgr, cv::COLOR_HSV2BGR);
  std::vector<cv::Vec3b> colours;
  colours.reserve(chart_of_triangle.size());
  for (const int c : chart_of_triangle) colours.push_back(bgr.at<cv::Vec3b>(0, c));
  return colours;
}

namespace {

cv::Mat Viridis() {
  cv::Mat ramp(1, 256, CV_8UC1);
  for (int i = 0; i < 256; ++i) ramp.at<std::uint8_t>(0, i) = static_cast<std::uint8_t>(i);
  cv::Mat colours;
  cv::applyColorMap(ramp, colours, cv::COLORMAP_VIRIDIS);
  return colours;
}

}  // namespace

std::vector<cv::Vec3b> DensityColours(const std::vector<double>& values, double lo, double hi) {
  CAROUSEL_THROW_IF(!(lo > 0.0 && hi > lo), InvalidArgument,
                    "density colours: need 0 < lo < hi, got " << lo << ", " << hi);
  const cv::Mat map = Viridis();
  const double a = std::log2(lo), b = std::log2(hi);
  std::vector<cv::Vec3b> colours;
  colours.reserve(values.size());
  for (const double v : values) {
    if (!(v > 0.0)) {
      colours.emplace_back(128, 128, 128);
      continue;
    }
    const double t = std::clamp((std::log2(v) - a) / (b - a), 0.0, 1.0);
    colours.push_back(map.at<cv::Vec3b>(0, static_cast<int>(std::lround(t * 255.0))));
  }
  return colours;
}

cv::Mat DensityLegend(int width, int height) {
  const cv::Mat map = Viridis();
  cv::Mat strip;
  cv::resize(map, strip, cv::Size(std::max(width, 1), std::max(height, 1)), 0, 0, cv::INTER_LINEAR);
  return strip;
}

std::string HistogramSvg(const std::vector<int>& edges, const std::vector<int>& counts,
                         int atlas_size) {
  CAROUSEL_THROW_IF(
      edges.size() != counts.size() || edges.empty(), InvalidArgument,
      "histogram: " << edges.size() << " bin starts for " << counts.size() << " counts");
  const int bins = static_cast<int>(counts.size());
  const int max_count = std::max(1, *std::max_element(counts.begin(), counts.end()));
  constexpr int kWidth = 760, kHeight = 320, kLeft = 56, kBottom = 52, kTop = 34;
  const double bar_w = static_cast<double>(kWidth - kLeft - 16) / bins;
  const double plot_h = kHeight - kBottom - kTop;
  std::ostringstream svg;
  svg << "<svg xmlns=\"http://www.w3.org/2000/svg\" viewBox=\"0 0 " << kWidth << ' ' << kHeight
      << "\" width=\"" << kWidth << "\" height=\"" << kHeight
      << "\" role=\"img\" aria-label=\"faces by texels per face\">\n"
      << "<text x=\"" << kWidth / 2 << "\" y=\"20\" text-anchor=\"middle\" font-size=\"15\">"
      << "faces by texels per face (" << atlas_size << " &#215; " << atlas_size
      << " atlas)</text>\n";
  svg << "<line x1=\"" << kLeft << "\" y1=\"" << kHeight - kBottom << "\" x2=\"" << kWidth - 16
      << "\" y2=\"" << kHeight - kBottom << "\" stroke=\"#444\"/>\n";
  for (int i = 0; i < bins; ++i) {
    const double h = plot_h * counts[i] / max_count;
    const double x = kLeft + i * bar_w + 0.12 * bar_w;
    const double y = kHeight - kBottom - h;
    const std::string label =
        i + 1 == bins ? "&#8805;" + std::to_string(edges[i])
        : edges[i + 1] - 1 == edges[i]
            ? std::to_string(edges[i])
            : std::to_string(edges[i]) + "&#8211;" + std::to_string(edges[i + 1] - 1);
    svg << "<rect class=\"bar\" x=\"" << Fixed(x, 1) << "\" y=\"" << Fixed(y, 1) << "\" width=\""
        << Fixed(0.76 * bar_w, 1) << "\" height=\"" << Fixed(h, 1)
        << "\" fill=\"#3b6ea8\" data-count=\"" << counts[i] << "\"><title>" << counts[i]
        << " faces</title></rect>\n"
        << "<text x=\"" << Fixed(x + 0.38 * bar_w, 1) << "\" y=\"" << Fixed(y - 4, 1)
        << "\" text-anchor=\"middle\" font-size=\"12\">" << counts[i] << "</text>\n"
        << "<text x=\"" << Fixed(x + 0.38 * bar_w, 1) << "\" y=\"" << kHeight - kBottom + 18
        << "\" text-anchor=\"middle\" font-size=\"12\">" << label << "</text>\n";
  }
  svg << "<text x=\"" << kWidth / 2 << "\" y=\"" << kHeight - 10
      << "\" text-anchor=\"middle\" font-size=\"13\">texels per face</text>\n"
      << "<text x=\"16\" y=\"" << kTop + plot_h / 2
      << "\" font-size=\"13\" transform=\"rotate(-90 16 " << kTop + plot_h / 2
      << ")\" text-anchor=\"middle\">faces</text>\n"
      << "</svg>\n";
  return svg.str();
}

std::string ReportPageHtml(const ReportPageContent& c) {
  const std::string name = c.title.empty() ? "3D model" : c.title;
  const std::string title = EscapeHtml(name);
  std::ostringstream html;
  html << HtmlPageOpening(name + " \u2014 model report") << R"(<style>
  body { font-family: system-ui, sans-serif; margin: 1rem 1.5rem; color: #222; max-width: 1100px; }
  h1 { font-size: 1.3rem; } h2 { font-size: 1.05rem; margin-top: 1.6rem; }
  table { border-collapse: collapse; } td, th { padding: 0.25rem 0.7rem; text-align: right; }
  th { border-bottom: 1px solid #999; } td:first-child, th:first-child { text-align: left; }
  img { max-width: 100%; height: auto; border: 1px solid #ddd; }
  figure { margin: 0.6rem 0; } figcaption { font-size: 0.9rem; color: #555; }
</style>
</head>
<body>
<h1>)" << title
       << R"( &#8212; model report</h1>
<p><a href="index.html">3D view</a></p>
<h2>Model</h2>
<table id="figures">
)";
  html << "<tr><td>faces</td><td>" << c.faces << "</td></tr>\n"
       << "<tr><td>photos</td><td>" << c.views << "</td></tr>\n"
       << "<tr><td>charts</td><td>" << c.charts << "</td></tr>\n"
       << "<tr><td>UV islands</td><td>" << c.islands << "</td></tr>\n"
       << "<tr><td>atlas</td><td>" << c.atlas_size << " &#215; " << c.atlas_size
       << " texels</td></tr>\n"
       << "<tr><td>faces with &#8805; 1 texel per photo pixel</td><td>"
       << Fixed(100.0 * c.dense_fraction, 1) << " %</td></tr>\n"
       << "<tr><td>archive GLB (lossless)</td><td>" << Megabytes(c.lossless_bytes)
       << " MB</td></tr>\n"
       << "<tr><td>web GLB</td><td>" << Megabytes(c.web_bytes) << " MB</td></tr>\n"
       << "</table>\n";
  if (!c.histogram_counts.empty())
    html << "<h2>Faces by texels per face</h2>\n<figure id=\"histogram\">\n"
         << HistogramSvg(c.histogram_edges, c.histogram_counts, c.atlas_size) << "</figure>\n";
  if (!c.held_out.empty()) {
    html << "<h2>Held-out views</h2>\n<p>Photos that were not used for texturing (left) beside "
            "the model rendered through the same camera (right), scored over the object.</p>\n"
         << "<table id=\"held-out\">\n<tr><th>view</th><th>PSNR (dB)</th><th>SSIM</th>"
            "<th>PSNR web GLB (dB)</th><th>SSIM web GLB</th></tr>\n";
    for (const ReportHeldOutRow& r : c.held_out)
      html << "<tr><td>" << r.view << "</td><td>" << Fixed(r.psnr_db, 2) << "</td><td>"
           << Fixed(r.ssim, 4) << "</td><td>" << Fixed(r.psnr_db_web, 2) << "</td><td>"
           << Fixed(r.ssim_web, 4) << "</td></tr>\n";
    html << "</table>\n";
    for (const ReportHeldOutRow& r : c.held_out)
      html << "<figure><img src=\"" << EscapeHtml(r.image) << "\" alt=\"held-out view " << r.view
           << ": photo and render\"><figcaption>view " << r.view << ": photo | render, "
           << Fixed(r.psnr_db, 2) << " dB</figcaption></figure>\n";
  }
  if (!c.charts_image.empty() || !c.charts_atlas_image.empty()) {
    html << "<h2>Charts</h2>\n";
    if (!c.charts_image.empty())
      html << "<figure><img src=\"" << EscapeHtml(c.charts_image)
           << "\" alt=\"charts on the model\"><figcaption>" << c.islands
           << " UV islands, one colour each, on the model</figcaption></figure>\n";
    if (!c.charts_atlas_image.empty())
      html << "<figure><img src=\"" << EscapeHtml(c.charts_atlas_image)
           << "\" alt=\"charts in the atlas\"><figcaption>the islands packed in the "
              "atlas</figcaption></figure>\n";
  }
  if (!c.density_image.empty()) {
    html << "<h2>Texel density</h2>\n<figure><img src=\"" << EscapeHtml(c.density_image)
         << "\" alt=\"texel density on the model\"><figcaption>texels per pixel of the face's "
            "front photo, log scale from "
         << Fixed(c.density_lo, 2) << " to " << Fixed(c.density_hi, 2)
         << " (1 = the photo's full resolution); grey: seen by no photo</figcaption>";
    if (!c.density_legend_image.empty())
      html << "<img src=\"" << EscapeHtml(c.density_legend_image)
           << "\" alt=\"colour scale\" style=\"width:320px;height:16px\">";
    html << "</figure>\n";
  }
  if (!c.stage_seconds.empty()) {
    html
        << "<h2>Stage times</h2>\n<table id=\"stages\">\n<tr><th>stage</th><th>seconds</th></tr>\n";
    for (const auto& [stage, seconds] : c.stage_seconds)
      html << "<tr><td>" << EscapeHtml(stage) << "</td><td>" << Fixed(seconds, 2) << "</td></tr>\n";
    html << "</table>\n";
  }
  html << "</body>\n</html>\n";
  return html.str();
}

}  // namespace carousel::publish
