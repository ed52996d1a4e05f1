#include "carousel/studio/import.h"

#include <cmath>
#include <map>
#include <numbers>
#include <optional>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <Eigen/QR>
#include <Eigen/SVD>
#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/text.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

struct DatasetView {
  std::string name;  // file name relative to the images folder
  CameraModel camera;
};

double ToNumber(const std::string& token, const std::filesystem::path& path, std::size_t line) {
  std::size_t used = 0;
  double value = 0.0;
  try {
    value = std::stod(token, &used);
  } catch (const std::logic_error&) {
    used = 0;
  }
  if (used != token.size() || !std::isfinite(value)) {
    throw FormatError(path, "line " + std::to_string(line) + ": '" + token + "' is not a number");
  }
  return value;
}

// The rotation nearest to `m`; refuses matrices that are far from one.
Eigen::Matrix3d NearestRotation(const Eigen::Matrix3d& m, const std::filesystem::path& path,
                                std::size_t line) {
  const Eigen::JacobiSVD<Eigen::Matrix3d> svd(m, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix3d r = svd.matrixU() * svd.matrixV().transpose();
  if (r.determinant() < 0 || (r - m).cwiseAbs().maxCoeff() > 1e-3) {
    throw FormatError(path, "line " + std::to_string(line) + ": R is not a rotation matrix");
  }
  return r;
}

std::vector<DatasetView> ReadMiddlebury(const std::filesystem::path& par,
                                        const std::filesystem::path& images) {
  const std::vector<std::string> lines = ReadTextLines(par);
  if (lines.empty()) throw FormatError(par, "file is empty");
  const std::vector<std::string> header = SplitWords(lines[0]);
  if (header.size() != 1) throw FormatError(par, "line 1: expected the number of images");
  const double count = ToNumber(header[0], par, 1);
  if (count < 1 || count != std::floor(count)) {
    throw FormatError(par, "line 1: bad number of images '" + header[0] + "'");
  }
  std::vector<DatasetView> views;
  for (std::size_t i = 1; i < lines.size(); ++i) {
    const std::vector<std::string> t = SplitWords(lines[i]);
    if (t.empty()) continue;
    const std::size_t line = i + 1;
    if (t.size() != 22) {
      throw FormatError(par, "line " + std::to_string(line) +
                                 ": expected 22 fields (name, K, R, t), found " +
                                 std::to_string(t.size()));
    }
    double v[21];
    for (int k = 0; k < 21; ++k) v[k] = ToNumber(t[k + 1], par, line);
    // K row-major: k11 k12 k13 / k21 k22 k23 / k31 k32 k33.
    if (std::abs(v[3]) > 1e-9 || std::abs(v[6]) > 1e-9 || std::abs(v[7]) > 1e-9 ||
        std::abs(v[8] - 1.0) > 1e-9) {
      throw FormatError(
          par, "line " + std::to_string(line) + ": K is not an upper-triangular intrinsic matrix");
    }
    if (std::abs(v[1]) > 1e-6 * std::abs(v[0])) {
      throw FormatError(
          par, "line " + std::to_string(line) + ": skewed pixels (k12 != 0) are not supported");
    }
    Eigen::Matrix3d r;
    for (int k = 0; k < 9; ++k) r(k / 3, k % 3) = v[9 + k];
    DatasetView view;
    view.name = t[0];
    view.camera.fx = v[0];
    view.camera.cx = v[2];
    view.camera.fy = v[4];
    view.camera.cy = v[5];
    view.camera.cam_from_world = Rigid3d(NearestRotation(r, par, line), {v[18], v[19], v[20]});
    const cv::Mat photo = ReadImage(images / view.name);
    view.camera.width = photo.cols;
    view.camera.height = photo.rows;
    views.push_back(view);
  }
  if (views.size() != static_cast<std::size_t>(count)) {
    throw FormatError(par, "line 1 announces " + header[0] + " images, the file lists " +
                               std::to_string(views.size()));
  }
  return views;
}

std::vector<DatasetView> ReadColmap(const std::filesystem::path& model,
                                    const std::filesystem::path& images) {
  const std::filesystem::path cameras_txt = model / "cameras.txt";
  const std::filesystem::path images_txt = model / "images.txt";
  std::map<long, CameraModel> cameras;
  const std::vector<std::string> camera_lines = ReadTextLines(cameras_txt);
  for (std::size_t i = 0; i < camera_lines.size(); ++i) {
    const std::vector<std::string> t = SplitWords(camera_lines[i]);
    if (t.empty() || t[0][0] == '#') continue;
    const std::size_t line = i + 1;
    auto fail = [&](const std::string& what) -> void {
      throw FormatError(cameras_txt, "line " + std::to_string(line) + ": " + what);
    };
    if (t.size() < 4) fail("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS...");
    const std::string& kind = t[1];
    std::vector<double> p;
    for (std::size_t k = 4; k < t.size(); ++k) p.push_back(ToNumber(t[k], cameras_txt, line));
    CameraModel camera;
    const double width = ToNumber(t[2], cameras_txt, line);
    const double height = ToNumber(t[3], cameras_txt, line);
    if (!(width >= 1 && width <= 100000 && height >= 1 && height <= 100000) ||
        width != std::floor(width) || height != std::floor(height)) {
      fail("bad image size " + t[2] + "x" + t[3]);
    }
    camera.width = static_cast<int>(width);
    camera.height = static_cast<int>(height);
    auto need = [&](std::size_t n) {
      if (p.size() != n) fail(kind + " needs " + std::to_string(n) + " parameters");
    };
    if (kind == "SIMPLE_PINHOLE") {
      need(3);
      camera.fx = camera.fy = p[0];
      camera.cx = p[1];
      camera.cy = p[2];
    } else if (kind == "PINHOLE") {
      need(4);
      camera.fx = p[0], camera.fy = p[1], camera.cx = p[2], camera.cy = p[3];
    } else if (kind == "SIMPLE_RADIAL" || kind == "RADIAL") {
      need(kind == "RADIAL" ? 5 : 4);
      camera.fx = camera.fy = p[0];
      camera.cx = p[1];
      camera.cy = p[2];
      camera.distortion.k1 = p[3];
      if (kind == "RADIAL") camera.distortion.k2 = p[4];
    } else if (kind == "OPENCV" || kind == "FULL_OPENCV") {
      need(kind == "OPENCV" ? 8 : 12);
      camera.fx = p[0], camera.fy = p[1], camera.cx = p[2], camera.cy = p[3];
      camera.distortion = {p[4], p[5], p[6], p[7], kind == "OPENCV" ? 0.0 : p[8]};
      if (kind == "FULL_OPENCV" && (p[9] != 0 || p[10] != 0 || p[11] != 0)) {
        fail("FULL_OPENCV with rational terms k4..k6 is not supported");
      }
    } else {
      fail("camera model " + kind + " is not supported");
    }
    // COLMAP: centre of the top-left pixel at (0.5, 0.5); OpenCV: at (0, 0).
    camera.cx -= 0.5;
    camera.cy -= 0.5;
    cameras[static_cast<long>(ToNumber(t[0], cameras_txt, line))] = camera;
  }
  std::vector<DatasetView> views;
  const std::vector<std::string> image_lines = ReadTextLines(images_txt);
  bool expect_points = false;
  for (std::size_t i = 0; i < image_lines.size(); ++i) {
    if (!image_lines[i].empty() && image_lines[i][0] == '#') continue;
    if (expect_points) {  // the POINTS2D line that follows every image line
      expect_points = false;
      continue;
    }
    const std::vector<std::string> t = SplitWords(image_lines[i]);
    if (t.empty()) continue;
    const std::size_t line = i + 1;
    if (t.size() < 10) {
      throw FormatError(images_txt, "line " + std::to_string(line) +
                                        ": expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME");
    }
    double q[4], tr[3];
    for (int k = 0; k < 4; ++k) q[k] = ToNumber(t[1 + k], images_txt, line);
    for (int k = 0; k < 3; ++k) tr[k] = ToNumber(t[5 + k], images_txt, line);
    const long camera_id = static_cast<long>(ToNumber(t[8], images_txt, line));
    const auto camera = cameras.find(camera_id);
    if (camera == cameras.end()) {
      throw FormatError(images_txt, "line " + std::to_string(line) + ": unknown camera " + t[8]);
    }
    const Eigen::Quaterniond rotation(q[0], q[1], q[2], q[3]);
    if (std::abs(rotation.norm() - 1.0) > 1e-3) {
      throw FormatError(images_txt,
                        "line " + std::to_string(line) + ": quaternion is not unit length");
    }
    DatasetView view;
    view.name = t[9];
    view.camera = camera->second;
    view.camera.cam_from_world =
        Rigid3d(rotation.normalized().toRotationMatrix(), {tr[0], tr[1], tr[2]});
    const cv::Mat photo = ReadImage(images / view.name);
    if (photo.cols != view.camera.width || photo.rows != view.camera.height) {
      throw FormatError(images / view.name, "photo is " + std::to_string(photo.cols) + "x" +
                                                std::to_string(photo.rows) +
                                                " but its camera in cameras.txt is " +
                                                std::to_string(view.camera.width) + "x" +
                                                std::to_string(view.camera.height));
    }
    views.push_back(view);
    expect_points = true;
  }
  if (views.empty()) throw FormatError(images_txt, "no images");
  return views;
}

// The dataset's silhouette of photo `name` (masks_dir/<stem>.<ext> or <name>.png), 8-bit with
// the object at 255 (0/1 masks scaled). \throw IoError naming the mask looked for, FormatError
// for a mask of the wrong size.
cv::Mat ReadDatasetMask(const std::filesystem::path& masks_dir, const std::string& name,
                        const CameraModel& camera) {
  const std::filesystem::path photo(name);
  std::vector<std::filesystem::path> candidates;
  for (const char* ext : {".png", ".pgm", ".pbm", ".bmp", ".tif", ".tiff", ".jpg"}) {
    std::filesystem::path file = masks_dir / photo.parent_path() / photo.stem();
    file += ext;
    candidates.push_back(file);
  }
  candidates.push_back(masks_dir / (name + ".png"));
  for (const std::filesystem::path& file : candidates) {
    if (!std::filesystem::is_regular_file(file)) continue;
    cv::Mat mask = ReadMask(file);
    if (mask.cols != camera.width || mask.rows != camera.height)
      throw FormatError(file, "mask is " + std::to_string(mask.cols) + "x" +
                                  std::to_string(mask.rows) + ", its photo " + name + " is " +
                                  std::to_string(camera.width) + "x" +
                                  std::to_string(camera.height));
    double highest = 0.0;
    cv::minMaxLoc(mask, nullptr, &highest);
    if (highest <= 1.0) mask *= 255;
    return mask;
  }
  throw IoError(candidates.front(), "no mask for photo " + name + " in " + masks_dir.string());
}

void TransferPhoto(const std::filesystem::path& from, const std::filesystem::path& to,
                   ImportOptions::Transfer transfer) {
  std::error_code ec;
  std::filesystem::create_directories(to.parent_path(), ec);
  switch (transfer) {
    case ImportOptions::Transfer::kSymlink:
      std::filesystem::create_symlink(std::filesystem::absolute(from), to, ec);
      if (ec) throw IoError(to, "cannot link to " + from.string() + ": " + ec.message());
      return;
    case ImportOptions::Transfer::kHardLink:
      std::filesystem::create_hard_link(from, to, ec);
      if (!ec) return;
      [[fallthrough]];  // e.g. another file system: copy instead
    case ImportOptions::Transfer::kCopy:
      WriteFileAtomic(to, ReadFileBytes(from), {.overwrite = false});
      return;
  }
}

}  // namespace

