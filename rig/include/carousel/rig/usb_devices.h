// USB device discovery with libusb: the cameras (PTP still-image class) and the USB-serial
// adapters (FTDI, CH340, CP210x, Prolific, Arduino boards) on the bus, and arrive/leave events
// for the GUI and studio.
//
// Events come from libusb's hotplug support where the platform has it; elsewhere (no hotplug,
// or a sandbox without usbfs) UsbMonitor falls back to listing the bus periodically, or reports
// that USB is unavailable, without failing.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

namespace carousel::rig {

enum class UsbDeviceKind { kCamera, kSerialAdapter };

// One interface's class triple (bInterfaceClass, SubClass, Protocol).
struct UsbInterfaceClass {
  std::uint8_t interface_class = 0;
  std::uint8_t subclass = 0;
  std::uint8_t protocol = 0;
};

struct UsbDevice {
  UsbDeviceKind kind = UsbDeviceKind::kCamera;
  std::uint16_t vendor_id = 0;
  std::uint16_t product_id = 0;
  int bus = 0;
  int address = 0;
  std::string port_path;    // physical port, "1-2.3" (stable across re-plugging into it)
  std::string vendor;       // "Canon", "FTDI", ...
  std::string description;  // "PTP camera", "CH340 USB-serial", "Arduino Uno", ...
  // libgphoto2's port name for a camera: "usb:001,005".
  std::string gphoto_port() const;
  // "04a9:327f"
  std::string ids() const;
  bool operator==(const UsbDevice& other) const;
};

// What a device is, from its ids and interface classes: false for devices Carousel does not
// use; otherwise fills `device`'s ids, kind, vendor and description.
bool ClassifyUsbDevice(std::uint16_t vendor_id, std::uint16_t product_id,
                       const std::vector<UsbInterfaceClass>& interfaces, UsbDevice* device);

// The cameras and serial adapters on the bus now.
// \throw DeviceError("usb", reason) when libusb cannot reach the bus (no usbfs, permissions).
std::vector<UsbDevice> ListUsbDevices();

struct UsbChanges {
  std::vector<UsbDevice> arrived;
  std::vector<UsbDevice> left;
};
// The devices in `after` but not `before`, and the other way round (same bus, address, ids).
UsbChanges DiffUsbDevices(const std::vector<UsbDevice>& before,
                          const std::vector<UsbDevice>& after);

enum class UsbMonitorMode {
  kHotplug,      // libusb hotplug events
  kPolling,      // the bus is listed every poll interval
  kUnavailable,  // USB cannot be reached here; no events will come
};

// Calls `on_change(device, arrived)` from its own thread for every camera or serial adapter
// that arrives or leaves after construction. Devices present at construction are in
// `initial()`.
class UsbMonitor {
 public:
  using Callback = std::function<void(const UsbDevice& device, bool arrived)>;
  explicit UsbMonitor(Callback on_change,
                      std::chrono::milliseconds poll_interval = std::chrono::milliseconds(1000));
  ~UsbMonitor();
  UsbMonitor(const UsbMonitor&) = delete;
  UsbMonitor& operator=(const UsbMonitor&) = delete;

  UsbMonitorMode mode() const;
  // Why the mode is not kHotplug ("libusb: no hotplug support on this platform", ...).
  const std::string& reason() const;
  const std::vector<UsbDevice>& initial() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace carousel::rig
