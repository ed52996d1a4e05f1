#include "carousel/calib/intrinsics.h"

#include <cmath>
#include <random>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel::calib {
namespace {

using carousel::testing::TempDir;
using ::testing::HasSubstr;

std::vector<std::filesystem::path> OpenCvLeftImages() {
  std::vector<std::filesystem::path> images;
  for (const int i : {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14}) {
    char name[32];
    std::snprintf(name, sizeof name, "calib/images/left%02d.jpg", i);
    images.push_back(carousel::testing::SharedDataFile(name));
  }
  return images;
}

// A photo of `board` printed on a card at `cam_from_board`, through `camera` (lens
// distortion included), rendered by the simulated rig with sensor noise.
cv::Mat PhotographBoard(const CameraModel& camera, const BoardSpec& board,
                        const Rigid3d& cam_from_board, std::uint64_t seed) {
  const BoardImage drawn = DrawBoard(board, 80, 40);
  const sim::Scene card = sim::MakePrintedCardScene(
      drawn.image, drawn.board_from_pixel, camera.cam_from_world.Inverse() * cam_from_board);
  sim::RenderOptions options;
  options.plate_radius_m = 0.0;
  options.noise_sigma = 2.0;
  options.seed = seed;
  options.lit = false;
  cv::Mat gray;
  cv::cvtColor(sim::Render(card, camera, 0.0, options).image, gray, cv::COLOR_BGR2GRAY);
  return gray;
}

Rigid3d BoardPose(double tilt_x_deg, double tilt_y_deg, double roll_deg, const Eigen::Vector3d& t) {
  const double d = M_PI / 180.0;
  Rigid3d pose;
  pose.rotation = Eigen::AngleAxisd(roll_deg * d, Eigen::Vector3d::UnitZ()) *
                  Eigen::AngleAxisd(tilt_y_deg * d, Eigen::Vector3d::UnitY()) *
                  Eigen::AngleAxisd(tilt_x_deg * d, Eigen::Vector3d::UnitX()).toRotationMatrix();
  pose.translation = t;
  return pose;
}

TEST(BoardSpecTest, ParsesAndNamesWhatIsWrong) {
  const BoardSpec b = BoardSpec::Parse("chessboard:9x6:0.025");
  EXPECT_EQ(b.cols, 9);
  EXPECT_EQ(b.rows, 6);
  EXPECT_DOUBLE_EQ(b.square_m, 0.025);
  EXPECT_EQ(BoardSpec::Parse(b.ToString()).cols, 9);
  const auto points = b.ObjectPoints();
  ASSERT_EQ(points.size(), 54U);
  EXPECT_FLOAT_EQ(points[10].x, 0.025F);  // row 1, column 1
  EXPECT_FLOAT_EQ(points[10].y, 0.025F);
  EXPECT_THAT([] { BoardSpec::Parse("chessboard:9x6"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("COLSxROWS")));
  EXPECT_THAT([] { BoardSpec::Parse("chessboard:9by6:0.02"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("9x6")));
  EXPECT_THAT([] { BoardSpec::Parse("chessboard:9x6:big"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("\"big\"")));
  EXPECT_THAT([] { BoardSpec::Parse("chessboard:7x7:0.02"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("half round")));
  EXPECT_THAT([] { BoardSpec::Parse("chessboard:2x6:0.02"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("3..100")));
  // ChArUco: squares, square and marker sides, the dictionary.
  const BoardSpec c = BoardSpec::Parse("charuco:7x5:0.04:0.03:DICT_6X6_250");
  EXPECT_EQ(c.kind, BoardKind::kCharuco);
  EXPECT_EQ(c.CornersX(), 6);
  EXPECT_EQ(c.CornersY(), 4);
  EXPECT_EQ(c.ObjectPoints().size(), 24U);
  EXPECT_NEAR(c.WidthM(), 0.28, 1e-12);
  EXPECT_EQ(BoardSpec::Parse(c.ToString()).dictionary, "DICT_6X6_250");
  EXPECT_THAT([] { BoardSpec::Parse("charuco:7x5:0.04:0.05:DICT_6X6_250"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("marker side")));
  EXPECT_THAT([] { BoardSpec::Parse("charuco:7x5:0.04:0.03:DICT_9X9_1"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("unknown ArUco dictionary")));
  EXPECT_THAT([] { BoardSpec::Parse("charuco:30x30:0.01:0.007:DICT_4X4_50"); },
              ::testing::ThrowsMessage<InvalidArgument>(HasSubstr("needs 450 markers")));
}

// The drawing's map from pixels to the board frame puts every corner where detection finds it.
TEST(BoardSpecTest, DrawnBoardsMapPixelsToTheBoardFrame) {
  for (const char* spec : {"chessboard:9x6:0.025", "charuco:7x5:0.04:0.03:DICT_6X6_250"}) {
    const BoardSpec board = BoardSpec::Parse(spec);
    const BoardImage drawn = DrawBoard(board, 60, 30);
    const BoardDetection d = DetectBoard(drawn.image, board);
    ASSERT_TRUE(d.found) << spec << ": " << d.reason;
    ASSERT_EQ(d.ids.size(), board.ObjectPoints().size()) << spec;
    const std::vector<cv::Point3f> object = board.ObjectPoints();
    double worst = 0.0;
    for (std::size_t i = 0; i < d.ids.size(); ++i) {
      const Eigen::Vector2d xy =
          drawn.board_from_pixel * Eigen::Vector3d(d.corners[i].x, d.corners[i].y, 1.0);
      const cv::Point3f& p = object[static_cast<std::size_t>(d.ids[i])];
      worst = std::max(worst, (xy - Eigen::Vector2d(p.x, p.y)).norm());
    }
    // Corners refined in a perfectly sharp drawing sit within a few tenths of a pixel.
    EXPECT_LT(worst, 0.3 * board.square_m / 60) << spec;
    EXPECT_LT(d.edge_width_px, 1.5) << spec;  // a sharp drawing
  }
}

// Ground truth: boards photographed by the simulated rig through a known lens with distortion
// and noise, a chessboard and a ChArUco board (partly outside the picture in some views).
TEST(IntrinsicsTest, RecoversARenderedLensWithinTightBounds) {
  CameraModel truth;
  truth.width = 800;
  truth.height = 600;
  truth.fx = 900.0;
  truth.fy = 902.0;
  truth.cx = 405.3;
  truth.cy = 296.1;
  truth.distortion.k1 = -0.12;
  truth.distortion.k2 = 0.05;
  // Tilted boards spread over the image, near its corners too.
  const double tilts[][3] = {{25, 0, 0},    {-25, 10, 5},  {0, 30, -8},  {15, -25, 12},
                             {-20, -20, 3}, {30, 20, -15}, {10, 10, 90}, {-15, 25, 80}};
  const Eigen::Vector3d shifts[] = {{-0.17, -0.12, 0.55}, {0.02, -0.13, 0.55}, {-0.17, 0.0, 0.6},
                                    {0.0, 0.02, 0.6},     {-0.14, -0.12, 0.7}, {-0.08, -0.06, 0.5},
                                    {0.12, -0.12, 0.6},   {0.12, -0.02, 0.55}};
  for (const char* spec : {"chessboard:9x6:0.03", "charuco:9x7:0.03:0.022:DICT_5X5_100"}) {
    const BoardSpec board = BoardSpec::Parse(spec);
    std::vector<NamedImage> images;
    for (int i = 0; i < 8; ++i) {
      const Rigid3d pose = BoardPose(tilts[i][0], tilts[i][1], tilts[i][2], shifts[i]);
      images.push_back({"view" + std::to_string(i), PhotographBoard(truth, board, pose, i)});
    }
    Progress progress;
    const IntrinsicsResult r = CalibrateIntrinsics(images, board, IntrinsicsOptions{}, progress);
    // A chessboard must be whole: the views that cut it off are refused (ChArUco keeps them).
    for (const ViewReport& v : r.views) {
      if (!v.used) std::printf("%s %s: %s\n", spec, v.name.c_str(), v.reason.c_str());
    }
    EXPECT_GE(r.UsedViews(), board.kind == BoardKind::kCharuco ? 8 : 6) << spec;
    EXPECT_LT(r.rms_px, 0.3) << spec;
    EXPECT_NEAR(r.camera.fx / truth.fx, 1.0, 0.005) << spec;
    EXPECT_NEAR(r.camera.fy / truth.fy, 1.0, 0.005) << spec;
    EXPECT_NEAR(r.camera.cx, truth.cx, 2.0) << spec;
    EXPECT_NEAR(r.camera.cy, truth.cy, 2.0) << spec;
    // The lens: a point near the image corner lands where the true lens puts it.
    const Eigen::Vector2d corner_ray(0.4, 0.3);
    const Eigen::Vector2d expected = truth.PixelFromNormalized(truth.distortion.Apply(corner_ray));
    const Eigen::Vector2d got = r.camera.PixelFromNormalized(r.camera.distortion.Apply(corner_ray));
    EXPECT_LT((got - expected).norm(), 3.0) << spec;
    std::printf(
        "%s, rendered lens: fx %.2f (%.2f) fy %.2f (%.2f) cx %.2f (%.2f) cy %.2f (%.2f) "
        "k1 %.4f (%.4f) rms %.3f px; corner point off by %.2f px\n",
        spec, r.camera.fx, truth.fx, r.camera.fy, truth.fy, r.camera.cx, truth.cx, r.camera.cy,
        truth.cy, r.camera.distortion.k1, truth.distortion.k1, r.rms_px, (got - expected).norm());
  }
}

// OpenCV's own sample photos against its published calibration of them.
TEST(IntrinsicsTest, OpenCvSamplePhotosMatchThePublishedIntrinsics) {
  const CameraModel published =
      ReadOpenCvIntrinsics(carousel::testing::SharedDataFile("calib/left_intrinsics.yml"));
  EXPECT_EQ(published.width, 640);
  EXPECT_NEAR(published.fx, 535.9157, 1e-3);
  EXPECT_NEAR(published.distortion.k3, 0.2384, 1e-4);

  Progress progress;
  IntrinsicsOptions options;
  options.fix_aspect_ratio = true;  // as the published run (flags: 2)
  const IntrinsicsResult r = CalibrateIntrinsics(
      OpenCvLeftImages(), BoardSpec::Parse("chessboard:9x6:0.025"), options, progress);
  EXPECT_GE(r.UsedViews(), 12);
  EXPECT_NEAR(r.camera.fx / published.fx, 1.0, 0.01);
  EXPECT_NEAR(r.camera.fy / published.fy, 1.0, 0.01);
  EXPECT_NEAR(r.camera.cx / published.cx, 1.0, 0.01);
  EXPECT_NEAR(r.camera.cy / published.cy, 1.0, 0.01);
  EXPECT_LT(r.rms_px, 0.5);
  std::printf(
      "OpenCV left photos: %d/%zu views, fx %.2f fy %.2f cx %.2f cy %.2f (published "
      "%.2f %.2f %.2f %.2f), RMS %.3f px, coverage %.0f %%\n",
      r.UsedViews(), r.views.size(), r.camera.fx, r.camera.fy, r.camera.cx, r.camera.cy,
      published.fx, published.fy, published.cx, published.cy, r.rms_px, 100.0 * r.cell_coverage);
  for (const ViewReport& v : r.views) {
    std::printf("  %s: %s %.3f px %s\n", v.name.c_str(), v.used ? "used" : "rejected", v.rms_px,
                v.reason.c_str());
  }

  // Written as OpenCV's YAML and read back (by us and by OpenCV).
  TempDir dir;
  const auto yml = dir / "left.yml";
  WriteOpenCvIntrinsics(yml, r, BoardSpec::Parse("chessboard:9x6:0.025"));
  const CameraModel back = ReadOpenCvIntrinsics(yml);
  EXPECT_DOUBLE_EQ(back.fx, r.camera.fx);
  EXPECT_DOUBLE_EQ(back.distortion.k2, r.camera.distortion.k2);
  cv::FileStorage fs(yml.string(), cv::FileStorage::READ);
  EXPECT_EQ(static_cast<int>(fs["nframes"]), r.UsedViews());
}

// OpenCV's calibrateCamera with its default model (k1 k2 p1 p2 k3 free) on our detections.
CameraModel OpenCvOnTheSameDetections(const std::vector<std::filesystem::path>& images,
                                      const BoardSpec& board) {
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  cv::Size size;
  for (const auto& path : images) {
    const cv::Mat gray = cv::imread(path.string(), cv::IMREAD_GRAYSCALE);
    size = gray.size();
    const BoardDetection d = DetectBoard(gray, board);
    if (!d.found) continue;
    const std::vector<cv::Point3f> all = board.ObjectPoints();
    object.emplace_back();
    for (const int id : d.ids) object.back().push_back(all[static_cast<std::size_t>(id)]);
    image.push_back(d.corners);
  }
  cv::Mat k;
  cv::Mat dist;
  std::vector<cv::Mat> rvecs;
  std::vector<cv::Mat> tvecs;
  cv::calibrateCamera(object, image, size, k, dist, rvecs, tvecs);
  CameraModel c;
  c.fx = k.at<double>(0, 0);
  c.fy = k.at<double>(1, 1);
  c.cx = k.at<double>(0, 2);
  c.cy = k.at<double>(1, 2);
  return c;
}

// Few real photos: 4-view subsets of OpenCV's sample photos hold k3 (and only k3: the boards
// reach out to the image corners) and agree with OpenCV's own calibration of the same
// detections within 0.5 %; the standard deviations shrink with more views, and a two-view
// calibration whose focal length is off is flagged weak.
TEST(IntrinsicsTest, FewRealPhotosHoldK3AgreeWithOpenCvAndReportTheirUncertainty) {
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:0.025");
  const std::vector<std::filesystem::path> all = OpenCvLeftImages();
  Progress progress;
  const IntrinsicsResult whole = CalibrateIntrinsics(all, board, IntrinsicsOptions{}, progress);
  EXPECT_TRUE(whole.held.empty());
  EXPECT_FALSE(whole.weak);
  const CameraModel cv_whole = OpenCvOnTheSameDetections(all, board);
  const auto agree = [](const CameraModel& ours, const CameraModel& theirs,
                        const std::string& what) {
    EXPECT_NEAR(ours.fx / theirs.fx, 1.0, 0.005) << what;
    EXPECT_NEAR(ours.fy / theirs.fy, 1.0, 0.005) << what;
    EXPECT_NEAR(ours.cx / theirs.cx, 1.0, 0.005) << what;
    EXPECT_NEAR(ours.cy / theirs.cy, 1.0, 0.005) << what;
  };
  agree(whole.camera, cv_whole, "13 views");
  std::printf(
      "13 views: fx %.2f fy %.2f cx %.2f cy %.2f (sd %.2f %.2f %.2f %.2f) OpenCV %.2f "
      "%.2f %.2f %.2f\n",
      whole.camera.fx, whole.camera.fy, whole.camera.cx, whole.camera.cy, whole.std_fx,
      whole.std_fy, whole.std_cx, whole.std_cy, cv_whole.fx, cv_whole.fy, cv_whole.cx, cv_whole.cy);
  IntrinsicsOptions few;
  few.min_views = 2;
  for (const std::size_t count : {4u, 2u}) {
    for (std::size_t first = 0; first < all.size(); first += 4) {
      std::vector<std::filesystem::path> subset;
      for (std::size_t j = 0; j < count; ++j) subset.push_back(all[(first + j) % all.size()]);
      const std::string what =
          std::to_string(count) + " views from " + subset[0].filename().string();
      const IntrinsicsResult r = CalibrateIntrinsics(subset, board, few, progress);
      ASSERT_EQ(r.UsedViews(), static_cast<int>(count)) << what;
      EXPECT_EQ(r.held, std::vector<std::string>{"k3"}) << what;
      EXPECT_GT(r.corner_reach, IntrinsicsOptions::kNearCentreReach) << what;
      const CameraModel cv = OpenCvOnTheSameDetections(subset, board);
      const double fx_off = std::abs(r.camera.fx / whole.camera.fx - 1.0);
      std::printf(
          "%s: fx %.2f fy %.2f cx %.2f cy %.2f (sd %.2f %.2f %.2f %.2f)%s; OpenCV %.2f "
          "%.2f %.2f %.2f; fx %.2f %% off the 13 views'\n",
          what.c_str(), r.camera.fx, r.camera.fy, r.camera.cx, r.camera.cy, r.std_fx, r.std_fy,
          r.std_cx, r.std_cy, r.weak ? " weak" : "", cv.fx, cv.fy, cv.cx, cv.cy, 100.0 * fx_off);
      // More views, smaller standard deviations.
      EXPECT_GT(r.std_fx, whole.std_fx) << what;
      EXPECT_GT(r.std_cx, whole.std_cx) << what;
      if (count == 4) {
        agree(r.camera, cv, what);
        EXPECT_FALSE(r.weak) << what;
      } else if (fx_off > 0.01) {
        EXPECT_TRUE(r.weak) << what;
        EXPECT_THAT(r.warnings.back(),
                    HasSubstr("a weak calibration: one standard deviation of fx"))
            << what;
      }
    }
  }
}

// Boards that stay near the image centre leave k2 unconstrained: with few views it is held
// too (and the option switches the holding off).
TEST(IntrinsicsTest, BoardsNearTheCentreHoldK2AsWell) {
  CameraModel truth;
  truth.width = 800;
  truth.height = 600;
  truth.fx = truth.fy = 900.0;
  truth.cx = 400.0;
  truth.cy = 300.0;
  truth.distortion.k1 = -0.12;
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:0.03");
  const double tilts[][3] = {{25, 0, 0}, {-25, 10, 5}, {0, 30, -8}, {15, -25, 12}};
  std::vector<NamedImage> images;
  for (int i = 0; i < 4; ++i) {
    const Rigid3d pose =
        BoardPose(tilts[i][0], tilts[i][1], tilts[i][2], Eigen::Vector3d(-0.12, -0.075, 1.3));
    images.push_back({"view" + std::to_string(i), PhotographBoard(truth, board, pose, i)});
  }
  Progress progress;
  const IntrinsicsResult r = CalibrateIntrinsics(images, board, IntrinsicsOptions{}, progress);
  std::printf("boards near the centre: reach %.2f, fx %.1f (sd %.1f)%s\n", r.corner_reach,
              r.camera.fx, r.std_fx, r.weak ? " weak" : "");
  EXPECT_EQ(r.UsedViews(), 4);
  EXPECT_LT(r.corner_reach, IntrinsicsOptions::kNearCentreReach);
  EXPECT_EQ(r.held, (std::vector<std::string>{"k2", "k3"}));
  EXPECT_EQ(r.camera.distortion.k2, 0.0);
  EXPECT_EQ(r.camera.distortion.k3, 0.0);
  IntrinsicsOptions free;
  free.hold_weak_terms = false;
  const IntrinsicsResult f = CalibrateIntrinsics(images, board, free, progress);
  EXPECT_TRUE(f.held.empty());
  EXPECT_NE(f.camera.distortion.k2, 0.0);
}

// --out by extension: .json is ours (read back bit for bit), .yml/.xml OpenCV's, anything else
// is refused before calibrating.
TEST(IntrinsicsTest, TheFileFormatFollowsTheExtension) {
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:0.025");
  std::vector<std::filesystem::path> images = OpenCvLeftImages();
  images.resize(5);
  Progress progress;
  const IntrinsicsResult r = CalibrateIntrinsics(images, board, IntrinsicsOptions{}, progress);
  TempDir dir;
  WriteIntrinsics(dir / "cam.json", r, board);
  const nlohmann::json j = nlohmann::json::parse(carousel::testing::ReadBytes(dir / "cam.json"));
  EXPECT_DOUBLE_EQ(j.at("std_px").at("fx").get<double>(), r.std_fx);
  EXPECT_EQ(j.at("held"), nlohmann::json::array({"k3"}));
  EXPECT_EQ(j.at("views").size(), 5u);
  EXPECT_EQ(j.at("board"), board.ToString());
  EXPECT_FALSE(j.at("camera").contains("cam_from_world"));
  const CameraModel json_back = ReadIntrinsics(dir / "cam.json");
  EXPECT_EQ(json_back.fx, r.camera.fx);
  EXPECT_EQ(json_back.distortion.k1, r.camera.distortion.k1);
  EXPECT_EQ(json_back.width, 640);
  for (const char* name : {"cam.yml", "cam.xml"}) {
    WriteIntrinsics(dir / name, r, board);
    cv::FileStorage fs((dir / name).string(), cv::FileStorage::READ);
    cv::Mat k;
    fs["camera_matrix"] >> k;
    EXPECT_DOUBLE_EQ(k.at<double>(0, 0), r.camera.fx) << name;
    EXPECT_EQ(static_cast<std::string>(fs["held_terms"]), "k3") << name;
    EXPECT_DOUBLE_EQ(ReadIntrinsics(dir / name).cy, r.camera.cy) << name;
  }
  CAROUSEL_EXPECT_THROW_WITH(WriteIntrinsics(dir / "cam.txt", r, board), InvalidArgument,
                             "name it .json");
  EXPECT_FALSE(std::filesystem::exists(dir / "cam.txt"));
  // A broken JSON file is named.
  WriteFileAtomic(dir / "bad.json", std::string("{\"camera\": {\"fx\": 1}}"));
  CAROUSEL_EXPECT_THROW_WITH(ReadIntrinsics(dir / "bad.json"), FormatError, "bad.json");
}

TEST(IntrinsicsTest, BadPhotosAreRejectedWithTheirReason) {
  TempDir dir;
  std::vector<std::filesystem::path> images = OpenCvLeftImages();
  images.resize(4);
  const cv::Mat photo = cv::imread(images[0].string(), cv::IMREAD_GRAYSCALE);
  ASSERT_FALSE(photo.empty());
  // Garbage, a grey picture, the board half cut off, the board shrunk to a speck.
  carousel::testing::WriteBytes(dir / "corrupt.jpg", "\xFF\xD8\xFF garbage");
  cv::imwrite((dir / "blank.png").string(), cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)));
  cv::Mat cut = photo.clone();
  cut.colRange(320, 640).setTo(cv::Scalar(128));
  cv::imwrite((dir / "cut.png").string(), cut);
  cv::Mat speck(480, 640, CV_8UC1, cv::Scalar(200));
  cv::Mat small;
  cv::resize(photo, small, cv::Size(80, 60), 0, 0, cv::INTER_AREA);
  small.copyTo(speck(cv::Rect(10, 10, 80, 60)));
  cv::imwrite((dir / "speck.png").string(), speck);
  cv::Mat blurred;
  cv::GaussianBlur(photo, blurred, cv::Size(0, 0), 3.0);
  cv::imwrite((dir / "blurred.png").string(), blurred);
  for (const char* name : {"corrupt.jpg", "blank.png", "cut.png", "speck.png", "blurred.png"}) {
    images.push_back(dir / name);
  }

  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:0.025");
  Progress progress;
  IntrinsicsOptions options;
  options.detect.min_board_area_fraction = 0.05;
  options.detect.max_edge_width_px = 4.0;
  const IntrinsicsResult r = CalibrateIntrinsics(images, board, options, progress);
  ASSERT_EQ(r.views.size(), 9U);
  const auto reason = [&](std::size_t i) { return r.views[i].reason; };
  EXPECT_THAT(reason(4), HasSubstr("cannot be read"));
  EXPECT_THAT(reason(5), HasSubstr("no complete 9x6 chessboard"));
  EXPECT_THAT(reason(6), HasSubstr("no complete 9x6 chessboard"));
  EXPECT_THAT(reason(7), ::testing::AnyOf(HasSubstr("too small"), HasSubstr("no complete")));
  EXPECT_THAT(reason(8), ::testing::AnyOf(HasSubstr("blurred"), HasSubstr("no complete")));
  for (std::size_t i = 4; i < 9; ++i) EXPECT_FALSE(r.views[i].used) << r.views[i].name;
  EXPECT_EQ(r.UsedViews(), 4);
  EXPECT_FALSE(r.warnings.empty());  // 4 views are few

  // Too few usable photos: an error that lists every rejected file and why.
  options.min_views = 6;
  try {
    CalibrateIntrinsics(images, board, options, progress);
    ADD_FAILURE() << "calibrated from 4 usable views with min_views 6";
  } catch (const InvalidArgument& e) {
    EXPECT_THAT(e.what(), HasSubstr("4 usable view(s) of 9"));
    EXPECT_THAT(e.what(), HasSubstr("corrupt.jpg: cannot be read"));
    EXPECT_THAT(e.what(), HasSubstr("blank.png: no complete"));
  }
}

TEST(IntrinsicsTest, BlurAndSizeThresholdsAreMeasuredNotGuessed) {
  const cv::Mat photo = cv::imread(
      carousel::testing::SharedDataFile("calib/images/left03.jpg").string(), cv::IMREAD_GRAYSCALE);
  const BoardSpec board = BoardSpec::Parse("chessboard:9x6:0.025");
  const BoardDetection sharp = DetectBoard(photo, board);
  ASSERT_TRUE(sharp.found) << sharp.reason;
  cv::Mat blurred;
  cv::GaussianBlur(photo, blurred, cv::Size(0, 0), 2.0);
  DetectOptions strict;
  strict.max_edge_width_px = sharp.edge_width_px + 0.5;
  const BoardDetection soft = DetectBoard(blurred, board, strict);
  EXPECT_GT(soft.edge_width_px, sharp.edge_width_px + 0.5);
  EXPECT_FALSE(soft.found);
  EXPECT_THAT(soft.reason, HasSubstr("blurred"));
  DetectOptions big;
  big.min_board_area_fraction = sharp.area_fraction + 0.01;
  const BoardDetection small = DetectBoard(photo, board, big);
  EXPECT_FALSE(small.found);
  EXPECT_THAT(small.reason, HasSubstr("too small"));
  std::printf("left03: board %.1f %% of the image, edges %.2f px; blurred (sigma 2): %.2f px\n",
              100.0 * sharp.area_fraction, sharp.edge_width_px, soft.edge_width_px);
}

TEST(IntrinsicsTest, MalformedCalibrationFilesNameTheFileAndTheNode) {
  TempDir dir;
  carousel::testing::WriteBytes(dir / "garbage.yml", "not: [yaml");
  EXPECT_THROW(ReadOpenCvIntrinsics(dir / "garbage.yml"), FormatError);
  carousel::testing::WriteBytes(dir / "nok.yml",
                                "%YAML:1.0\n---\nimage_width: 640\nimage_height: 480\n");
  EXPECT_THAT([&] { ReadOpenCvIntrinsics(dir / "nok.yml"); },
              ::testing::ThrowsMessage<FormatError>(
                  ::testing::AllOf(HasSubstr("nok.yml"), HasSubstr("camera_matrix"))));
  EXPECT_THROW(ReadOpenCvIntrinsics(dir / "missing.yml"), IoError);
}

}  // namespace
}  // namespace carousel::calib
