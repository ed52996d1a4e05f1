// Private to the libgphoto2 backend (carousel_rig): what its sources share.
//
//   gphoto_ports.cpp     libgphoto2's process-wide tables (camera and port drivers), keeping
//                        the drivers loaded, the fd-0 guard, detection
//   gphoto_camera.cpp    the worker thread, the session (open, find again by serial, reopen)
//                        and the public GPhotoCamera calls
//   gphoto_config.cpp    configuration widgets: settings, their labels, summary
//   gphoto_transfer.cpp  capture, camera events, download, live view
#pragma once

#include <gphoto2/gphoto2.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <filesystem>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "carousel/core/error.h"
#include "carousel/rig/gphoto_camera.h"

namespace carousel::rig {
namespace gphoto_internal {

// libgphoto2's process-wide tables (camera drivers, port drivers) load once; loading and
// gp_camera_init go through ltdl, which is not thread-safe, so both are serialised.
std::mutex& LibraryMutex();
// The camera drivers' abilities and the port list, loaded on first use.
// \throw DeviceError when libgphoto2 cannot load them.
CameraAbilitiesList* Abilities();
GPPortInfoList* Ports();

// libgphoto2 2.5.30 closes file descriptor 0 when a PTP/IP camera exits; this keeps fd 0
// occupied by /dev/null so that it never closes another file or socket (gphoto_ports.cpp).
void KeepFdZeroOccupied();
// Keeps every libgphoto2 camera and port driver now mapped loaded for the life of the process.
void PinLoadedDrivers();
// Loads every libgphoto2 port driver for good ($IOLIBS, else libgphoto2_port's folder).
void LoadPortDriversForGood();
// gp_camera_exit + unref, then the fd-0 guard (the caller holds LibraryMutex()).
void ExitCamera(::Camera* camera, GPContext* context);

// "I/O problem (-7)": libgphoto2's text for a result code, with the code.
std::string Describe(int result);

// The libgphoto2 widget names a rig setting goes by, by camera family (empty: not a rig
// setting).
const std::vector<std::string>& WidgetNames(const std::string& setting);

// Owns a CameraWidget tree.
struct WidgetTree {
  CameraWidget* root = nullptr;
  WidgetTree() = default;
  WidgetTree(const WidgetTree&) = delete;
  WidgetTree& operator=(const WidgetTree&) = delete;
  ~WidgetTree() {
    if (root) gp_widget_free(root);
  }
};

}  // namespace gphoto_internal

// ---- the worker and the libgphoto2 session --------------------------------------------------

class GPhotoCamera::Impl : public std::enable_shared_from_this<GPhotoCamera::Impl> {
 public:
  using Clock = std::chrono::steady_clock;
  using milliseconds = std::chrono::milliseconds;

  explicit Impl(GPhotoCameraOptions options);
  ~Impl();

  // A job's lifecycle, shared by the caller and the worker.
  struct JobState {
    std::mutex mutex;
    bool started = false;
    bool abandoned = false;  // the caller gave up waiting
    bool committed = false;  // the job has made its result visible (a photo under its name)
  };

  // Runs `job` on the worker; waits until `deadline`. A job that has not started by then is
  // abandoned (it never runs); one that is running finishes in the background and leaves the
  // session marked for a reconnect.
  template <typename R>
  R Run(std::function<R(Clock::time_point)> job, milliseconds timeout, const std::string& what) {
    const Clock::time_point deadline = Clock::now() + timeout;
    auto state = std::make_shared<JobState>();
    auto task = std::make_shared<std::packaged_task<R()>>([this, job, deadline, state] {
      {
        std::lock_guard<std::mutex> lock(state->mutex);
        if (state->abandoned) throw DeviceError(device_, "abandoned");
        state->started = true;
      }
      running_job_ = state;
      struct Clear {
        Impl* impl;
        ~Clear() { impl->running_job_.reset(); }
      } clear{this};
      return job(deadline);
    });
    std::future<R> result = task->get_future();
    {
      std::lock_guard<std::mutex> lock(queue_mutex_);
      queue_.push_back([task] { (*task)(); });
    }
    queue_cv_.notify_one();
    if (result.wait_until(deadline + milliseconds(250)) != std::future_status::ready) {
      bool running = false;
      bool committed = false;
      {
        std::lock_guard<std::mutex> lock(state->mutex);
        state->abandoned = true;
        running = state->started;
        committed = state->committed;
      }
      // The result is already visible (a photo linked under its name): what is left is a
      // folder sync, so report the outcome rather than a failure that did not happen.
      if (committed) return result.get();
      if (running) needs_reconnect_ = true;
      throw DeviceError(device_, what + " did not finish within " +
                                     std::to_string(timeout.count()) + " ms" +
                                     (running ? " (the camera is not answering)" : ""));
    }
    return result.get();
  }

