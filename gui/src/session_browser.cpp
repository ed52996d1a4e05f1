#include "carousel/gui/session_browser.h"

#include <algorithm>
#include <fstream>
#include <iterator>
#include <map>
#include <sstream>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/session.h"

namespace carousel::gui {
namespace {

bool IsFile(const std::filesystem::path& path) {
  std::error_code ec;
  return std::filesystem::is_regular_file(path, ec);
}

std::string StateOf(const studio::Session& session) {
  const auto done = [&session](const char* stage) {
    const auto it = session.stages.find(stage);
    return it != session.stages.end() && it->second == "done";
  };
  if (done("publish")) return "complete";
  if (done("texture")) return "textured";
  if (done("reconstruct")) return "reconstructed";
  if (done("capture")) return "captured";
  return "capturing";
}

std::string ReadBytes(const std::filesystem::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return {};
  return {std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
}

// Decoded at a JPEG scale that keeps at least `size` pixels (libjpeg's scaled decode,
// ImageReduction), then resized down.
cv::Mat Thumbnail(const std::string& bytes, int size, int flags_full, int flags_2, int flags_4,
                  int flags_8, int full_long_side) {
  const cv::Mat raw(1, static_cast<int>(bytes.size()), CV_8UC1,
                    const_cast<char*>(bytes.data()));  // imdecode only reads it
  const int reduction = ImageReduction(full_long_side, size);
  const int flags = reduction == 8   ? flags_8
                    : reduction == 4 ? flags_4
                    : reduction == 2 ? flags_2
                                     : flags_full;
  cv::Mat image = cv::imdecode(raw, flags);
  if (image.empty()) return image;
  const double scale = static_cast<double>(size) / std::max(image.cols, image.rows);
  if (scale < 1.0) cv::resize(image, image, cv::Size(), scale, scale, cv::INTER_AREA);
  return image;
}

}  // namespace

std::vector<SessionSummary> ListSessions(const std::filesystem::path& out) {
  std::vector<std::pair<std::filesystem::file_time_type, SessionSummary>> found;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(out, ec)) {
    const std::filesystem::path& folder = entry.path();
    const std::string name = folder.filename().string();
    if (name.empty() || name[0] == '.' || !entry.is_directory(ec)) continue;
    if (!IsFile(folder / studio::kManifestName) && !IsFile(folder / "run.json")) continue;
    SessionSummary s;
    s.folder = folder;
    s.resumable = IsFile(folder / "run.json");
    s.has_model = IsFile(folder / "model" / "model.glb");
    try {
      const studio::Session session = studio::ReadSession(folder);
      s.product = session.product;
      s.created_utc = session.created_utc;
      s.source = session.source;
      s.photos = static_cast<int>(session.views.size());
      s.state = StateOf(session);
      s.calibration = session.stages.count("calibrate") != 0 ||
                      std::filesystem::is_directory(folder / "calibration", ec);
      if (s.calibration && s.state == "captured")
        s.state = session.stages.count("calibrate") != 0 ? "calibrated" : "captured";
    } catch (const IoError& e) {
      if (IsFile(folder / studio::kManifestName)) {
        s.state = "unreadable";
        s.problem = e.what();
      } else {
        s.state = "capturing";  // run.json written, no photo recorded yet
        s.product = name;
      }
    }
    const auto time = std::filesystem::last_write_time(folder, ec);
    found.emplace_back(ec ? std::filesystem::file_time_type() : time, std::move(s));
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) {
    return a.first != b.first ? a.first > b.first : a.second.folder < b.second.folder;
  });
  std::vector<SessionSummary> out_list;
  out_list.reserve(found.size());
  for (auto& [time, s] : found) out_list.push_back(std::move(s));
  return out_list;
}

PhotoWatcher::PhotoWatcher(int thumb_size, int period_ms)
    : thumb_size_(thumb_size), period_ms_(period_ms), thread_([this] { Loop(); }) {}

PhotoWatcher::~PhotoWatcher() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void PhotoWatcher::Watch(const std::filesystem::path& session) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (session == session_) return;
    session_ = session;
    ++generation_;
    ready_.clear();
    done_photos_.clear();
    done_masks_.clear();
    handed_out_ = 0;
  }
  wake_.notify_all();
}

