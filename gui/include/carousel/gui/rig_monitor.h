// The Rig panel's devices, without a window: the rig (simulated, or a rig file's turntable
// controller and libgphoto2 cameras, opened through studio's one rig factory) held open on a
// thread of its own while nothing is being captured: turntable status, identify, home, jog,
// the cameras' settings and live view (rig::Camera::PreviewFrame: libgphoto2's preview, which
// the PTP/IP emulator streams). A session opens the same devices, so the window disconnects
// the monitor before it presses the button.
#pragma once

#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/rig/usb_devices.h"
#include "carousel/studio/rig_factory.h"

namespace carousel::gui {

struct RigCameraView {
  std::string name;  // "Carousel PTP/IP Emulator EMU0 on ptpip:127.0.0.1:..."
  std::map<std::string, std::string> settings;
};

struct RigMonitorStatus {
  enum class State { kOff, kConnecting, kOn, kFailed };
  State state = State::kOff;
  std::string error;      // kFailed, or the last command's failure (names the device)
  std::string turntable;  // model, firmware and port
  double angle_deg = 0.0;
  bool moving = false, homed = false;
  std::string fault;
  std::vector<RigCameraView> cameras;
  int live_camera = 0;
  int frames = 0;  // live-view frames received since connecting
  double fps = 0.0;
};

class RigMonitor {
 public:
  RigMonitor() = default;
  ~RigMonitor();
  RigMonitor(const RigMonitor&) = delete;
  RigMonitor& operator=(const RigMonitor&) = delete;

  // Opens the rig on the monitor's thread (returns at once; Status() follows).
  void Connect(const studio::RigRequest& request);
  // Closes the devices and waits until they are released.
  void Disconnect();

  RigMonitorStatus Status() const;
  // The newest live-view frame (CV_8UC4 RGBA) when it is newer than `*seen`, which is updated.
  cv::Mat TakeFrame(int* seen);

  void Identify();
  void Home();
  void Jog(double degrees);  // relative to the current angle
  void SetLiveCamera(int camera);
  void SetCameraSetting(int camera, const std::string& name, const std::string& value);

 private:
  using Command = std::function<void(studio::RigBackends&)>;
  void Queue(Command command);
  void Loop(studio::RigRequest request);

  mutable std::mutex mutex_;
  std::condition_variable wake_;
  RigMonitorStatus status_;
  std::deque<Command> commands_;
  bool stop_ = false;
  cv::Mat frame_;
  std::thread thread_;
};

// Cameras and USB-serial adapters arriving and leaving (rig::UsbMonitor: libusb hotplug, or
// polling where hotplug is missing), as lines for the Rig panel, newest last.
class UsbEvents {
 public:
  UsbEvents();
  ~UsbEvents();
  UsbEvents(const UsbEvents&) = delete;
  UsbEvents& operator=(const UsbEvents&) = delete;
  // "present: Canon PTP camera on usb:001,005", "arrived: ...", "left: ...".
  std::vector<std::string> Lines() const;
  // How it watches: "hotplug", "polling (reason)", "unavailable (reason)".
  std::string Mode() const;

 private:
  mutable std::mutex mutex_;
  std::vector<std::string> lines_;
  std::unique_ptr<rig::UsbMonitor> monitor_;
};

}  // namespace carousel::gui
