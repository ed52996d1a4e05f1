#include "carousel/core/view.h"

#include <algorithm>
#include <cstdlib>
#include <mutex>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"

namespace carousel {

struct View::Cache {
  std::mutex mutex;
  cv::Mat image;
  cv::Mat mask;
  bool image_in_memory_only = false;
  bool mask_in_memory_only = false;
};

namespace {

// A picture decoded at 1/`reduction` of its size is rounded up (JPEG) or down (the others)
// from the camera's size over the reduction.
void RequireSize(const std::filesystem::path& path, const cv::Mat& pixels,
                 const CameraModel& camera, const char* what, int reduction = 1) {
  if (std::abs(pixels.cols * reduction - camera.width) >= reduction ||
      std::abs(pixels.rows * reduction - camera.height) >= reduction) {
    throw FormatError(path, std::string(what) + (reduction > 1 ? " is about " : " is ") +
                                std::to_string(pixels.cols * reduction) + "x" +
                                std::to_string(pixels.rows * reduction) + " but its camera is " +
                                std::to_string(camera.width) + "x" + std::to_string(camera.height));
  }
}

}  // namespace

View::View() : cache_(std::make_shared<Cache>()) {}

View::View(CameraModel camera, std::filesystem::path image_path, std::filesystem::path mask_path,
           double table_angle_rad)
    : camera_(std::move(camera)),
      image_path_(std::move(image_path)),
      mask_path_(std::move(mask_path)),
      table_angle_rad_(table_angle_rad),
      name_(image_path_.empty() ? std::string("view") : image_path_.filename().string()),
      cache_(std::make_shared<Cache>()) {}

void View::set_mask_path(std::filesystem::path mask_path) {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  mask_path_ = std::move(mask_path);
  cache_->mask.release();
  cache_->mask_in_memory_only = false;
}

cv::Mat View::Image() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  if (cache_->image.empty()) {
    CAROUSEL_THROW_IF(image_path_.empty(), InvalidArgument,
                      "view '" << name_ << "' has no photo: neither a file nor pixels");
    cv::Mat image = ReadImage(image_path_, ImageReadMode::kColor);
    RequireSize(image_path_, image, camera_, "photo");
    cache_->image = image;
  }
  return cache_->image;
}

cv::Mat View::ImageAtLeast(int min_side) const {
  const int reduction = ImageReduction(std::max(camera_.width, camera_.height), min_side);
  if (reduction == 1) return Image();
  {
    std::lock_guard<std::mutex> lock(cache_->mutex);
    if (!cache_->image.empty()) return cache_->image;
  }
  CAROUSEL_THROW_IF(image_path_.empty(), InvalidArgument,
                    "view '" << name_ << "' has no photo: neither a file nor pixels");
  cv::Mat image = ReadImage(image_path_, ImageReadMode::kColor, reduction);
  RequireSize(image_path_, image, camera_, "photo", reduction);
  return image;
}

cv::Mat View::Mask() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  if (cache_->mask.empty()) {
    CAROUSEL_THROW_IF(mask_path_.empty(), InvalidArgument,
                      "view '" << name_ << "' has no silhouette mask");
    cv::Mat mask = ReadMask(mask_path_);
    RequireSize(mask_path_, mask, camera_, "mask");
    cache_->mask = mask;
  }
  return cache_->mask;
}

bool View::HasMask() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  return !mask_path_.empty() || !cache_->mask.empty();
}

bool View::HasImage() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  return !image_path_.empty() || !cache_->image.empty();
}

void View::SetImage(cv::Mat image) {
  CAROUSEL_THROW_IF(image.type() != CV_8UC3, InvalidArgument,
                    "View::SetImage: '" << name_ << "' needs an 8-bit 3-channel image");
  CAROUSEL_THROW_IF(image.cols != camera_.width || image.rows != camera_.height, InvalidArgument,
                    "View::SetImage: '" << name_ << "' image is " << image.cols << "x" << image.rows
                                        << " but its camera is " << camera_.width << "x"
                                        << camera_.height);
  std::lock_guard<std::mutex> lock(cache_->mutex);
  cache_->image = std::move(image);
  cache_->image_in_memory_only = true;
}

void View::SetMask(cv::Mat mask) {
  CAROUSEL_THROW_IF(mask.type() != CV_8UC1, InvalidArgument,
                    "View::SetMask: '" << name_ << "' needs an 8-bit 1-channel mask");
  CAROUSEL_THROW_IF(mask.cols != camera_.width || mask.rows != camera_.height, InvalidArgument,
                    "View::SetMask: '" << name_ << "' mask is " << mask.cols << "x" << mask.rows
                                       << " but its camera is " << camera_.width << "x"
                                       << camera_.height);
  std::lock_guard<std::mutex> lock(cache_->mutex);
  cache_->mask = std::move(mask);
  cache_->mask_in_memory_only = true;
}

void View::ReleasePixels() const {
  std::lock_guard<std::mutex> lock(cache_->mutex);
  if (!cache_->image_in_memory_only) cache_->image.release();
  if (!cache_->mask_in_memory_only) cache_->mask.release();
}

}  // namespace carousel
