// The PTP/IP camera emulator: a camera on 127.0.0.1 that real, unmodified libgphoto2 (and the
// Debian gphoto2 client) drives like a network DSLR, serving photos the simulated rig renders
// at the turntable's current angle.
//
// It speaks PTP/IP as libgphoto2 2.5.30 does (../shared/reference/rig-notes.md section 1): the
// command and event sockets with their Init handshakes, the standard PTP operations a generic
// camera (VendorExtensionID 0) needs, ObjectAdded and CaptureComplete events, GetPartialObject
// for large photos, SetDevicePropValue with a host-to-device data phase, and live view through
// PTP 1.1 streams (SupportedStreams/EnabledStreams, GetStreamInfo, GetStream: the only preview
// path libgphoto2 has for a generic camera). One client session
// at a time; after the client leaves (or the connection drops) it accepts the next one, and
// the photos stay on its card.
//
// Faults for tests: Device Busy answers to InitiateCapture, missing events, a connection
// dropped in the middle of a download, a slow capture, a slow download.
#pragma once

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace carousel::sim {

class SimCamera;

// Which events follow a capture.
enum class PtpIpEvents {
  kAll,           // ObjectAdded, then CaptureComplete (a well-behaved camera)
  kAddedOnly,     // no CaptureComplete
  kCompleteOnly,  // no ObjectAdded
  kNone,          // nothing at all
};

struct PtpIpCameraOptions {
  std::string manufacturer = "Carousel";
  std::string model = "PTP/IP Emulator";
  std::string serial = "EMU0001";
  std::string bind_address = "127.0.0.1";
  std::uint16_t port = 0;  // 0: any free port (see PtpIpCamera::port())
  // Time from InitiateCapture to the ObjectAdded event, like a shutter plus processing.
  std::chrono::milliseconds capture_delay{0};
  void Validate() const;
};

// Renders the photo of one capture: JPEG bytes. Called on the emulator's thread; `settings`
// are the camera's current values by rig setting name (iso, aperture, shutterspeed,
// whitebalance).
using PtpIpShutter =
    std::function<std::vector<std::uint8_t>(const std::map<std::string, std::string>& settings)>;

// A photo the emulator took.
struct PtpIpPhoto {
  std::uint32_t handle = 0;
  std::string name;  // IMG_0001.JPG
  std::vector<std::uint8_t> bytes;
  std::chrono::steady_clock::time_point triggered_at{};  // when InitiateCapture arrived
  bool deleted = false;
};

// What the emulator saw, for tests and the CLI.
struct PtpIpCounters {
  int sessions = 0;                // OpenSession calls answered OK
  int connections = 0;             // command connections accepted
  int operations = 0;              // PTP operations received
  int captures = 0;                // InitiateCapture answered OK
  int busy_answers = 0;            // InitiateCapture answered Device Busy
  int drops = 0;                   // connections dropped on purpose
  int preview_frames = 0;          // live-view frames served (GetStream)
  int external_releases = 0;       // ReleaseShutter() calls
  std::uint64_t bytes_served = 0;  // object bytes sent
};

class PtpIpCamera {
 public:
  // Listens at once; throws DeviceError naming the address if it cannot.
  PtpIpCamera(PtpIpShutter shutter, PtpIpCameraOptions options = {});
  // A camera photographing the simulated rig: `camera` renders, its settings follow the PTP
  // properties the client sets, and live view (PTP 1.1 streams) shows its preview frames.
  // With the other constructor a live-view frame is a full photo from `shutter`.
  PtpIpCamera(const std::shared_ptr<SimCamera>& camera, PtpIpCameraOptions options = {});
  ~PtpIpCamera();
  PtpIpCamera(const PtpIpCamera&) = delete;
  PtpIpCamera& operator=(const PtpIpCamera&) = delete;

  std::uint16_t port() const;
  // The libgphoto2 port path: "ptpip:127.0.0.1:P:P" (both sockets on one port; rig-notes 1.6.1).
  std::string gphoto_port() const;

  // The remote-release socket: takes a photo as if the shutter button were pressed (a wired
  // release from the turntable controller); ObjectAdded follows as after InitiateCapture.
  void ReleaseShutter();

  // ---- faults (take effect for the next operations) ----
  // The next `count` InitiateCapture operations answer Device Busy (0x2019).
  void SetBusy(int count);
  void SetEvents(PtpIpEvents events);
  void SetCaptureDelay(std::chrono::milliseconds delay);
  // A slow link: waits this long before each 256 KiB chunk of an object download.
  void SetDownloadDelay(std::chrono::milliseconds per_chunk);
  // Close both sockets once `after_bytes` bytes of an object download have been sent, for the
  // next `count` downloads (0 disarms).
  void DropDuringDownloads(std::uint64_t after_bytes, int count = 1);

  std::vector<PtpIpPhoto> Photos() const;
  PtpIpCounters Counters() const;
  // Property values by PTP code, as the client last set them.
  std::map<std::uint16_t, std::uint32_t> PropertyValues() const;

 private:
  class Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace carousel::sim