void ImportOptions::Validate() const {
  CAROUSEL_THROW_IF(source.empty(), InvalidArgument, "ImportOptions.source is empty");
  CAROUSEL_THROW_IF(format == Format::kColmap && images_dir.empty(), InvalidArgument,
                    "a COLMAP import needs the photos' folder (--images)");
}

std::optional<UprightFrameResult> UprightFrame(const std::vector<CameraModel>& cameras) {
  if (cameras.size() < 3) return std::nullopt;
  std::vector<Eigen::Vector3d> centres, axes, ups;
  for (const CameraModel& camera : cameras) {
    const Eigen::Matrix3d& r = camera.cam_from_world.rotation;
    centres.push_back(-(r.transpose() * camera.cam_from_world.translation));
    axes.push_back(r.row(2).transpose());  // the optical axis (camera +z) in the world
    ups.push_back(-r.row(1).transpose());  // the photo's up (camera -y) in the world
  }
  const double n = static_cast<double>(cameras.size());
  // The point nearest every optical axis: sum (I - d d^T) (x - c) = 0.
  Eigen::Matrix3d normal_matrix = Eigen::Matrix3d::Zero();
  Eigen::Vector3d rhs = Eigen::Vector3d::Zero();
  for (std::size_t i = 0; i < centres.size(); ++i) {
    const Eigen::Matrix3d p = Eigen::Matrix3d::Identity() - axes[i] * axes[i].transpose();
    normal_matrix += p;
    rhs += p * centres[i];
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> axes_spread(normal_matrix);
  if (axes_spread.eigenvalues()(0) < 1e-3 * n) return std::nullopt;  // all axes parallel
  const Eigen::Vector3d target = normal_matrix.ldlt().solve(rhs);

  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& c : centres) mean += c / n;
  Eigen::Matrix3d scatter = Eigen::Matrix3d::Zero();
  for (const Eigen::Vector3d& c : centres) scatter += (c - mean) * (c - mean).transpose() / n;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> spread(scatter);
  const Eigen::Vector3d& lambda = spread.eigenvalues();                       // ascending
  if (lambda(2) <= 0.0 || lambda(1) < 1e-6 * lambda(2)) return std::nullopt;  // one point, a line
  Eigen::Vector3d up;
  Eigen::Vector3d mean_up = Eigen::Vector3d::Zero();
  for (const Eigen::Vector3d& u : ups) mean_up += u / n;
  UprightFrameResult result;
  Eigen::Vector3d origin = target;
  if (lambda(0) < 0.5 * lambda(1)) {
    // A ring, rings about one axis, or a dome: the least spread direction is the axis.
    up = spread.eigenvectors().col(0).normalized();
    result.basis = "the axis of the camera ring";
    // The ring's centre: a circle fitted to the centres in the ring's plane (algebraic,
    // x^2 + y^2 + a x + b y + c = 0, least squares), then the axis through it.
    const Eigen::Vector3d e1 = spread.eigenvectors().col(2).normalized();
    const Eigen::Vector3d e2 = up.cross(e1).normalized();
    Eigen::MatrixXd a(centres.size(), 3);
    Eigen::VectorXd b(centres.size());
    for (std::size_t i = 0; i < centres.size(); ++i) {
      const double x = (centres[i] - mean).dot(e1), y = (centres[i] - mean).dot(e2);
      a.row(static_cast<Eigen::Index>(i)) << x, y, 1.0;
      b(static_cast<Eigen::Index>(i)) = -(x * x + y * y);
    }
    const Eigen::Vector3d circle = a.colPivHouseholderQr().solve(b);
    const double cx = -0.5 * circle(0), cy = -0.5 * circle(1);
    const double radius_sq = cx * cx + cy * cy - circle(2);
    if (radius_sq > 0.0 && std::isfinite(radius_sq)) {
      result.ring_radius = std::sqrt(radius_sq);
      double sum_sq = 0.0;
      for (const Eigen::Vector3d& c : centres) {
        const double x = (c - mean).dot(e1) - cx, y = (c - mean).dot(e2) - cy;
        const double off = std::hypot(x, y) - result.ring_radius;
        sum_sq += off * off;
      }
      result.ring_rms = std::sqrt(sum_sq / n);
      // A ring the centres really follow (not a dome's scatter): its axis holds the origin.
      if (result.ring_rms < 0.1 * result.ring_radius) {
        const Eigen::Vector3d centre = mean + cx * e1 + cy * e2;
        origin = centre + up * up.dot(target - centre);
        result.basis += " through the ring's centre";
      }
    }
  } else if (mean_up.norm() > 0.5) {
    up = mean_up.normalized();
    result.basis = "the photos' mean up direction";
  } else {
    return std::nullopt;
  }
  double look = 0.0, photo_up = 0.0;
  for (std::size_t i = 0; i < axes.size(); ++i) {
    look += axes[i].dot(up) / n;
    photo_up += ups[i].dot(up) / n;
  }
  const double level = std::sin(2.0 * std::numbers::pi / 180.0);
  if (look > level || (std::abs(look) <= level && photo_up < 0.0)) up = -up;
  result.basis += std::abs(look) > level ? ", the cameras looking down on the object"
                                         : ", pointing where the photos' up does";
  const Eigen::Matrix3d rotation =
      Eigen::Quaterniond::FromTwoVectors(up, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  result.world_from_dataset = Rigid3d(rotation, -(rotation * origin));
  return result;
}

ImportResult ImportDataset(const ImportOptions& options,
                           const std::filesystem::path& session_folder, Progress& progress) {
  options.Validate();
  progress.BeginStage("read dataset");
  std::filesystem::path images = options.images_dir;
  std::vector<DatasetView> views;
  std::string kind;
  if (options.format == ImportOptions::Format::kMiddlebury) {
    if (images.empty()) images = options.source.parent_path();
    views = ReadMiddlebury(options.source, images);
    kind = "middlebury";
  } else {
    views = ReadColmap(options.source, images);
    kind = "colmap";
  }
  for (const DatasetView& view : views) {
    try {
      view.camera.Validate();
    } catch (const InvalidArgument& e) {
      throw FormatError(options.source, view.name + ": " + e.what());
    }
  }
  std::string frame = "kept";
  std::optional<Rigid3d> world_from_dataset;
  if (!options.keep_frame) {
    std::vector<CameraModel> cameras;
    cameras.reserve(views.size());
    for (const DatasetView& view : views) cameras.push_back(view.camera);
    if (const auto upright = UprightFrame(cameras)) {
      world_from_dataset = upright->world_from_dataset;
      frame = "upright: +Z from " + upright->basis;
      const Rigid3d dataset_from_world = world_from_dataset->Inverse();
      for (DatasetView& view : views)
        view.camera.cam_from_world = view.camera.cam_from_world * dataset_from_world;
    } else {
      frame = "kept (the cameras fix no up axis)";
      CAROUSEL_LOG_WARN(options.source.string()
                        << ": the cameras fix no up axis; the dataset's own frame is kept");
    }
  }
  progress.EndStage();

  // --force must never replace the folder the dataset itself lives in.
  const auto inside = [](const std::filesystem::path& child, const std::filesystem::path& parent) {
    const std::string c = std::filesystem::weakly_canonical(child).string() + "/";
    const std::string p = std::filesystem::weakly_canonical(parent).string() + "/";
    return c.rfind(p, 0) == 0;
  };
  if (inside(options.source, session_folder) || inside(images, session_folder)) {
    throw IoError(session_folder, "holds the dataset being imported; choose another folder");
  }
  StagedSessionFolder folder(session_folder, options.overwrite);
  folder.CreateFolder("images");
  Session session;
  std::filesystem::path dataset_folder =
      std::filesystem::absolute(options.source).lexically_normal();
  if (!std::filesystem::is_directory(dataset_folder)) dataset_folder = dataset_folder.parent_path();
  session.product = options.product.empty() ? dataset_folder.filename().string() : options.product;
  session.created_utc = NowUtc();
  session.source = "import:" + kind;
  session.frame = "dataset";
  session.world_from_dataset = world_from_dataset;
  progress.BeginStage("copy photos");
  for (std::size_t i = 0; i < views.size(); ++i) {
    progress.CheckCancelled();
    SessionView view;
    view.image = (std::filesystem::path("images") / views[i].name).lexically_normal().string();
    if (view.image.rfind("images/", 0) != 0) {
      throw FormatError(options.source, "image name '" + views[i].name + "' leaves the folder");
    }
    view.camera = 0;
    view.stop = static_cast<int>(i);
    view.camera_model = views[i].camera;
    TransferPhoto(images / views[i].name, folder.staging() / view.image, options.transfer);
    if (!options.masks_dir.empty()) {
      const std::filesystem::path stem = std::filesystem::path(views[i].name).stem();
      view.given_mask = "masks/given/" + stem.string() + ".png";
      folder.CreateFolder("masks/given");
      WriteImage(folder.staging() / view.given_mask,
                 ReadDatasetMask(options.masks_dir, views[i].name, view.camera_model),
                 {.overwrite = false});
      view.given_mask_sha256 = FileSha256(folder.staging() / view.given_mask);
    }
    session.views.push_back(view);
    progress.Report(i + 1, views.size());
  }
  progress.EndStage();
  session.stages["capture"] = "done";
  WriteSessionManifest(folder.staging(), session);
  folder.Commit();
  return {folder.target(), static_cast<int>(views.size()), frame};
}

}  // namespace carousel::studio
