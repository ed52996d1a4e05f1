// Camera: the interface every camera backend implements (libgphoto2 in carousel_rig, the
// simulated camera in sim/). Part of carousel_rig_api: no third-party dependencies.
//
// Contract for implementations:
//   - every blocking call takes a timeout and throws DeviceError naming the camera when it
//     expires or the device fails; nothing waits unboundedly;
//   - Capture() fires the shutter and returns once the camera reports the new photo;
//     Download() then writes that photo atomically (temporary name, fsync, rename), so a
//     half-transferred photo never sits under its final name, and never overwrites a file;
//   - calls on one Camera object are not concurrent (studio gives each camera its own worker).
// Settings are strings as the camera presents them ("400", "f/8", "1/125"), named by the keys
// in camera_settings.h; unknown keys or values are InvalidArgument.
#pragma once

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <map>
#include <string>

#include <opencv2/core.hpp>

#include "carousel/core/error.h"
#include "carousel/rig/camera_settings.h"

namespace carousel::rig {

struct CameraInfo {
  std::string manufacturer;
  std::string model;
  std::string serial;  // unique per body: rig files name cameras by it
  std::string port;    // "usb:002,005", "ptpip:127.0.0.1:15740", "sim:0"
  std::string driver;  // "libgphoto2 2.5.30", "simulated"
};

// A photo the camera holds after Capture(), not yet downloaded.
struct CapturedPhoto {
  std::string camera_path;  // where the camera stores it, e.g. "/store_00010001/DCIM/IMG_0001.JPG"
  std::uint64_t size_bytes = 0;
  std::chrono::steady_clock::time_point triggered_at{};  // when the trigger was sent
};

class Camera {
 public:
  virtual ~Camera() = default;

  virtual CameraInfo Identify() = 0;
  // Current values of the settings the camera exposes.
  virtual std::map<std::string, std::string> Settings(std::chrono::milliseconds timeout) = 0;
  // \throw InvalidArgument for an unknown setting or value; DeviceError on failure.
  virtual void SetSetting(const std::string& name, const std::string& value,
                          std::chrono::milliseconds timeout) = 0;
  // Fires the shutter and waits until the photo exists on the camera.
  virtual CapturedPhoto Capture(std::chrono::milliseconds timeout) = 0;
  // Writes `photo` to `destination` atomically; never overwrites (IoError if it exists).
  // Deletes it from the camera afterwards when `delete_from_camera`.
  virtual void Download(const CapturedPhoto& photo, const std::filesystem::path& destination,
                        bool delete_from_camera, std::chrono::milliseconds timeout) = 0;
  // A live-view frame (8-bit BGR, any size the camera offers).
  virtual cv::Mat PreviewFrame(std::chrono::milliseconds timeout) = 0;

  // A shutter released from outside the camera (the turntable controller's shutter output
  // wired to its remote socket): PrepareExternalRelease() before the release, then
  // WaitForPhoto() returns the photo the release produced. Backends that cannot be released
  // from outside throw DeviceError.
  virtual void PrepareExternalRelease(std::chrono::milliseconds /*timeout*/) {
    throw DeviceError(Identify().port, "this camera cannot be released from outside");
  }
  virtual CapturedPhoto WaitForPhoto(std::chrono::milliseconds /*timeout*/) {
    throw DeviceError(Identify().port, "this camera cannot be released from outside");
  }
};

}  // namespace carousel::rig
