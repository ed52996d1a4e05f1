// Private to sim: the PTP/IP camera emulator behind carousel/sim/ptpip_camera.h.
//
//   ptpip_codec.{h,cpp}   the wire format (packets, PTP containers), pure
//   ptpip_camera.cpp      the server: sockets, the Init handshakes, sessions, data phases,
//                         events, faults; and the public PtpIpCamera calls
//   ptpip_operations.cpp  the camera: its PTP operations, object store, properties, captures
//
// One server thread owns the sockets and answers every operation; the API calls share the
// camera's state with it under mutex_.
#pragma once

#include <atomic>
#include <chrono>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "carousel/sim/ptpip_camera.h"
#include "ptpip_codec.h"

namespace carousel::sim {

class PtpIpCamera::Impl {
 public:
  using Clock = std::chrono::steady_clock;

  Impl(PtpIpShutter shutter, PtpIpCameraOptions options,
       std::function<std::vector<std::uint8_t>()> preview);
  ~Impl();

  std::uint16_t port() const { return port_; }
  std::string Address() const { return options_.bind_address; }

  void SetBusy(int count);
  void SetEvents(PtpIpEvents events);
  void SetCaptureDelay(std::chrono::milliseconds delay);
  void SetDownloadDelay(std::chrono::milliseconds per_chunk);
  void ReleaseShutter();
  void DropDuringDownloads(std::uint64_t after_bytes, int count);
  std::vector<PtpIpPhoto> Photos() const;
  PtpIpCounters Counters() const;
  std::map<std::uint16_t, std::uint32_t> PropertyValues() const;

 private:
  // A property: PTP data type, current value, allowed values (empty: range 0..100).
  struct Property {
    std::uint16_t type = ptpip::kUint16;
    bool writable = true;
    std::uint32_t value = 0;
    std::uint32_t default_value = 0;
    std::vector<std::uint32_t> values;
  };

  struct PendingEvent {
    Clock::time_point due;
    std::uint16_t code = 0;
    std::uint32_t tid = 0;
    std::uint32_t param = 0;
  };

  // ---- connection handling (the server thread only; ptpip_camera.cpp) ----
  void Serve();
  void Accept();
  void CloseSession();
  // Closes both sockets on purpose (a fault).
  [[noreturn]] void Drop();
  void SendDueEvents();
  void HandleCommand(const ptpip::Packet& packet);
  // Start Data, then Data packets up to End Data (host-to-device).
  void ReadHostData(ptpip::Command* command);
  void Respond(const ptpip::Command& command, std::uint16_t code,
               const std::vector<std::uint32_t>& params = {});
  // Sends a device-to-host data phase; with `object` set, counts object bytes and applies
  // an armed drop.
  void SendData(const ptpip::Command& command, const std::uint8_t* data, std::size_t size,
                bool object = false);
  void SendData(const ptpip::Command& command, ptpip::Writer& w);

  // ---- the camera (the server thread; ptpip_operations.cpp) ----
  // Photos released from outside (the remote socket) since the last look.
  void TakeExternalReleases();
  // Photos not deleted, by handle (the caller holds mutex_).
  const PtpIpPhoto* FindPhoto(std::uint32_t handle) const;
  static std::uint32_t ParentOf(std::uint32_t handle);
  // The handles of a format (0: any) under a parent (0: anywhere; 0xFFFFFFFF: the root);
  // the caller holds mutex_.
  std::vector<std::uint32_t> Handles(std::uint32_t format, std::uint32_t parent) const;
  void Dispatch(const ptpip::Command& c);
  void DeviceInfo(const ptpip::Command& c);
  void ObjectInfo(const ptpip::Command& c);
  void GetObject(const ptpip::Command& c);
  void DeleteObject(const ptpip::Command& c);
  void InitiateCapture(const ptpip::Command& c);
  // Exposes, stores and announces a photo (InitiateCapture, or a release from outside with
  // transaction id 0).
  void TakePhoto(std::uint32_t tid, Clock::time_point arrived);
  // One live-view frame: a complete JPEG (libgphoto2 hands the data phase over as it is).
  void Stream(const ptpip::Command& c);
  void PropertyDesc(const ptpip::Command& c);
  void SetProperty(const ptpip::Command& c);

  PtpIpShutter shutter_;
  std::function<std::vector<std::uint8_t>()> preview_;  // empty: a full photo per frame
  PtpIpCameraOptions options_;
  std::uint16_t port_ = 0;
  int listen_fd_ = -1;
  int wake_fd_ = -1;
  std::atomic<bool> stopping_{false};
  std::thread thread_;

  // The server thread's own state.
  int cmd_fd_ = -1;
  int event_fd_ = -1;
  std::uint32_t connection_number_ = 0;
  bool session_open_ = false;
  std::deque<PendingEvent> pending_events_;

  // Shared with the API (mutex_).
  mutable std::mutex mutex_;
  std::map<std::uint16_t, Property> properties_;
  std::vector<PtpIpPhoto> photos_;
  PtpIpCounters counters_;
  int busy_ = 0;
  PtpIpEvents events_ = PtpIpEvents::kAll;
  std::chrono::milliseconds capture_delay_{0};
  std::chrono::milliseconds download_delay_{0};
  std::vector<Clock::time_point> external_releases_;  // not yet taken
  std::optional<std::uint64_t> drop_after_;           // object bytes still to serve before the drop
  std::uint64_t drop_after_bytes_ = 0;
  int drops_left_ = 0;
};

}  // namespace carousel::sim