std::vector<PhotoThumb> PhotoWatcher::TakeReady() {
  std::lock_guard<std::mutex> lock(mutex_);
  std::vector<PhotoThumb> out;
  out.swap(ready_);
  return out;
}

void PhotoWatcher::Loop() {
  std::unique_lock<std::mutex> lock(mutex_);
  while (!stop_) {
    const std::filesystem::path session = session_;
    if (!session.empty()) {
      lock.unlock();
      try {
        Scan(session);
      } catch (const std::exception& e) {  // a file that vanished mid-read: the next scan
        CAROUSEL_LOG_WARN("photos of " << session.string() << ": " << e.what());
      }
      lock.lock();
    }
    wake_.wait_for(lock, std::chrono::milliseconds(period_ms_));
  }
}

void PhotoWatcher::Scan(const std::filesystem::path& folder) {
  int generation = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    generation = generation_;
  }
  studio::Session session;
  try {
    session = studio::ReadSession(folder);
  } catch (const Error&) {
    return;  // not written yet, or being replaced: the next scan reads it
  }
  for (const studio::SessionView& view : session.views) {
    const std::string stem = studio::ViewStem(view.camera, view.stop, view.pass);
    const bool has_mask = !view.mask.empty() && IsFile(folder / view.mask);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (generation != generation_ || stop_) return;
      if (done_photos_.count(stem) != 0 && (!has_mask || done_masks_.count(stem) != 0)) continue;
    }
    PhotoThumb thumb;
    thumb.stem = stem;
    thumb.camera = view.camera;
    thumb.stop = view.stop;
    thumb.pass = view.pass;
    thumb.table_angle_deg = view.table_angle_deg;
    const std::filesystem::path image = folder / view.image;
    const std::string bytes = ReadBytes(image);
    if (bytes.empty()) {
      thumb.problem = image.string() + ": missing or empty";
    } else {
      const std::string sha = studio::Sha256(bytes);
      thumb.verified = !view.sha256.empty() && sha == view.sha256;
      if (!thumb.verified)
        thumb.problem = view.sha256.empty() ? "no checksum recorded" : "checksum differs";
      const int long_side = std::max(view.camera_model.width, view.camera_model.height);
      cv::Mat bgr = Thumbnail(bytes, thumb_size_, cv::IMREAD_COLOR, cv::IMREAD_REDUCED_COLOR_2,
                              cv::IMREAD_REDUCED_COLOR_4, cv::IMREAD_REDUCED_COLOR_8, long_side);
      if (bgr.empty()) {
        thumb.problem = image.string() + ": cannot be decoded";
      } else {
        cv::cvtColor(bgr, thumb.rgba, cv::COLOR_BGR2RGBA);
      }
      if (has_mask && !thumb.rgba.empty()) {
        const cv::Mat mask =
            Thumbnail(ReadBytes(folder / view.mask), thumb_size_, cv::IMREAD_GRAYSCALE,
                      cv::IMREAD_REDUCED_GRAYSCALE_2, cv::IMREAD_REDUCED_GRAYSCALE_4,
                      cv::IMREAD_REDUCED_GRAYSCALE_8, long_side);
        if (!mask.empty()) {
          cv::Mat fitted;
          cv::resize(mask, fitted, thumb.rgba.size(), 0, 0, cv::INTER_NEAREST);
          // Background tinted: a translucent magenta where the silhouette is empty.
          thumb.mask_rgba = cv::Mat(fitted.size(), CV_8UC4, cv::Scalar(255, 0, 255, 0));
          thumb.mask_rgba.setTo(cv::Scalar(255, 0, 255, 120), fitted < 128);
        }
      }
    }
    std::lock_guard<std::mutex> lock(mutex_);
    if (generation != generation_ || stop_) return;
    done_photos_.insert(stem);
    if (!thumb.mask_rgba.empty()) done_masks_.insert(stem);
    ready_.push_back(std::move(thumb));
    ++handed_out_;
  }
}

}  // namespace carousel::gui
