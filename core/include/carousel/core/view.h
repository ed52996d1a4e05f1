// View: one photo with its camera, silhouette mask and turntable angle: the unit recon and
// texture work on (they take std::vector<View>, never a calibration file; DESIGN.md).
//
// Pixels are loaded lazily on first use and cached; copies of a View share the cache, and the
// cache is safe to use from several threads. ReleasePixels() frees the memory of a view whose
// photo will not be needed again (16 x 5184x3456 photos are 860 MB decoded).
#pragma once

#include <filesystem>
#include <memory>
#include <string>

#include <opencv2/core.hpp>

#include "carousel/core/camera_model.h"

namespace carousel {

class View {
 public:
  View();
  // `image_path` may be empty for a view whose pixels are set in memory (SetImage).
  View(CameraModel camera, std::filesystem::path image_path, std::filesystem::path mask_path = {},
       double table_angle_rad = 0.0);

  const CameraModel& camera() const { return camera_; }
  CameraModel& mutable_camera() { return camera_; }
  const std::filesystem::path& image_path() const { return image_path_; }
  const std::filesystem::path& mask_path() const { return mask_path_; }
  void set_mask_path(std::filesystem::path mask_path);
  // Turntable angle at capture, radians (the object appears rotated by +angle about +Z).
  double table_angle_rad() const { return table_angle_rad_; }
  void set_table_angle_rad(double angle) { table_angle_rad_ = angle; }
  // A short name for messages: the photo's file name, or "view <n>" if it has none.
  const std::string& name() const { return name_; }
  void set_name(std::string name) { name_ = std::move(name); }

  // The photo, 8-bit BGR, loaded on first call.
  // \throw IoError/FormatError naming the file (missing, corrupt, or not camera().width x
  //        camera().height); InvalidArgument if the view has neither a path nor pixels.
  cv::Mat Image() const;
  // The photo for a picture whose longer side is `min_side`: the loaded photo if it is in
  // memory, else the file decoded at 1/2, 1/4 or 1/8 of its size (ImageReduction: a JPEG
  // decodes much faster so), neither cached nor full-size. Callers resize it to the size they
  // need. \throw as Image().
  cv::Mat ImageAtLeast(int min_side) const;
  // The silhouette, 8-bit, 255 = object, same size as the photo, loaded on first call.
  // \throw as Image(); InvalidArgument if the view has no mask.
  cv::Mat Mask() const;
  bool HasMask() const;
  bool HasImage() const;

  // Sets pixels in memory (renderer output, tests). \throw InvalidArgument if the size does
  // not match the camera, or the type is wrong (image: CV_8UC3; mask: CV_8UC1).
  void SetImage(cv::Mat image);
  void SetMask(cv::Mat mask);
  // Drops cached pixels that can be reloaded from files.
  void ReleasePixels() const;

 private:
  struct Cache;
  CameraModel camera_;
  std::filesystem::path image_path_;
  std::filesystem::path mask_path_;
  double table_angle_rad_ = 0.0;
  std::string name_;
  std::shared_ptr<Cache> cache_;  // never null
};

}  // namespace carousel
