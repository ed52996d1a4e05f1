// The Sessions and Photos panels' data, without a window: the session folders under the
// output folder with their state, and a session's photos with thumbnails decoded and
// checksums verified on a background thread (the UI thread only uploads what is ready).
#pragma once

#include <atomic>
#include <condition_variable>
#include <filesystem>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

namespace carousel::gui {

struct SessionSummary {
  std::filesystem::path folder;
  std::string product, created_utc, source;
  int photos = 0;
  // "complete" (model published or textured), "textured", "reconstructed", "captured",
  // "capturing" (photos being taken or the run stopped during capture), "unreadable"
  std::string state;
  std::string problem;       // why it is unreadable (names the file)
  bool has_model = false;    // model/model.glb exists
  bool resumable = false;    // run.json exists: `carousel run --resume` continues it
  bool calibration = false;  // a calibration session (its photos are of the board)
};

// The session folders directly under `out` (hidden staging folders skipped), newest first.
// A folder whose session.json is damaged is listed as "unreadable" with the reason.
std::vector<SessionSummary> ListSessions(const std::filesystem::path& out);

// One photo of a session as the Photos panel shows it.
struct PhotoThumb {
  std::string stem;  // "cam0_stop03"
  int camera = 0, stop = 0;
  int pass = 0;  // the pass (the product laid down another way) it belongs to
  double table_angle_deg = 0.0;
  bool verified = false;  // the file's SHA-256 equals the manifest's
  std::string problem;    // why not (missing, checksum differs, undecodable)
  cv::Mat rgba;           // CV_8UC4 thumbnail, at most `size` pixels on its longer side
  cv::Mat mask_rgba;      // the silhouette overlay (CV_8UC4, alpha where the mask is empty)
};

// Watches a session folder: every `period_ms` it re-reads session.json and hands out each
// photo once it is recorded (and again when its mask appears).
class PhotoWatcher {
 public:
  explicit PhotoWatcher(int thumb_size = 160, int period_ms = 400);
  ~PhotoWatcher();
  PhotoWatcher(const PhotoWatcher&) = delete;
  PhotoWatcher& operator=(const PhotoWatcher&) = delete;
  // Starts watching `session` (empty: none); forgets what was handed out before.
  void Watch(const std::filesystem::path& session);
  // The photos made ready since the last call.
  std::vector<PhotoThumb> TakeReady();
  // Photos handed out for the watched session (tests).
  int handed_out() const { return handed_out_.load(); }

 private:
  void Loop();
  void Scan(const std::filesystem::path& session);

  int thumb_size_, period_ms_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::filesystem::path session_;
  int generation_ = 0;
  bool stop_ = false;
  std::vector<PhotoThumb> ready_;
  std::set<std::string> done_photos_, done_masks_;
  std::atomic<int> handed_out_{0};
  std::thread thread_;
};

}  // namespace carousel::gui
