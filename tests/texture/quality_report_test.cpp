// The quality report: faces by texels per face, the density summary, the histogram plot and
// report.json's fields.
#include "carousel/texture/quality_report.h"

#include <gtest/gtest.h>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/json.h"
#include "carousel/testing/testing.h"

namespace carousel::texture {
namespace {

using carousel::testing::TempDir;

TEST(QualityReportTest, FacesAreBinnedByTheirTexelCount) {
  const TexelHistogram h = FacesByTexels({0, 1, 10, 11, 50, 5000, 5001, 100000, 0});
  EXPECT_EQ(h.edges, (std::vector<int>{0, 1, 11, 51, 101, 501, 1001, 5001}));
  EXPECT_EQ(h.counts, (std::vector<int>{2, 2, 2, 0, 0, 0, 1, 2}));
  const TexelHistogram custom = FacesByTexels({0, 3, 4, 9}, {0, 4});
  EXPECT_EQ(custom.counts, (std::vector<int>{2, 2}));
  EXPECT_THROW(FacesByTexels({1}, {}), InvalidArgument);
  EXPECT_THROW(FacesByTexels({1}, {1, 5}), InvalidArgument);
  EXPECT_THROW(FacesByTexels({1}, {0, 5, 5}), InvalidArgument);
}

TEST(QualityReportTest, TheSummaryCountsDenseFacesAmongTheSeenOnes) {
  GroupingResult grouping;
  grouping.front_view = {0, Mesh::kNoView, 1, 0};
  grouping.unseen_faces = 1;
  grouping.corrected_faces = 2;
  grouping.uncorrectable_faces = 3;
  grouping.island_faces_switched = 4;
  TextureMap map;
  map.texels_per_face = {12, 0, 600, 2};
  map.density_ratio = {1.0, 0.0, 0.5, 2.0};
  map.gains = {{1.0, 1.1, 0.9}, {1.0, 1.0, 1.0}};
  map.filled_faces = 1;
  map.blended_texels = 5;
  map.corrected_texels = 6;
  map.occluded_texels = 8;
  map.inpainted_texels = 7;
  const QualityReport r = SummarizeTexture(grouping, map);
  EXPECT_DOUBLE_EQ(r.dense_fraction, 2.0 / 3.0);  // the unseen face does not count
  EXPECT_EQ(r.histogram.counts, (std::vector<int>{1, 1, 1, 0, 0, 1, 0, 0}));
  EXPECT_EQ(r.unseen_faces, 1);
  EXPECT_EQ(r.corrected_faces, 2);
  EXPECT_EQ(r.uncorrectable_faces, 3);
  EXPECT_EQ(r.island_faces_switched, 4);
  EXPECT_EQ(r.filled_faces, 1);
  EXPECT_EQ(r.blended_texels, 5);
  EXPECT_EQ(r.corrected_texels, 6);
  EXPECT_EQ(r.occluded_texels, 8);
  EXPECT_EQ(r.inpainted_texels, 7);
  EXPECT_EQ(r.view_gains_bgr.size(), 2u);
  EXPECT_EQ(r.density_ratio, map.density_ratio);
}

// Heights of the plot's bars (BGR 180, 110, 40) from left to right; empty bins draw none.
std::vector<int> BarHeights(const cv::Mat& plot) {
  std::vector<int> heights;
  bool in_bar = false;
  for (int x = 0; x < plot.cols; ++x) {
    int h = 0;
    for (int y = 0; y < plot.rows; ++y) h += plot.at<cv::Vec3b>(y, x) == cv::Vec3b(180, 110, 40);
    if (h > 0 && !in_bar) heights.push_back(h);
    in_bar = h > 0;
  }
  return heights;
}

TEST(QualityReportTest, ThePlotDrawsOneBarPerBinScaledToThePeak) {
  const TexelHistogram h{{0, 1, 11}, {10, 40, 20}};
  const cv::Mat plot = PlotTexelHistogram(h, 1536);
  EXPECT_EQ(plot.type(), CV_8UC3);
  EXPECT_EQ(plot.cols, 900);
  EXPECT_EQ(plot.rows, 420);
  const std::vector<int> bars = BarHeights(plot);
  ASSERT_EQ(bars.size(), 3u);
  EXPECT_NEAR(bars[1], 300, 2);  // the peak fills the plot's height
  EXPECT_NEAR(bars[0], 75, 2);
  EXPECT_NEAR(bars[2], 150, 2);
  // The title depends on the size (written out: Hershey fonts have no '^').
  cv::Mat other = PlotTexelHistogram(h, 512);
  EXPECT_GT(cv::norm(plot(cv::Rect(0, 0, 900, 40)), other(cv::Rect(0, 0, 900, 40)), cv::NORM_L1),
            0.0);
  EXPECT_THROW(PlotTexelHistogram({{0, 1}, {1}}, 512), InvalidArgument);
}

QualityReport Example() {
  QualityReport r;
  r.faces = 4;
  r.views = 16;
  r.excluded_views = {3, 11};
  r.charts = 20;
  r.atlas_size = 1024;
  r.unseen_faces = 1;
  r.dense_fraction = 0.75;
  r.density_ratio = {1.0, 0.0, 2.0, 1.5};
  r.histogram = FacesByTexels({1, 20, 30, 700});
  r.view_gains_bgr = {{1.0, 1.1, 0.9}};
  r.blend = false;
  r.packing = "obb";
  r.held_out = {{3, 20.0, 0.7, 0.98}, {11, 22.0, 0.8, 0.97}};
  r.seconds.export_model = 0.25;
  r.seconds.total = 2.0;
  return r;
}

TEST(QualityReportTest, ReportJsonHasEveryField) {
  const nlohmann::json j = QualityReportJson(Example());
  for (const char* key :
       {"faces", "views", "excluded_views", "charts", "atlas_size", "grouping", "filled_faces",
        "blended_texels", "corrected_texels", "occluded_texels", "inpainted_texels",
        "texel_density", "histogram", "view_gains_bgr", "options", "held_out", "seconds"})
    EXPECT_TRUE(j.contains(key)) << key;
  EXPECT_EQ(j["faces"], 4);
  EXPECT_EQ(j["excluded_views"], nlohmann::json::array({3, 11}));
  EXPECT_EQ(j["grouping"]["unseen_faces"], 1);
  EXPECT_EQ(j["texel_density"]["faces_with_at_least_one_texel_per_photo_pixel"], 0.75);
  EXPECT_EQ(j["texel_density"]["per_face"].size(), 4u);
  EXPECT_EQ(j["histogram"]["faces"], nlohmann::json::array({0, 1, 2, 0, 0, 1, 0, 0}));
  EXPECT_EQ(j["histogram"]["texels_per_face_bin_starts"][7], 5001);
  EXPECT_EQ(j["view_gains_bgr"][0][1], 1.1);
  EXPECT_EQ(j["options"]["blend"], false);
  EXPECT_EQ(j["options"]["packing"], "obb");
  EXPECT_EQ(j["held_out"]["views"].size(), 2u);
  EXPECT_EQ(j["held_out"]["views"][1]["view"], 11);
  EXPECT_EQ(j["held_out"]["views"][1]["silhouette_iou"], 0.97);
  EXPECT_DOUBLE_EQ(j["held_out"]["mean_psnr_db"].get<double>(), 21.0);
  EXPECT_DOUBLE_EQ(j["held_out"]["mean_ssim"].get<double>(), 0.75);
  EXPECT_EQ(j["seconds"]["export"], 0.25);
  for (const char* key :
       {"grouping", "atlas", "transfer", "export", "evaluation", "png", "glb", "total"})
    EXPECT_TRUE(j["seconds"].contains(key)) << key;
  // Nothing held out: no held_out section.
  QualityReport none = Example();
  none.held_out.clear();
  EXPECT_FALSE(QualityReportJson(none).contains("held_out"));
}

TEST(QualityReportTest, TheReportIsWrittenBesideTheModel) {
  TempDir dir;
  WriteQualityReport(Example(), dir.path());
  const nlohmann::json j = ParseJsonFile(dir / "report.json");
  EXPECT_EQ(j, QualityReportJson(Example()));
  const cv::Mat plot = ReadImage(dir / "report.png");
  EXPECT_EQ(plot.cols, 900);
  EXPECT_EQ(BarHeights(plot).size(), 3u);  // the bins with faces
  CAROUSEL_EXPECT_THROW_WITH(WriteQualityReport(Example(), dir / "no" / "such" / "folder"), IoError,
                             "report");
}

}  // namespace
}  // namespace carousel::texture
