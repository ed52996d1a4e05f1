#include "carousel/calib/intrinsics.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calib_internal.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"

namespace carousel::calib {
namespace {

using internal::BoardView;
using internal::CalibrateViews;
using internal::Fixed;
using internal::MakeBoardView;
using internal::Median;
using internal::ViewsCalibration;

}  // namespace

const OptionTable<IntrinsicsOptions>& IntrinsicsOptions::Fields() {
  using O = IntrinsicsOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::fix_aspect_ratio, {.name = "fix-aspect", .help = "fx = fy (square pixels)"});
    t.Add(&O::fix_k3, {.name = "fix-k3", .help = "k3 = 0 (narrow lenses)"});
    t.Add(&O::zero_tangential, {.name = "zero-tangential", .help = "p1 = p2 = 0"});
    t.Add(&O::min_views,
          {.name = "min-views", .help = "usable photos needed", .min = 1, .advanced = true});
    return t;
  }();
  return table;
}

void IntrinsicsOptions::Validate() const {
  detect.Validate();
  Fields().Check(*this);
  CAROUSEL_THROW_IF(min_views < 1, InvalidArgument, "min_views must be >= 1");
  CAROUSEL_THROW_IF(!std::isfinite(outlier_factor) || !(outlier_floor_px >= 0), InvalidArgument,
                    "outlier_factor must be finite and outlier_floor_px >= 0");
}

int IntrinsicsResult::UsedViews() const {
  return static_cast<int>(
      std::count_if(views.begin(), views.end(), [](const ViewReport& v) { return v.used; }));
}

// ---- calibration ----

namespace {

struct UsableView {
  std::size_t report;  // index into result.views
  BoardView view;
};

double RunCalibration(const std::vector<UsableView>& usable, const cv::Size& size,
                      const IntrinsicsOptions& options, cv::Mat& k, cv::Mat& d,
                      std::vector<double>& per_view) {
  std::vector<BoardView> views;
  views.reserve(usable.size());
  for (const UsableView& v : usable) views.push_back(v.view);
  int flags = 0;
  if (options.fix_aspect_ratio) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  if (options.zero_tangential) flags |= cv::CALIB_ZERO_TANGENT_DIST;
  if (options.fix_k3) flags |= cv::CALIB_FIX_K3;
  const ViewsCalibration c = CalibrateViews(views, size, flags);
  k = c.k;
  d = c.d;
  per_view = c.per_view_rms;
  return c.rms;
}

}  // namespace

