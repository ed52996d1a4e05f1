// publish/'s catalog images (cut-outs, the spin as an animated WebP, the zipped 360° set), the
// report page and the static catalog site: units on synthetic images, then the files the
// publish stage wrote for small simulated sessions, checked on their pixels.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <map>
#include <regex>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/publish/catalog_images.h"
#include "carousel/publish/renders.h"
#include "carousel/publish/report_page.h"
#include "carousel/publish/site.h"
#include "carousel/testing/testing.h"
#include "carousel/texture/textured_model.h"
#include "small_session.h"

namespace carousel::publish {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

// A photo with a smooth grey backdrop and a red-and-blue box at `box`, and its mask.
std::pair<cv::Mat, cv::Mat> BoxPhoto(cv::Size size, cv::Rect box) {
  cv::Mat photo(size, CV_8UC3);
  for (int y = 0; y < size.height; ++y) photo.row(y).setTo(cv::Scalar(120 + y % 40, 130, 140));
  photo(box).setTo(cv::Scalar(30, 40, 200));
  photo(cv::Rect(box.x, box.y, box.width / 2, box.height)).setTo(cv::Scalar(200, 60, 20));
  cv::Mat mask(size, CV_8UC1, cv::Scalar(0));
  mask(box).setTo(255);
  return {photo, mask};
}

cv::Rect ObjectBox(const cv::Mat& image) {
  cv::Mat grey;
  cv::cvtColor(image, grey, image.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return cv::boundingRect(grey < 235);
}

TEST(CutOutTest, CentresTheObjectWithAUniformMarginOnWhite) {
  const cv::Rect box(30, 50, 120, 60);  // off-centre, wider than high
  const auto [photo, mask] = BoxPhoto({320, 200}, box);
  const cv::Mat cut = CutOut(photo, mask, {.margin = 0.1});
  ASSERT_EQ(cut.type(), CV_8UC3);
  ASSERT_EQ(cut.rows, cut.cols);
  // 120 px of object fill 80 % of the side.
  EXPECT_NEAR(cut.cols, 150, 1);
  const cv::Rect found = ObjectBox(cut);
  EXPECT_NEAR(found.x + 0.5 * found.width, 0.5 * cut.cols, 1.0);
  EXPECT_NEAR(found.y + 0.5 * found.height, 0.5 * cut.rows, 1.0);
  EXPECT_NEAR(found.x, 0.1 * cut.cols, 1.0);
  EXPECT_EQ(found.width, box.width);
  EXPECT_EQ(found.height, box.height);
  // The object's own pixels, pure white elsewhere (the grey backdrop is gone).
  EXPECT_EQ(cut.at<cv::Vec3b>(found.y + 5, found.x + 5), cv::Vec3b(200, 60, 20));
  EXPECT_EQ(cut.at<cv::Vec3b>(found.y + 5, found.x + found.width - 5), cv::Vec3b(30, 40, 200));
  EXPECT_EQ(cut.at<cv::Vec3b>(2, 2), cv::Vec3b(255, 255, 255));
  EXPECT_EQ(cut.at<cv::Vec3b>(found.y - 3, found.x + 10), cv::Vec3b(255, 255, 255));
  // A requested size scales the square.
  const cv::Mat scaled = CutOut(photo, mask, {.margin = 0.1, .size = 300});
  EXPECT_EQ(scaled.size(), cv::Size(300, 300));
  EXPECT_NEAR(ObjectBox(scaled).width, 240, 2);
}

TEST(CutOutTest, TransparentKeepsTheMaskAsAlphaAndSoftEdgesBlend) {
  const cv::Rect box(100, 20, 60, 150);
  auto [photo, mask] = BoxPhoto({320, 200}, box);
  mask.at<std::uint8_t>(100, box.x) = 128;  // a soft edge pixel
  const cv::Mat cut =
      CutOut(photo, mask, {.backdrop = CutoutBackdrop::kTransparent, .margin = 0.05});
  ASSERT_EQ(cut.type(), CV_8UC4);
  std::vector<cv::Mat> channels;
  cv::split(cut, channels);
  // Alpha is the mask, moved into the square.
  EXPECT_EQ(cv::countNonZero(channels[3] == 255), box.area() - 1);
  EXPECT_EQ(cv::countNonZero(channels[3] == 128), 1);
  EXPECT_EQ(cv::countNonZero(channels[3]), box.area());
  const cv::Rect alpha_box = cv::boundingRect(channels[3]);
  EXPECT_NEAR(alpha_box.y + 0.5 * alpha_box.height, 0.5 * cut.rows, 1.0);
  // On white, the soft pixel is half photo, half white.
  const cv::Mat white = CutOut(photo, mask, {.margin = 0.05});
  const cv::Vec3b& soft = white.at<cv::Vec3b>(100 - box.y + alpha_box.y, alpha_box.x);
  const cv::Vec3b full = photo.at<cv::Vec3b>(100, box.x);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(soft[c], 0.5 * full[c] + 0.5 * 255, 1.5) << c;
}

TEST(CutOutTest, AnObjectAtThePhotosEdgeStaysCentredAndAnEmptyMaskIsAnError) {
  const cv::Rect box(0, 0, 80, 80);  // the square reaches beyond the photo
  const auto [photo, mask] = BoxPhoto({320, 200}, box);
  const cv::Mat cut = CutOut(photo, mask, {.margin = 0.2});
  const cv::Rect found = ObjectBox(cut);
  EXPECT_NEAR(found.x + 0.5 * found.width, 0.5 * cut.cols, 1.0);
  EXPECT_EQ(cut.at<cv::Vec3b>(1, 1), cv::Vec3b(255, 255, 255));
  EXPECT_THROW(CutOut(photo, cv::Mat(photo.size(), CV_8UC1, cv::Scalar(0)), {}), InvalidArgument);
  EXPECT_THROW(CutOut(photo, cv::Mat(10, 10, CV_8UC1, cv::Scalar(255)), {}), InvalidArgument);
  EXPECT_THROW(CutOut(photo, mask, {.margin = 0.6}), InvalidArgument);
}

TEST(AnimatedWebpTest, FramesAndTimesRoundTripAndDamageIsNamed) {
  std::vector<cv::Mat> frames;
  for (int k = 0; k < 6; ++k) {
    cv::Mat f(96, 128, CV_8UC3, cv::Scalar(255, 255, 255));
    cv::circle(f, {20 + 15 * k, 48}, 18, cv::Scalar(40 * k, 100, 220 - 30 * k), cv::FILLED);
    frames.push_back(f);
  }
  const std::vector<std::uint8_t> bytes = EncodeAnimatedWebp(frames, 100, 90, "spin.webp");
  ASSERT_GT(bytes.size(), 12u);
  EXPECT_EQ(std::string(bytes.begin() + 8, bytes.begin() + 12), "WEBP");
  const AnimatedImage decoded = DecodeAnimatedWebp(bytes, "spin.webp");
  ASSERT_EQ(decoded.frames.size(), frames.size());
  EXPECT_EQ(decoded.loop_count, 0);
  for (std::size_t k = 0; k < frames.size(); ++k) {
    EXPECT_EQ(decoded.timestamps_ms[k], 100 * static_cast<int>(k + 1));
    cv::Mat bgr;
    cv::cvtColor(decoded.frames[k], bgr, cv::COLOR_BGRA2BGR);
    EXPECT_GT(cv::PSNR(bgr, frames[k]), 30.0) << k;
    if (k > 0) {
      EXPECT_LT(cv::PSNR(bgr, frames[0]), 25.0) << "frame " << k << " is frame 0";
    }
  }
  std::vector<std::uint8_t> damaged(bytes.begin(), bytes.begin() + 40);
  try {
    DecodeAnimatedWebp(damaged, "/x/spin.webp");
    ADD_FAILURE() << "a truncated WebP decoded";
  } catch (const FormatError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/x/spin.webp"));
  }
  EXPECT_THROW(EncodeAnimatedWebp({frames[0], cv::Mat(10, 10, CV_8UC3)}, 100, 80, "a.webp"),
               InvalidArgument);
}

TEST(ZipTest, EntriesRoundTripInOrderAndTheSameEntriesGiveTheSameBytes) {
  std::vector<ZipEntry> entries = {{"b_01.jpg", {1, 2, 3}}, {"a_02.jpg", {}}, {"c.txt", {}}};
  entries[2].bytes.assign(5000, 'x');
  const std::vector<std::uint8_t> one = ZipArchive(entries, "set.zip");
  EXPECT_EQ(one, ZipArchive(entries, "set.zip"));
  EXPECT_EQ(one[0], 'P');
  EXPECT_EQ(one[1], 'K');
  testing::TempDir dir;
  WriteFileAtomic(dir / "set.zip", std::span<const std::uint8_t>(one.data(), one.size()));
  const std::vector<ZipEntry> back = ReadZip(dir / "set.zip");
  ASSERT_EQ(back.size(), entries.size());
  for (std::size_t i = 0; i < entries.size(); ++i) {
    EXPECT_EQ(back[i].name, entries[i].name);
    EXPECT_EQ(back[i].bytes, entries[i].bytes);
  }
  EXPECT_THROW(ZipArchive({{"a", {}}, {"a", {}}}, "d.zip"), InvalidArgument);
  testing::WriteBytes(dir / "not.zip", "not a zip at all");
  try {
    ReadZip(dir / "not.zip");
    ADD_FAILURE() << "a text file read as a zip";
  } catch (const FormatError& e) {
    EXPECT_THAT(e.what(), HasSubstr("not.zip"));
  }
}

TEST(SpinSetNamesTest, SequentialAndSafe) {
  const std::vector<std::string> names = SpinSetNames("Shoe 12/blue", 24, ".jpg");
  ASSERT_EQ(names.size(), 24u);
  EXPECT_EQ(names.front(), "Shoe-12-blue_01.jpg");
  EXPECT_EQ(names.back(), "Shoe-12-blue_24.jpg");
  EXPECT_EQ(SpinSetNames("", 72, ".png").back(), "product_72.png");
  EXPECT_EQ(SiteSlug("../x y"), "..-x-y");
  EXPECT_EQ(SiteSlug(".."), "product-..");
  EXPECT_EQ(SiteSlug("assets"), "product-assets");
}

texture::TexturedModel TwoSquares() {
  texture::TexturedModel m;
  // Square A in the atlas's left half, square B in its right half, B's corners at new UVs.
  for (int s = 0; s < 2; ++s) {
    const float u0 = s == 0 ? 0.1f : 0.6f;
    for (int k = 0; k < 4; ++k) {
      const int column = k % 2, row = k / 2;
      m.positions.emplace_back(0.1 * s + 0.05 * column, 0.0, 0.05 * row);
      m.uvs.emplace_back(u0 + 0.3f * static_cast<float>(column),
                         0.1f + 0.3f * static_cast<float>(row));
    }
    const int b = 4 * s;
    m.triangles.emplace_back(b, b + 1, b + 3);
    m.triangles.emplace_back(b, b + 3, b + 2);
  }
  m.texture = cv::Mat(64, 64, CV_8UC3, cv::Scalar(128, 128, 128));
  return m;
}

TEST(ReportPageTest, IslandsPaintAndTheHistogramAndPageSayWhatTheyShow) {
  const texture::TexturedModel model = TwoSquares();
  const std::vector<int> islands = ChartOfTriangle(model);
  EXPECT_EQ(islands, (std::vector<int>{0, 0, 1, 1}));
  const std::vector<cv::Vec3b> colours = {{0, 0, 255}, {0, 0, 255}, {255, 0, 0}, {255, 0, 0}};
  const cv::Mat painted = PaintTriangles(model, colours, 100, {0, 0, 0}, 1);
  EXPECT_EQ(painted.at<cv::Vec3b>(25, 25), cv::Vec3b(0, 0, 255));
  EXPECT_EQ(painted.at<cv::Vec3b>(25, 75), cv::Vec3b(255, 0, 0));
  EXPECT_EQ(painted.at<cv::Vec3b>(80, 50), cv::Vec3b(0, 0, 0));
  EXPECT_THROW(PaintTriangles(model, {colours[0]}, 100), InvalidArgument);
  // Density colours: the map's ends, grey for unseen.
  const std::vector<cv::Vec3b> d = DensityColours({0.25, 4.0, 100.0, 0.0}, 0.25, 4.0);
  EXPECT_NE(d[0], d[1]);
  EXPECT_EQ(d[1], d[2]);
  EXPECT_EQ(d[3], cv::Vec3b(128, 128, 128));

  const std::string svg = HistogramSvg({0, 1, 11, 51}, {3, 40, 7, 1}, 1536);
  EXPECT_THAT(svg, HasSubstr("1536 &#215; 1536"));
  EXPECT_THAT(svg, HasSubstr("1&#8211;10"));
  EXPECT_THAT(svg, HasSubstr("&#8805;51"));
  EXPECT_THAT(svg, Not(HasSubstr("~")));
  const std::regex bar("data-count=\"([0-9]+)\"");
  int total = 0, bars = 0;
  for (auto it = std::sregex_iterator(svg.begin(), svg.end(), bar); it != std::sregex_iterator();
       ++it, ++bars)
    total += std::stoi((*it)[1]);
  EXPECT_EQ(bars, 4);
  EXPECT_EQ(total, 51);
  EXPECT_THROW(HistogramSvg({0, 1}, {1}, 64), InvalidArgument);

  ReportPageContent page;
  page.title = "<Shoe & Co>";
  page.histogram_edges = {0, 1};
  page.histogram_counts = {1, 2};
  page.held_out = {{.view = 3,
                    .image = "report/heldout_03.jpg",
                    .psnr_db = 23.336,
                    .ssim = 0.76,
                    .psnr_db_web = 23.301,
                    .ssim_web = 0.75}};
  page.stage_seconds = {{"reconstruct", 1.5}};
  const std::string html = ReportPageHtml(page);
  EXPECT_THAT(html, HasSubstr("&lt;Shoe &amp; Co&gt;"));
  EXPECT_THAT(html, Not(HasSubstr("<Shoe")));
  EXPECT_THAT(html, HasSubstr("23.34"));
  EXPECT_THAT(html, HasSubstr("23.30"));
  EXPECT_THAT(html, HasSubstr("report/heldout_03.jpg"));
  EXPECT_THAT(html, HasSubstr("<td>reconstruct</td><td>1.50</td>"));
}

// --- the publish stage's files of simulated sessions -----------------------------------------

nlohmann::json ReadJson(const std::filesystem::path& path) {
  return nlohmann::json::parse(testing::ReadBytes(path));
}

cv::Mat Decode(const std::vector<std::uint8_t>& bytes) {
  return cv::imdecode(bytes, cv::IMREAD_COLOR);
}

TEST(CatalogImagesTest, TheSpinAndTheTurntableRendersDecodeAndMatchTheModel) {
  const std::filesystem::path model_folder = SmallSession() / "model";
  const nlohmann::json summary = ReadJson(model_folder / "publish.json");
  const nlohmann::json& catalog = summary["catalog"];
  ASSERT_EQ(catalog["spin_source"], "renders");  // 8 stops: fewer than the set's 24
  const int frames = catalog["spin_frames"].get<int>();
  ASSERT_EQ(frames, 24);
  const std::vector<ZipEntry> set = ReadZip(model_folder / "360.zip");
  ASSERT_EQ(set.size(), 24u);
  EXPECT_EQ(set.front().name, "tiny_01.jpg");
  EXPECT_EQ(set.back().name, "tiny_24.jpg");
  const AnimatedImage spin =
      DecodeAnimatedWebp(ReadFileBytes(model_folder / "spin.webp"), "spin.webp");
  ASSERT_EQ(spin.frames.size(), 24u);
  EXPECT_EQ(spin.loop_count, 0);

  // Our renderer's pictures of the lossless model from the orbit publish.json states.
  const texture::TexturedModel model = texture::ReadTexturedModel(model_folder / "model.glb");
  const nlohmann::json& orbit = catalog["spin_renders"];
  OrbitShot shot;
  shot.width = shot.height = orbit["size"].get<int>();
  shot.elevation_deg = orbit["elevation_deg"].get<double>();
  shot.framing = OrbitShot::Framing::kCylinder;
  EXPECT_GT(shot.elevation_deg, 5.0);  // the simulated camera looks down on the product
  cv::Mat previous;
  for (int k : {0, 5, 12, 19}) {
    shot.azimuth_deg =
        orbit["first_azimuth_deg"].get<double>() + k * orbit["step_deg"].get<double>();
    const cv::Mat ours = RenderShot(model, shot);
    const cv::Mat jpeg = Decode(set[k].bytes);
    ASSERT_EQ(jpeg.size(), ours.size()) << k;
    EXPECT_GT(cv::PSNR(jpeg, ours), 33.0) << "360° image " << k;
    cv::Mat webp;
    cv::cvtColor(spin.frames[k], webp, cv::COLOR_BGRA2BGR);
    EXPECT_GT(cv::PSNR(webp, ours), 28.0) << "spin frame " << k;
    // The object fills the frame sanely, and the frames turn.
    const cv::Rect box = ObjectBox(jpeg);
    EXPECT_GT(std::max(box.width, box.height), 0.3 * jpeg.cols) << k;
    EXPECT_LT(std::max(box.width, box.height), 0.95 * jpeg.cols) << k;
    if (!previous.empty()) {
      EXPECT_LT(cv::PSNR(previous, jpeg), 25.0) << k;
    }
    previous = jpeg;
  }
  // The hero shot is the model seen from the hero orbit.
  const cv::Mat hero = cv::imread((model_folder / "hero.jpg").string(), cv::IMREAD_COLOR);
  OrbitShot hero_shot;
  hero_shot.width = hero_shot.height = hero.cols;
  hero_shot.framing = OrbitShot::Framing::kFit;
  EXPECT_GT(cv::PSNR(hero, RenderShot(model, hero_shot)), 33.0);
}

TEST(CatalogImagesTest, CutOutsAreThePhotosThroughTheirMasksOnWhite) {
  const std::filesystem::path session = SmallSession();
  const nlohmann::json manifest = ReadJson(session / "session.json");
  ASSERT_EQ(ReadJson(session / "model/publish.json")["catalog"]["cutouts"], 8);
  for (const int v : {0, 3, 6}) {
    const nlohmann::json& view = manifest["views"][v];
    const std::string stem = std::filesystem::path(view["image"].get<std::string>()).stem();
    const cv::Mat cut =
        cv::imread((session / "model/cutouts" / (stem + ".jpg")).string(), cv::IMREAD_COLOR);
    ASSERT_FALSE(cut.empty()) << stem;
    EXPECT_EQ(cut.rows, cut.cols);
    EXPECT_EQ(cut.cols, kSmallCutoutSize);
    // White corners, the object centred with the margin along its longer side.
    for (const cv::Point p : {cv::Point(3, 3), cv::Point(cut.cols - 4, cut.rows - 4)})
      EXPECT_GE(cut.at<cv::Vec3b>(p)[1], 250) << stem;
    const cv::Rect box = ObjectBox(cut);
    EXPECT_NEAR(box.x + 0.5 * box.width, 0.5 * cut.cols, 0.02 * cut.cols) << stem;
    EXPECT_NEAR(box.y + 0.5 * box.height, 0.5 * cut.rows, 0.02 * cut.rows) << stem;
    EXPECT_NEAR(std::max(box.width, box.height), 0.88 * cut.cols, 0.03 * cut.cols) << stem;
    // The object's colours are the photo's under its mask (the cut-out scaled up from it).
    const cv::Mat photo = ReadImage(session / view["image"].get<std::string>());
    const cv::Mat mask = ReadMask(session / view["mask"].get<std::string>());
    cv::Mat eroded;
    cv::erode(mask, eroded, cv::getStructuringElement(cv::MORPH_ELLIPSE, {7, 7}));
    const cv::Scalar photo_mean = cv::mean(photo, eroded);
    // Where the object lies in the cut-out: a black photo cut out through the same mask.
    cv::Mat inside;
    cv::cvtColor(CutOut(cv::Mat(photo.size(), CV_8UC3, cv::Scalar::all(0)), mask,
                        {.size = kSmallCutoutSize}),
                 inside, cv::COLOR_BGR2GRAY);
    // Away from the edge by about as much as the photo's mask was eroded (7 px of the photo).
    const int k = 2 * std::max(3, 7 * kSmallCutoutSize / 648 / 2) + 1;
    cv::erode(inside < 10, inside, cv::getStructuringElement(cv::MORPH_ELLIPSE, {k, k}));
    ASSERT_GT(cv::countNonZero(inside), 1000) << stem;
    const cv::Scalar cut_mean = cv::mean(cut, inside);
    for (int c = 0; c < 3; ++c) EXPECT_NEAR(cut_mean[c], photo_mean[c], 4.0) << stem << " " << c;
    // And the grey studio backdrop is gone: no backdrop-grey ring around the object.
    cv::Mat cut_grey;
    cv::cvtColor(cut, cut_grey, cv::COLOR_BGR2GRAY);
    const double grey_fraction =
        static_cast<double>(cv::countNonZero((cut_grey > 150) & (cut_grey < 235))) / cut.total();
    EXPECT_LT(grey_fraction, 0.05) << stem;
  }
}

// `carousel run` takes the publish stage's flags and records them in run.json (a resume
// publishes the same way).
TEST(CatalogImagesTest, ASessionWith24StopsMakesItsSetFromThePhotos) {
  testing::TempDir dir;
  const testing::ShellResult run = testing::RunShell(
      testing::CarouselExecutable() + " run --sim --data " + testing::SharedDataDir().string() +
      " --scene shoe --product ring24 --out " + dir.path().string() +
      " --views 24 --size 324x216 --spin-size 240 --cutout-backdrop transparent --cutout-size 256"
      " --no-report-page");
  ASSERT_EQ(run.code, 0) << run.out;
  const std::filesystem::path session = dir / "ring24";
  const nlohmann::json summary = ReadJson(session / "model/publish.json");
  ASSERT_EQ(summary["catalog"]["spin_source"], "photos");
  EXPECT_EQ(summary["catalog"]["backdrop"], "transparent");
  EXPECT_FALSE(std::filesystem::exists(session / "model/report.html"));
  const nlohmann::json recorded = ReadJson(session / "run.json");
  EXPECT_EQ(recorded["publish"]["spin-size"], 240);
  EXPECT_EQ(recorded["publish"]["cutout-backdrop"], "transparent");
  EXPECT_EQ(recorded["publish"]["report-page"], false);
  const nlohmann::json manifest = ReadJson(session / "session.json");
  // A transparent cut-out is a PNG with an alpha channel.
  const std::string stem =
      std::filesystem::path(manifest["views"][0]["image"].get<std::string>()).stem().string();
  const cv::Mat cut =
      cv::imread((session / "model/cutouts" / (stem + ".png")).string(), cv::IMREAD_UNCHANGED);
  ASSERT_FALSE(cut.empty()) << stem;
  EXPECT_EQ(cut.channels(), 4);
  EXPECT_EQ(cut.cols, 256);
  const std::vector<ZipEntry> set = ReadZip(session / "model/360.zip");
  ASSERT_EQ(set.size(), 24u);
  // Entry k is the cut-out of the photo at the k-th table angle.
  std::vector<std::pair<double, int>> by_angle;
  by_angle.reserve(24);
  for (int v = 0; v < 24; ++v)
    by_angle.emplace_back(manifest["views"][v]["table_angle_deg"].get<double>(), v);
  std::sort(by_angle.begin(), by_angle.end());
  for (const int k : {0, 7, 23}) {
    const nlohmann::json& view = manifest["views"][by_angle[k].second];
    const cv::Mat expected = CutOut(ReadImage(session / view["image"].get<std::string>()),
                                    ReadMask(session / view["mask"].get<std::string>()),
                                    {.backdrop = CutoutBackdrop::kTransparent, .size = 240});
    const cv::Mat image = cv::imdecode(set[k].bytes, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(image.size(), expected.size());
    ASSERT_EQ(image.type(), expected.type());
    EXPECT_GT(cv::PSNR(image, expected), 33.0) << k;
  }
}

// A camera mounted on its side: the session's photos and masks turned a quarter clockwise, its
// cameras turned with them. The cut-outs come out upright, the same as the upright session's.
TEST(CatalogImagesTest, PhotosOfASidewaysCameraGiveUprightCutouts) {
  testing::TempDir dir;
  const std::filesystem::path session = dir / "sideways";
  std::filesystem::copy(SmallSession(), session, std::filesystem::copy_options::recursive);
  std::filesystem::remove_all(session / "model/cutouts");
  nlohmann::json manifest = ReadJson(session / "session.json");
  for (nlohmann::json& view : manifest["views"]) {
    for (const char* key : {"image", "mask"}) {
      const std::filesystem::path file = session / view[key].get<std::string>();
      cv::Mat image = cv::imread(file.string(), cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(image.empty()) << file;
      cv::rotate(image, image, cv::ROTATE_90_CLOCKWISE);
      ASSERT_TRUE(cv::imwrite(file.string(), image, {cv::IMWRITE_JPEG_QUALITY, 100}));
    }
    view.erase("sha256");
    // Pixel (u, v) moves to (H - 1 - v, u): x' = -y, y' = x in the camera frame.
    nlohmann::json& c = view["camera_model"];
    const int width = c["width"], height = c["height"];
    const double cx = c["cx"], cy = c["cy"], fx = c["fx"], fy = c["fy"];
    c["width"] = height;
    c["height"] = width;
    c["fx"] = fy;
    c["fy"] = fx;
    c["cx"] = height - 1 - cy;
    c["cy"] = cx;
    std::vector<double> r = c["cam_from_world"]["rotation_row_major"];
    std::vector<double> t = c["cam_from_world"]["translation"];
    c["cam_from_world"]["rotation_row_major"] = {-r[3], -r[4], -r[5], r[0], r[1],
                                                 r[2],  r[6],  r[7],  r[8]};
    c["cam_from_world"]["translation"] = {-t[1], t[0], t[2]};
  }
  testing::WriteBytes(session / "session.json", manifest.dump(2));
  const testing::ShellResult run = testing::RunShell(testing::CarouselExecutable() + " publish " +
                                                     session.string() + " --no-report-page");
  ASSERT_EQ(run.code, 0) << run.out;
  const nlohmann::json summary = ReadJson(session / "model/publish.json");
  const int cutouts = summary["catalog"]["cutouts"];
  EXPECT_EQ(cutouts, static_cast<int>(manifest["views"].size()));
  EXPECT_EQ(summary["catalog"]["cutouts_turned_upright"], cutouts);
  for (const auto& view : manifest["views"]) {
    const std::string name =
        std::filesystem::path(view["image"].get<std::string>()).stem().string() + ".jpg";
    const cv::Mat upright = cv::imread((SmallSession() / "model/cutouts" / name).string());
    const cv::Mat turned = cv::imread((session / "model/cutouts" / name).string());
    ASSERT_EQ(turned.size(), upright.size()) << name;
    // Compared at 1/8 size (the crop may differ by a source pixel, 2.5 px of the cut-out), and
    // against the cut-out turned the wrong way.
    cv::Mat a, b, wrong;
    cv::resize(turned, a, upright.size() / 8, 0, 0, cv::INTER_AREA);
    cv::resize(upright, b, upright.size() / 8, 0, 0, cv::INTER_AREA);
    cv::rotate(b, wrong, cv::ROTATE_90_CLOCKWISE);
    EXPECT_GT(cv::PSNR(a, b), 24.0) << name;
    EXPECT_GT(cv::PSNR(a, b), cv::PSNR(a, wrong) + 10.0) << name << ": " << cv::PSNR(a, wrong);
  }
  const nlohmann::json upright_summary = ReadJson(SmallSession() / "model/publish.json");
  EXPECT_EQ(upright_summary["catalog"]["cutouts_turned_upright"], 0);
}

// `carousel publish` goes on with the options the session last published with; a flag changes
// only what it names.
TEST(CatalogImagesTest, PublishingAgainKeepsTheSessionsOptionsAndAFlagChangesOnlyItsOwn) {
  testing::TempDir dir;
  const std::filesystem::path session = dir / "s";
  std::filesystem::copy(SmallSession(), session, std::filesystem::copy_options::recursive);
  const std::string publish = testing::CarouselExecutable() + " publish " + session.string();
  const auto cutout_side = [&] {
    const std::string stem =
        std::filesystem::path(
            ReadJson(session / "session.json")["views"][0]["image"].get<std::string>())
            .stem()
            .string();
    return cv::imread((session / "model/cutouts" / (stem + ".jpg")).string()).cols;
  };
  const testing::ShellResult changed =
      testing::RunShell(publish + " --cutout-size 320 --spin-frames 0");
  ASSERT_EQ(changed.code, 0) << changed.out;
  nlohmann::json options = ReadJson(session / "model/publish.json")["options"];
  EXPECT_EQ(options["cutout-size"], 320);
  EXPECT_EQ(options["spin-frames"], 0);
  EXPECT_EQ(options["hero-size"], 640);  // as the session was made
  EXPECT_EQ(cutout_side(), 320);
  EXPECT_FALSE(std::filesystem::exists(session / "model/360.zip"));  // the earlier one goes
  EXPECT_FALSE(std::filesystem::exists(session / "model/spin.webp"));
  const testing::ShellResult again = testing::RunShell(publish + " --hero-size 500");
  ASSERT_EQ(again.code, 0) << again.out;
  options = ReadJson(session / "model/publish.json")["options"];
  EXPECT_EQ(options["cutout-size"], 320);
  EXPECT_EQ(options["spin-frames"], 0);
  EXPECT_EQ(options["hero-size"], 500);
  EXPECT_EQ(cutout_side(), 320);
  EXPECT_EQ(cv::imread((session / "model/hero.jpg").string()).cols, 500);
  // A malformed record is named.
  nlohmann::json summary = ReadJson(session / "model/publish.json");
  summary["options"]["cutout-size"] = "big";
  testing::WriteBytes(session / "model/publish.json", summary.dump());
  const testing::ShellResult bad = testing::RunShell(publish);
  EXPECT_NE(bad.code, 0);
  EXPECT_THAT(bad.out, HasSubstr("publish.json"));
  EXPECT_THAT(bad.out, HasSubstr("cutout-size"));
}

TEST(ReportPageTest, TheSessionsReportShowsItsFiguresAndEveryImageItNames) {
  const std::filesystem::path model_folder = SmallSession() / "model";
  const std::string html = testing::ReadBytes(model_folder / "report.html");
  const nlohmann::json report = ReadJson(model_folder / "report.json");
  const nlohmann::json summary = ReadJson(model_folder / "publish.json");
  // The histogram's bars count every face.
  const std::regex bar("data-count=\"([0-9]+)\"");
  int total = 0;
  for (auto it = std::sregex_iterator(html.begin(), html.end(), bar); it != std::sregex_iterator();
       ++it)
    total += std::stoi((*it)[1]);
  EXPECT_EQ(total, report["faces"].get<int>());
  // The held-out view with both GLBs' scores, as publish.json has them.
  char psnr[32];
  std::snprintf(psnr, sizeof psnr, "%.2f",
                summary["held_out"]["views"][0]["psnr_db_web"].get<double>());
  EXPECT_THAT(html, HasSubstr(psnr));
  EXPECT_THAT(html, HasSubstr("report/heldout_03.jpg"));
  for (const char* stage : {"capture", "reconstruct", "texture", "texture/atlas"})
    EXPECT_THAT(html, HasSubstr(std::string("<td>") + stage + "</td>"));
  // Every image it names exists and decodes; the held-out one is photo | render.
  const std::regex img("src=\"([^\"]+)\"");
  int images = 0;
  for (auto it = std::sregex_iterator(html.begin(), html.end(), img); it != std::sregex_iterator();
       ++it, ++images) {
    const cv::Mat image = cv::imread((model_folder / (*it)[1].str()).string(), cv::IMREAD_COLOR);
    EXPECT_FALSE(image.empty()) << (*it)[1];
  }
  EXPECT_GE(images, 5);
  const cv::Mat pair = cv::imread((model_folder / "report/heldout_03.jpg").string());
  EXPECT_GT(pair.cols, pair.rows);
}

std::map<std::string, std::filesystem::file_time_type> Times(const std::filesystem::path& root) {
  std::map<std::string, std::filesystem::file_time_type> times;
  for (const auto& e : std::filesystem::recursive_directory_iterator(root))
    if (e.is_regular_file())
      times[std::filesystem::relative(e.path(), root).string()] = e.last_write_time();
  return times;
}

TEST(SiteTest, TheCatalogLinksEveryProductAndPublishingTwiceChangesNothing) {
  testing::TempDir dir;
  for (const char* name : {"shoe-a", "shoe b"})
    std::filesystem::copy(SmallSession(), dir / name, std::filesystem::copy_options::recursive);
  const std::filesystem::path site = dir / "site";
  const std::string publish = testing::CarouselExecutable() + " publish '" +
                              (dir / "shoe-a").string() + "' '" + (dir / "shoe b").string() +
                              "' --out " + site.string();
  const testing::ShellResult first = testing::RunShell(publish);
  ASSERT_EQ(first.code, 0) << first.out;
  EXPECT_THAT(first.out, HasSubstr("lists 2 products"));
  const std::string index = testing::ReadBytes(site / "index.html");
  EXPECT_THAT(index, HasSubstr("href=\"shoe-a/index.html\""));
  EXPECT_THAT(index, HasSubstr("href=\"shoe-b/index.html\""));
  const std::string page = testing::ReadBytes(site / "shoe-a/index.html");
  EXPECT_THAT(page, HasSubstr("../assets/model-viewer.min.js"));
  EXPECT_TRUE(std::filesystem::is_regular_file(site / "assets/model-viewer.min.js"));
  EXPECT_TRUE(std::filesystem::is_regular_file(site / "assets/meshopt_decoder.js"));
  EXPECT_FALSE(std::filesystem::exists(site / "shoe-a/model-viewer.min.js"));
  const nlohmann::json published = ReadJson(dir / "shoe-a/model/publish.json");
  for (const auto& f : published["files"]) {
    const std::string name = f.get<std::string>();
    if (name == "model-viewer.min.js" || name == "meshopt_decoder.js") continue;
    EXPECT_TRUE(std::filesystem::is_regular_file(site / "shoe-a" / name)) << name;
  }
  EXPECT_EQ(testing::ReadBytes(site / "shoe-a/model.web.glb"),
            testing::ReadBytes(dir / "shoe-a/model/model.web.glb"));

  // Twice: the same bytes, not one file rewritten; a stray file in a product folder goes.
  const auto times = Times(site);
  testing::WriteBytes(site / "shoe-a/stale.jpg", "old");
  const testing::ShellResult second = testing::RunShell(publish);
  ASSERT_EQ(second.code, 0) << second.out;
  EXPECT_THAT(second.out, HasSubstr("0 files written"));
  EXPECT_FALSE(std::filesystem::exists(site / "shoe-a/stale.jpg"));
  EXPECT_EQ(Times(site), times);
  // The session's own model folder was not rewritten either (same bytes).
  EXPECT_EQ(testing::ReadBytes(dir / "shoe-a/model/model.web.glb"),
            testing::ReadBytes(SmallSession() / "model/model.web.glb"));
}

// The lossless GLB with its texture taken out: what a foreign or damaged export looks like.
void DropTexture(const std::filesystem::path& glb) {
  const std::string bytes = testing::ReadBytes(glb);
  std::uint32_t json_length = 0;
  std::memcpy(&json_length, bytes.data() + 12, 4);
  nlohmann::json gltf = nlohmann::json::parse(bytes.substr(20, json_length));
  gltf.erase("textures");
  gltf.erase("images");
  gltf.erase("samplers");
  for (auto& m : gltf["materials"]) m["pbrMetallicRoughness"].erase("baseColorTexture");
  std::string json = gltf.dump();
  while (json.size() % 4 != 0) json += ' ';
  const std::string bin = bytes.substr(20 + json_length);
  std::string out(12, '\0');
  const std::uint32_t header[3] = {0x46546C67u, 2u,
                                   static_cast<std::uint32_t>(12 + 8 + json.size() + bin.size())};
  std::memcpy(out.data(), header, 12);
  const std::uint32_t chunk[2] = {static_cast<std::uint32_t>(json.size()), 0x4E4F534Au};
  out.append(reinterpret_cast<const char*>(chunk), 8);
  out += json + bin;
  testing::WriteBytes(glb, out);
}

TEST(SiteTest, BadInputIsNamedAndNothingPublishedIsLost) {
  testing::TempDir dir;
  std::filesystem::copy(SmallSession(), dir / "s", std::filesystem::copy_options::recursive);
  // An unwritable site folder: its parent is a file.
  testing::WriteBytes(dir / "file", "x");
  const testing::ShellResult unwritable =
      testing::RunShell(testing::CarouselExecutable() + " publish " + (dir / "s").string() +
                        " --out " + (dir / "file/site").string());
  EXPECT_NE(unwritable.code, 0);
  EXPECT_THAT(unwritable.out, HasSubstr((dir / "file/site").string()));
  EXPECT_THAT(unwritable.out, HasSubstr("site folder"));
  // A GLB without a texture.
  const std::string web_before = testing::ReadBytes(dir / "s/model/model.web.glb");
  DropTexture(dir / "s/model/model.glb");
  const testing::ShellResult untextured =
      testing::RunShell(testing::CarouselExecutable() + " publish " + (dir / "s").string());
  EXPECT_NE(untextured.code, 0);
  EXPECT_THAT(untextured.out, HasSubstr("model.glb"));
  EXPECT_THAT(untextured.out, HasSubstr("no base colour texture"));
  EXPECT_EQ(testing::ReadBytes(dir / "s/model/model.web.glb"), web_before);
  // A session without a model.
  std::filesystem::remove(dir / "s/model/model.glb");
  const testing::ShellResult missing =
      testing::RunShell(testing::CarouselExecutable() + " publish " + (dir / "s").string());
  EXPECT_NE(missing.code, 0);
  EXPECT_THAT(missing.out, HasSubstr("model.glb"));
  EXPECT_THAT(missing.out, HasSubstr("carousel texture"));
}

}  // namespace
}  // namespace carousel::publish
