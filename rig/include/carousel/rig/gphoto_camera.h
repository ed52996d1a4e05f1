// The libgphoto2 camera backend: real DSLRs over USB, and network cameras over PTP/IP
// ("ptpip:HOST:PORT:PORT"), through Debian's libgphoto2.
//
// One long-lived libgphoto2 session and one worker thread per camera: every libgphoto2 call
// runs on the worker, and each public call waits for it with its own deadline, so a camera that
// hangs inside libgphoto2 gives a DeviceError in time instead of a hang (the worker finishes
// the stuck call in the background; the next call reconnects).
//
// Works around libgphoto2 2.5.30 (../shared/reference/rig-notes.md section 1.6): capture is
// gp_camera_trigger_capture plus our own event loop against a deadline (the generic
// gp_camera_capture has no timeout and hangs on Device Busy; wait_for_event does not block over
// PTP/IP); "busy" is retried with exponential backoff a bounded number of times; a camera that
// drops off and comes back (another USB address, a new TCP connection) is reopened, found
// again by its serial number.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "carousel/rig/camera.h"

namespace carousel::rig {

struct GPhotoCameraOptions {
  // libgphoto2 port: "usb:002,005", "ptpip:127.0.0.1:15740:15740". Empty: the only camera
  // libgphoto2 detects.
  std::string port;
  // libgphoto2 model name. Empty: "PTP/IP Camera" on ptpip: ports, otherwise as detected.
  std::string model;
  std::chrono::milliseconds connect_timeout{15000};
  // Device Busy on the trigger: retries, starting after `busy_backoff` and doubling.
  int busy_retries = 6;
  std::chrono::milliseconds busy_backoff{100};
  // Downloads that fail (connection dropped) are retried after a reconnect, within the
  // call's deadline, up to this many attempts in all.
  int download_attempts = 3;
  void Validate() const;
};

// A camera libgphoto2 found on USB (or a serial port).
struct DetectedCamera {
  std::string model;
  std::string port;
};

// Cameras libgphoto2 auto-detects (network cameras cannot be detected; name their port).
// \throw DeviceError when libgphoto2 cannot list ports.
std::vector<DetectedCamera> DetectGPhotoCameras();

// "libgphoto2 2.5.30".
std::string GPhotoVersion();

struct GPhotoCounters {
  int captures = 0;
  int busy_retries = 0;
  int download_retries = 0;
  int reconnects = 0;
};

class GPhotoCamera : public Camera {
 public:
  // Opens the camera. \throw DeviceError naming the port when it cannot be opened in time.
  explicit GPhotoCamera(GPhotoCameraOptions options);
  ~GPhotoCamera() override;
  GPhotoCamera(const GPhotoCamera&) = delete;
  GPhotoCamera& operator=(const GPhotoCamera&) = delete;

  CameraInfo Identify() override;
  std::map<std::string, std::string> Settings(std::chrono::milliseconds timeout) override;
  void SetSetting(const std::string& name, const std::string& value,
                  std::chrono::milliseconds timeout) override;
  CapturedPhoto Capture(std::chrono::milliseconds timeout) override;
  void Download(const CapturedPhoto& photo, const std::filesystem::path& destination,
                bool delete_from_camera, std::chrono::milliseconds timeout) override;
  cv::Mat PreviewFrame(std::chrono::milliseconds timeout) override;
  void PrepareExternalRelease(std::chrono::milliseconds timeout) override;
  CapturedPhoto WaitForPhoto(std::chrono::milliseconds timeout) override;

  // libgphoto2's summary text of the camera.
  std::string Summary(std::chrono::milliseconds timeout);
  // Every configuration widget with a value: full path ("/main/imgsettings/iso") -> value,
  // and, in `choices` when given, the allowed values of the radio/menu widgets.
  std::map<std::string, std::string> Configuration(
      std::chrono::milliseconds timeout,
      std::map<std::string, std::vector<std::string>>* choices = nullptr);
  // Sets a widget by its libgphoto2 name ("iso", "f-number", ...), bypassing the rig names.
  void SetConfiguration(const std::string& widget, const std::string& value,
                        std::chrono::milliseconds timeout);
  // Closes and reopens the session (finding a USB camera again by its serial number).
  void Reconnect(std::chrono::milliseconds timeout);
  GPhotoCounters Counters() const;

 private:
  class Impl;
  std::shared_ptr<Impl> impl_;
};

}  // namespace carousel::rig