IntrinsicsResult CalibrateIntrinsics(const std::vector<NamedImage>& images, const BoardSpec& board,
                                     const IntrinsicsOptions& options, Progress& progress) {
  board.Validate();
  options.Validate();
  IntrinsicsResult result;
  result.views.resize(images.size());
  std::vector<UsableView> usable;
  cv::Size size;
  progress.BeginStage("find the board");
  for (std::size_t i = 0; i < images.size(); ++i) {
    ViewReport& report = result.views[i];
    report.name = images[i].name;
    const cv::Mat& image = images[i].image;
    if (image.empty()) {
      report.reason = "no image";
    } else if (image.depth() != CV_8U) {
      report.reason = "not an 8-bit image";
    } else if (!size.empty() && image.size() != size) {
      report.reason = "its size " + std::to_string(image.cols) + "x" + std::to_string(image.rows) +
                      " differs from the first image's " + std::to_string(size.width) + "x" +
                      std::to_string(size.height);
    } else {
      BoardDetection detection = DetectBoard(image, board, options.detect);
      if (detection.found) {
        if (size.empty()) size = image.size();
        report.corners = static_cast<int>(detection.corners.size());
        usable.push_back({i, MakeBoardView(board, detection)});
      } else {
        report.reason = detection.reason;
      }
    }
    progress.Report(i + 1, images.size());
  }

  const auto fail = [&](const std::string& why) {
    std::ostringstream message;
    message << why << " (" << usable.size() << " usable view(s) of " << images.size()
            << ", at least " << options.min_views << " needed)";
    for (const ViewReport& v : result.views) {
      if (!v.reason.empty()) message << "\n  " << v.name << ": " << v.reason;
    }
    throw InvalidArgument(message.str());
  };
  if (static_cast<int>(usable.size()) < options.min_views) {
    fail("cannot calibrate: too few photos show the board");
  }

  progress.BeginStage("calibrate");
  cv::Mat k;
  cv::Mat d;
  std::vector<double> per_view;
  double rms = RunCalibration(usable, size, options, k, d, per_view);
  // Reject reprojection outliers (a board that moved during the exposure, a wrong corner
  // order) and calibrate again, a few rounds at most.
  for (int round = 0; round < 3 && options.outlier_factor > 0; ++round) {
    const double limit =
        std::max(options.outlier_factor * Median(per_view), options.outlier_floor_px);
    std::vector<UsableView> kept;
    for (std::size_t i = 0; i < usable.size(); ++i) {
      if (per_view[i] <= limit) {
        kept.push_back(usable[i]);
      } else {
        result.views[usable[i].report].reason = "a reprojection outlier (" + Fixed(per_view[i], 2) +
                                                " px RMS, the others' median " +
                                                Fixed(Median(per_view), 2) + " px)";
        result.views[usable[i].report].corners = 0;
      }
    }
    if (kept.size() == usable.size()) break;
    usable = std::move(kept);
    if (static_cast<int>(usable.size()) < options.min_views) {
      fail("cannot calibrate: too few views remain after rejecting reprojection outliers");
    }
    rms = RunCalibration(usable, size, options, k, d, per_view);
  }
  progress.Report(1.0);

  for (std::size_t i = 0; i < usable.size(); ++i) {
    ViewReport& report = result.views[usable[i].report];
    report.used = true;
    report.rms_px = per_view[i];
  }
  result.rms_px = rms;
  result.camera = internal::CameraFromCv(k, d, size);
  result.camera.Validate();

  // Coverage of the image by the used corners, 3 x 3 cells.
  std::array<bool, 9> seen{};
  for (const UsableView& v : usable) {
    for (const cv::Point2f& p : v.view.image) {
      const int cx = std::clamp(static_cast<int>(3.0 * p.x / size.width), 0, 2);
      const int cy = std::clamp(static_cast<int>(3.0 * p.y / size.height), 0, 2);
      seen[static_cast<std::size_t>(cy * 3 + cx)] = true;
    }
  }
  result.cell_coverage = static_cast<double>(std::count(seen.begin(), seen.end(), true)) /
                         static_cast<double>(seen.size());
  result.corners_covered = seen[0] && seen[2] && seen[6] && seen[8];
  if (!result.corners_covered) {
    result.warnings.push_back(
        "the board was never seen in every corner of the image: the lens distortion there is "
        "extrapolated (add photos with the board near each image corner)");
  }
  if (result.UsedViews() < 10) {
    result.warnings.push_back("only " + std::to_string(result.UsedViews()) +
                              " usable views: 10 to 20 at varied tilts constrain the lens better");
  }
  return result;
}

IntrinsicsResult CalibrateIntrinsics(const std::vector<std::filesystem::path>& images,
                                     const BoardSpec& board, const IntrinsicsOptions& options,
                                     Progress& progress) {
  std::vector<NamedImage> loaded;
  std::vector<std::string> unreadable(images.size());
  loaded.reserve(images.size());
  for (std::size_t i = 0; i < images.size(); ++i) {
    NamedImage named{images[i].string(), {}};
    try {
      named.image = ReadImage(images[i], ImageReadMode::kGray);
    } catch (const IoError& e) {
      unreadable[i] = std::string("cannot be read: ") + e.reason();
    }
    loaded.push_back(std::move(named));
  }
  // Unreadable files keep their own reason rather than "no image".
  IntrinsicsResult result;
  try {
    result = CalibrateIntrinsics(loaded, board, options, progress);
  } catch (const InvalidArgument& e) {
    std::string message = e.what();
    for (std::size_t i = 0; i < images.size(); ++i) {
      if (unreadable[i].empty()) continue;
      const std::string from = loaded[i].name + ": no image";
      const std::size_t at = message.find(from);
      if (at != std::string::npos) {
        message.replace(at, from.size(), loaded[i].name + ": " + unreadable[i]);
      }
    }
    throw InvalidArgument(message);
  }
  for (std::size_t i = 0; i < images.size(); ++i) {
    if (!unreadable[i].empty()) result.views[i].reason = unreadable[i];
  }
  return result;
}

// ---- OpenCV YAML ----

