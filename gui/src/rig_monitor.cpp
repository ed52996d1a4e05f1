#include "carousel/gui/rig_monitor.h"

#include <chrono>
#include <cmath>
#include <numbers>

#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"

namespace carousel::gui {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

constexpr double kDegPerRad = 180.0 / std::numbers::pi;

}  // namespace

RigMonitor::~RigMonitor() { Disconnect(); }

void RigMonitor::Connect(const studio::RigRequest& request) {
  Disconnect();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    status_ = RigMonitorStatus();
    status_.state = RigMonitorStatus::State::kConnecting;
    stop_ = false;
    commands_.clear();
    frame_.release();
  }
  thread_ = std::thread([this, request] { Loop(request); });
}

void RigMonitor::Disconnect() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  if (thread_.joinable()) thread_.join();
  std::lock_guard<std::mutex> lock(mutex_);
  if (status_.state != RigMonitorStatus::State::kFailed)
    status_.state = RigMonitorStatus::State::kOff;
}

RigMonitorStatus RigMonitor::Status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return status_;
}

cv::Mat RigMonitor::TakeFrame(int* seen) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (frame_.empty() || status_.frames == *seen) return {};
  *seen = status_.frames;
  return frame_;
}

void RigMonitor::Queue(Command command) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    commands_.push_back(std::move(command));
  }
  wake_.notify_all();
}

void RigMonitor::Identify() {
  Queue([this](studio::RigBackends& rig) {
    const rig::TurntableInfo info = rig.turntable->Identify();
    std::lock_guard<std::mutex> lock(mutex_);
    status_.turntable = info.model + " " + info.firmware + " on " + info.port;
  });
}

void RigMonitor::Home() {
  Queue([](studio::RigBackends& rig) { rig.turntable->Home(60s); });
}

void RigMonitor::Jog(double degrees) {
  Queue([degrees](studio::RigBackends& rig) {
    const rig::TurntableStatus now = rig.turntable->Status();
    rig.turntable->MoveTo(now.target_rad + degrees / kDegPerRad, 60s);
  });
}

void RigMonitor::SetLiveCamera(int camera) {
  std::lock_guard<std::mutex> lock(mutex_);
  status_.live_camera = camera;
}

void RigMonitor::SetCameraSetting(int camera, const std::string& name, const std::string& value) {
  Queue([this, camera, name, value](studio::RigBackends& rig) {
    rig::Camera& c = *rig.cameras.at(static_cast<std::size_t>(camera));
    c.SetSetting(name, value, 10s);
    const auto settings = c.Settings(10s);
    std::lock_guard<std::mutex> lock(mutex_);
    status_.cameras.at(static_cast<std::size_t>(camera)).settings = settings;
  });
}

void RigMonitor::Loop(studio::RigRequest request) {
  studio::RigBackends rig;
  try {
    rig = studio::OpenRig(request);
    const rig::TurntableInfo info = rig.turntable->Identify();
    std::vector<RigCameraView> cameras;
    for (const auto& camera : rig.cameras) {
      const rig::CameraInfo c = camera->Identify();
      cameras.push_back({c.manufacturer + " " + c.model + " " + c.serial + " on " + c.port,
                         camera->Settings(10s)});
    }
    std::lock_guard<std::mutex> lock(mutex_);
    status_.turntable = info.model + " " + info.firmware + " on " + info.port;
    status_.cameras = std::move(cameras);
    status_.state = RigMonitorStatus::State::kOn;
  } catch (const std::exception& e) {
    std::lock_guard<std::mutex> lock(mutex_);
    status_.state = RigMonitorStatus::State::kFailed;
    status_.error = e.what();
    return;
  }
  Clock::time_point last_status{}, fps_start = Clock::now();
  int fps_frames = 0;
  while (true) {
    Command command;
    int live = 0;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (stop_) break;
      if (!commands_.empty()) {
        command = std::move(commands_.front());
        commands_.pop_front();
      }
      live = status_.live_camera;
    }
    try {
      if (command) command(rig);
      if (Clock::now() - last_status > 200ms) {
        const rig::TurntableStatus s = rig.turntable->Status();
        last_status = Clock::now();
        std::lock_guard<std::mutex> lock(mutex_);
        status_.angle_deg = s.angle_rad * kDegPerRad;
        status_.moving = s.moving;
        status_.homed = s.homed;
        status_.fault = s.fault;
      }
      if (live >= 0 && live < static_cast<int>(rig.cameras.size())) {
        const cv::Mat bgr = rig.cameras[static_cast<std::size_t>(live)]->PreviewFrame(5s);
        cv::Mat rgba;
        if (!bgr.empty()) {
          cv::cvtColor(bgr, rgba, bgr.channels() == 1 ? cv::COLOR_GRAY2RGBA : cv::COLOR_BGR2RGBA);
          ++fps_frames;
        }
        std::lock_guard<std::mutex> lock(mutex_);
        if (!rgba.empty()) {
          frame_ = rgba;
          ++status_.frames;
        }
        const double elapsed = std::chrono::duration<double>(Clock::now() - fps_start).count();
        if (elapsed > 1.0) {
          status_.fps = fps_frames / elapsed;
          fps_frames = 0;
          fps_start = Clock::now();
        }
      }
    } catch (const std::exception& e) {  // the device named in the message stays shown
      std::lock_guard<std::mutex> lock(mutex_);
      status_.error = e.what();
    }
    std::unique_lock<std::mutex> lock(mutex_);
    // About 10 live-view frames a second, sooner when a command waits.
    wake_.wait_for(lock, 100ms, [this] { return stop_ || !commands_.empty(); });
  }
  // The devices close here (rig's destructors), on this thread.
}

namespace {

std::string Describe(const rig::UsbDevice& d) {
  return d.vendor + " " + d.description + " (" + d.ids() + ") on " +
         (d.kind == rig::UsbDeviceKind::kCamera ? d.gphoto_port() : "port " + d.port_path);
}

}  // namespace

UsbEvents::UsbEvents() {
  monitor_ = std::make_unique<rig::UsbMonitor>([this](const rig::UsbDevice& d, bool arrived) {
    std::lock_guard<std::mutex> lock(mutex_);
    lines_.push_back(std::string(arrived ? "arrived: " : "left: ") + Describe(d));
    if (lines_.size() > 50) lines_.erase(lines_.begin());
  });
  std::lock_guard<std::mutex> lock(mutex_);
  for (const rig::UsbDevice& d : monitor_->initial())
    lines_.insert(lines_.begin(), "present: " + Describe(d));
}

UsbEvents::~UsbEvents() { monitor_.reset(); }

std::vector<std::string> UsbEvents::Lines() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return lines_;
}

std::string UsbEvents::Mode() const {
  switch (monitor_->mode()) {
    case rig::UsbMonitorMode::kHotplug:
      return "hotplug";
    case rig::UsbMonitorMode::kPolling:
      return "polling (" + monitor_->reason() + ")";
    case rig::UsbMonitorMode::kUnavailable:
      return "unavailable (" + monitor_->reason() + ")";
  }
  return "?";
}

}  // namespace carousel::gui
