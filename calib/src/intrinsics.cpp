#include "carousel/calib/intrinsics.h"

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <initializer_list>
#include <sstream>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calib_internal.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/json.h"

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
    t.Add(&O::hold_weak_terms,
          {.name = "hold-weak-terms",
           .help = "with fewer than 10 views hold k3 = 0 (and k2 = 0 when the corners stay "
                   "near the image centre)"});
    t.Add(&O::weak_fraction, {.name = "weak-fraction",
                              .help = "warn when the standard deviation of fx, fy (of cx, cy) "
                                      "exceeds this fraction of it (of the image side)",
                              .min = 0.0,
                              .min_exclusive = true,
                              .advanced = true});
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

// The farthest corner's distance from the image centre, over half the image diagonal.
double CornerReach(const std::vector<UsableView>& usable, const cv::Size& size) {
  const cv::Point2d centre(0.5 * (size.width - 1), 0.5 * (size.height - 1));
  const double half_diagonal = 0.5 * std::hypot(size.width, size.height);
  double reach = 0.0;
  for (const UsableView& v : usable) {
    for (const cv::Point2f& p : v.view.image) {
      reach = std::max(reach, cv::norm(cv::Point2d(p) - centre) / half_diagonal);
    }
  }
  return reach;
}

// OpenCV's calibration with the lens terms the options and the views allow; `held` names the
// terms held at zero.
ViewsCalibration RunCalibration(const std::vector<UsableView>& usable, const cv::Size& size,
                                const IntrinsicsOptions& options, std::vector<std::string>* held) {
  std::vector<BoardView> views;
  views.reserve(usable.size());
  for (const UsableView& v : usable) views.push_back(v.view);
  held->clear();
  int flags = 0;
  if (options.fix_aspect_ratio) flags |= cv::CALIB_FIX_ASPECT_RATIO;
  const bool few =
      options.hold_weak_terms && static_cast<int>(usable.size()) < IntrinsicsOptions::kFewViews;
  if (few && CornerReach(usable, size) < IntrinsicsOptions::kNearCentreReach) {
    flags |= cv::CALIB_FIX_K2;
    held->emplace_back("k2");
  }
  if (options.fix_k3 || few) {
    flags |= cv::CALIB_FIX_K3;
    held->emplace_back("k3");
  }
  if (options.zero_tangential) {
    flags |= cv::CALIB_ZERO_TANGENT_DIST;
    held->emplace_back("p1 p2");
  }
  return CalibrateViews(views, size, flags);
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
  ViewsCalibration c = RunCalibration(usable, size, options, &result.held);
  // Reject reprojection outliers (a board that moved during the exposure, a wrong corner
  // order) and calibrate again, a few rounds at most.
  for (int round = 0; round < 3 && options.outlier_factor > 0; ++round) {
    const std::vector<double>& per_view = c.per_view_rms;
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
    c = RunCalibration(usable, size, options, &result.held);
  }
  progress.Report(1.0);

  for (std::size_t i = 0; i < usable.size(); ++i) {
    ViewReport& report = result.views[usable[i].report];
    report.used = true;
    report.rms_px = c.per_view_rms[i];
  }
  result.rms_px = c.rms;
  result.camera = internal::CameraFromCv(c.k, c.d, size);
  result.camera.Validate();
  result.corner_reach = CornerReach(usable, size);
  result.std_fx = c.std_px[0];
  result.std_fy = c.std_px[1];
  result.std_cx = c.std_px[2];
  result.std_cy = c.std_px[3];
  const double w = options.weak_fraction;
  result.weak = result.std_fx > w * result.camera.fx || result.std_fy > w * result.camera.fy ||
                result.std_cx > w * size.width || result.std_cy > w * size.height;

  // Coverage of the image by the used corners, 3 x 3 cells.
  std::array<bool, 9> seen{};
  for (const UsableView& v : usable) {
    for (const cv::Point2f& p : v.view.image) {
      const int cx = std::clamp(static_cast<int>(3.0 * p.x / size.width), 0, 2);
      const int cy = std::clamp(static_cast<int>(3.0 * p.y / size.height), 0, 2);
      seen[3 * static_cast<std::size_t>(cy) + static_cast<std::size_t>(cx)] = true;
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
  if (result.UsedViews() < IntrinsicsOptions::kFewViews) {
    result.warnings.push_back("only " + std::to_string(result.UsedViews()) +
                              " usable views: 10 to 20 at varied tilts constrain the lens better");
  }
  if (result.weak) {
    const auto percent = [](double part, double whole) { return Fixed(100.0 * part / whole, 1); };
    result.warnings.push_back(
        "a weak calibration: one standard deviation of fx " + Fixed(result.std_fx, 2) + " px (" +
        percent(result.std_fx, result.camera.fx) + " %), fy " + Fixed(result.std_fy, 2) + " px (" +
        percent(result.std_fy, result.camera.fy) + " %), cx " + Fixed(result.std_cx, 2) + " px (" +
        percent(result.std_cx, size.width) + " % of the width), cy " + Fixed(result.std_cy, 2) +
        " px (" + percent(result.std_cy, size.height) +
        " % of the height); add photos with the board tilted and filling the image");
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

// ---- files ----

namespace {

bool HasExtension(const std::filesystem::path& path, std::initializer_list<const char*> any) {
  std::string ext = path.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char ch) { return static_cast<char>(std::tolower(ch)); });
  return std::any_of(any.begin(), any.end(), [&](const char* e) { return ext == e; });
}

}  // namespace

void CheckIntrinsicsPath(const std::filesystem::path& path) {
  CAROUSEL_THROW_IF(!HasExtension(path, {".json", ".yml", ".yaml", ".xml"}), InvalidArgument,
                    "cannot tell the format of " << path.string()
                                                 << ": name it .json (the camera as session.json "
                                                    "has it) or .yml, .yaml, .xml (OpenCV's)");
}

void WriteIntrinsics(const std::filesystem::path& path, const IntrinsicsResult& result,
                     const BoardSpec& board) {
  CheckIntrinsicsPath(path);
  if (!HasExtension(path, {".json"})) {
    WriteOpenCvIntrinsics(path, result, board);
    return;
  }
  nlohmann::json views = nlohmann::json::array();
  for (const ViewReport& v : result.views) {
    nlohmann::json view = {{"name", v.name}, {"used", v.used}};
    if (v.used) {
      view["corners"] = v.corners;
      view["rms_px"] = v.rms_px;
    } else {
      view["reason"] = v.reason;
    }
    views.push_back(view);
  }
  const nlohmann::json out = {{"camera", CameraModelToJson(result.camera, "")},
                              {"rms_px", result.rms_px},
                              {"std_px",
                               {{"fx", result.std_fx},
                                {"fy", result.std_fy},
                                {"cx", result.std_cx},
                                {"cy", result.std_cy}}},
                              {"held", result.held},
                              {"weak", result.weak},
                              {"cell_coverage", result.cell_coverage},
                              {"corner_reach", result.corner_reach},
                              {"board", board.ToString()},
                              {"views", views},
                              {"warnings", result.warnings}};
  WriteFileAtomic(path, out.dump(2) + "\n");
}

CameraModel ReadIntrinsics(const std::filesystem::path& path) {
  if (!HasExtension(path, {".json"})) return ReadOpenCvIntrinsics(path);
  const nlohmann::json file = ParseJsonFile(path);
  const JsonReader read(file, path);
  return CameraModelFromJson(read.Object("camera"), "");
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

// YAML, or XML for a .xml path.
cv::FileStorage MemoryStorage(const std::filesystem::path& path) {
  const bool xml = HasExtension(path, {".xml"});
  return cv::FileStorage(xml ? ".xml" : ".yml",
                         cv::FileStorage::WRITE | cv::FileStorage::MEMORY |
                             (xml ? cv::FileStorage::FORMAT_XML : cv::FileStorage::FORMAT_YAML));
}

}  // namespace

void WriteOpenCvIntrinsics(const std::filesystem::path& path, const IntrinsicsResult& result,
                           const BoardSpec& board) {
  cv::FileStorage fs = MemoryStorage(path);
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
  // Beyond OpenCV's sample: one standard deviation of fx fy cx cy, and the terms held at 0.
  fs << "intrinsics_std_px"
     << (cv::Mat_<double>(4, 1) << result.std_fx, result.std_fy, result.std_cx, result.std_cy);
  std::string held;
  for (const std::string& term : result.held) held += (held.empty() ? "" : " ") + term;
  fs << "held_terms" << held;
  WriteFileAtomic(path, fs.releaseAndGetString());
}

void WriteOpenCvIntrinsics(const std::filesystem::path& path, const CameraModel& camera,
                           double rms_px) {
  cv::FileStorage fs = MemoryStorage(path);
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