namespace {

// image size, camera_matrix, distortion_coefficients and the RMS, into `fs`.
void WriteCamera(cv::FileStorage& fs, const CameraModel& c, double rms_px) {
  fs << "image_width" << c.width;
  fs << "image_height" << c.height;
  const cv::Mat k = (cv::Mat_<double>(3, 3) << c.fx, 0.0, c.cx, 0.0, c.fy, c.cy, 0.0, 0.0, 1.0);
  const cv::Mat d = (cv::Mat_<double>(5, 1) << c.distortion.k1, c.distortion.k2, c.distortion.p1,
                     c.distortion.p2, c.distortion.k3);
  fs << "camera_matrix" << k;
  fs << "distortion_coefficients" << d;
  fs << "avg_reprojection_error" << rms_px;
}

cv::FileStorage MemoryYaml() {
  return cv::FileStorage(
      ".yml", cv::FileStorage::WRITE | cv::FileStorage::MEMORY | cv::FileStorage::FORMAT_YAML);
}

}  // namespace

void WriteOpenCvIntrinsics(const std::filesystem::path& path, const IntrinsicsResult& result,
                           const BoardSpec& board) {
  cv::FileStorage fs = MemoryYaml();
  fs << "nframes" << result.UsedViews();
  fs << "board_width" << board.cols;
  fs << "board_height" << board.rows;
  fs << "square_size" << board.square_m;
  WriteCamera(fs, result.camera, result.rms_px);
  std::vector<double> per_view;
  for (const ViewReport& v : result.views) {
    if (v.used) per_view.push_back(v.rms_px);
  }
  fs << "per_view_reprojection_errors" << cv::Mat(per_view, true);
  WriteFileAtomic(path, fs.releaseAndGetString());
}

void WriteOpenCvIntrinsics(const std::filesystem::path& path, const CameraModel& camera,
                           double rms_px) {
  cv::FileStorage fs = MemoryYaml();
  WriteCamera(fs, camera, rms_px);
  WriteFileAtomic(path, fs.releaseAndGetString());
}

CameraModel ReadOpenCvIntrinsics(const std::filesystem::path& path) {
  RequireReadableFile(path);
  cv::FileStorage fs;
  try {
    if (!fs.open(path.string(), cv::FileStorage::READ)) {
      throw FormatError(path, "not an OpenCV YAML/XML file");
    }
  } catch (const cv::Exception& e) {
    throw FormatError(path, "not an OpenCV YAML/XML file (" + e.msg + ")");
  }
  cv::Mat k;
  cv::Mat d;
  CameraModel camera;
  try {
    const cv::FileNode kn = fs["camera_matrix"];
    const cv::FileNode dn = fs["distortion_coefficients"];
    if (kn.empty()) throw FormatError(path, "has no camera_matrix");
    if (dn.empty()) throw FormatError(path, "has no distortion_coefficients");
    kn >> k;
    dn >> d;
    const cv::FileNode wn = fs["image_width"];
    const cv::FileNode hn = fs["image_height"];
    if (!wn.isInt() || !hn.isInt()) throw FormatError(path, "has no image_width/image_height");
    camera.width = static_cast<int>(wn);
    camera.height = static_cast<int>(hn);
  } catch (const cv::Exception& e) {
    throw FormatError(path, "malformed calibration node (" + e.msg + ")");
  }
  if (k.rows != 3 || k.cols != 3) throw FormatError(path, "camera_matrix is not 3x3");
  k.convertTo(k, CV_64F);
  if (k.at<double>(0, 1) != 0.0) throw FormatError(path, "camera_matrix has a skew term");
  d = d.reshape(1, static_cast<int>(d.total()));
  d.convertTo(d, CV_64F);
  if (d.total() < 4) throw FormatError(path, "distortion_coefficients has fewer than 4 values");
  for (int i = 5; i < static_cast<int>(d.total()); ++i) {
    if (d.at<double>(i) != 0.0) {
      throw FormatError(path,
                        "distortion_coefficients beyond k1 k2 p1 p2 k3 (the rational or "
                        "thin-prism model) are not supported");
    }
  }
  camera = internal::CameraFromCv(k, d, cv::Size(camera.width, camera.height));
  try {
    camera.Validate();
  } catch (const InvalidArgument& e) {
    throw FormatError(path, e.what());
  }
  return camera;
}

}  // namespace carousel::calib