  // ---- on the worker thread ----

  // The session (gphoto_camera.cpp).
  // Marks the running job's result as visible; false when its caller has given up.
  bool CommitRunningJob();
  void Open(Clock::time_point deadline);
  // Finds the USB camera to open: the one on the given port, the only one there is, or (on
  // a reconnect) the one with our serial number, wherever it re-appeared.
  void ResolveUsb(std::string* model, std::string* port, Clock::time_point deadline);
  // The serial number of a detected camera (opens it briefly).
  std::string ProbeSerial(const DetectedCamera& c);
  void ReadIdentity();
  // The caller holds LibraryMutex() or calls it with lock = true.
  void Close(bool lock = true);
  // Reopens the session with bounded attempts until `deadline`.
  void Reopen(Clock::time_point deadline);
  void EnsureOpen(Clock::time_point deadline);
  std::string Where() const;

  // Capture and download (gphoto_transfer.cpp).
  // Discards events left from earlier captures (a late CaptureComplete, a stale ObjectAdded).
  void DrainEvents();
  CapturedPhoto DoCapture(Clock::time_point deadline);
  // Waits for ObjectAdded after a release (ours or the controller's); the loop is ours because
  // wait_for_event does not block over PTP/IP (rig-notes 1.6.4).
  CapturedPhoto WaitForNewPhoto(Clock::time_point triggered, Clock::time_point deadline);
  void DoDownload(const CapturedPhoto& photo, const std::filesystem::path& destination,
                  bool delete_from_camera, Clock::time_point deadline);
  cv::Mat DoPreview(Clock::time_point deadline);

  // The configuration (gphoto_config.cpp).
  void GetConfig(gphoto_internal::WidgetTree* tree);
  std::map<std::string, std::string> DoSettings(Clock::time_point deadline);
  // Sets a rig setting (or a libgphoto2 widget by its name when `raw`).
  void DoSet(const std::string& name, const std::string& value, bool raw,
             Clock::time_point deadline);
  std::map<std::string, std::string> DoConfiguration(
      Clock::time_point deadline, std::map<std::string, std::vector<std::string>>* choices);
  std::string DoSummary(Clock::time_point deadline);

  GPhotoCameraOptions options_;
  std::string device_;
  GPContext* context_ = nullptr;
  ::Camera* camera_ = nullptr;
  std::string current_port_;
  std::string current_model_;
  std::string serial_;
  CameraInfo info_;
  std::atomic<bool> needs_reconnect_{false};
  std::shared_ptr<JobState> running_job_;  // the worker's: the job it is running
  Clock::time_point external_armed_at_{};  // the worker's: when PrepareExternalRelease ran
  // The worker writes them; Counters() reads them without waiting for the worker.
  mutable std::mutex counters_mutex_;
  GPhotoCounters counters_;
  void Count(int GPhotoCounters::*counter) {
    std::lock_guard<std::mutex> lock(counters_mutex_);
    ++(counters_.*counter);
  }

 private:
  void Work();

  std::mutex queue_mutex_;
  std::condition_variable queue_cv_;
  std::deque<std::function<void()>> queue_;
  bool stopping_ = false;
  std::thread worker_;
};

}  // namespace carousel::rig
