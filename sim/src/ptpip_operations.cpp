// The emulated camera behind the PTP/IP server: the PTP operations it answers, its object
// store (one storage, DCIM/100CAROU, the photos), its device properties, and captures.
#include <algorithm>
#include <cmath>
#include <sstream>

#include "carousel/rig/camera_settings.h"
#include "ptpip_emulator.h"

namespace carousel::sim {
namespace {

using ptpip::Command;
using ptpip::kFormatAssociation;
using ptpip::kFormatJpeg;
using ptpip::Writer;
using enum ptpip::Op;
using enum ptpip::Response;
using enum ptpip::EventCode;
using enum ptpip::Prop;

constexpr std::uint32_t kStorageId = 0x00010001;
constexpr std::uint32_t kDcimHandle = 1;
constexpr std::uint32_t kFolderHandle = 2;
constexpr std::uint32_t kFirstPhotoHandle = 3;

std::string FormatAperture(std::uint32_t v) {
  std::ostringstream out;
  out << "f/" << v / 100.0;
  return out.str();
}

std::string FormatShutter(std::uint32_t tenths_of_ms) {
  const double seconds = tenths_of_ms / 10000.0;
  std::ostringstream out;
  if (seconds >= 1.0) {
    out << seconds;
  } else {
    out << "1/" << std::lround(1.0 / seconds);
  }
  return out.str();
}

std::string WhiteBalanceName(std::uint32_t v) {
  switch (v) {
    case 2:
      return "auto";
    case 4:
      return "daylight";
    case 5:
      return "fluorescent";
    case 6:
      return "tungsten";
    case 7:
      return "flash";
    default:
      return "manual";
  }
}

}  // namespace

void PtpIpCamera::Impl::TakeExternalReleases() {
  std::vector<Clock::time_point> releases;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    releases.swap(external_releases_);
  }
  for (const Clock::time_point at : releases) TakePhoto(0, at);
}

// ---- the object store ----

const PtpIpPhoto* PtpIpCamera::Impl::FindPhoto(std::uint32_t handle) const {
  for (const PtpIpPhoto& p : photos_) {
    if (p.handle == handle && !p.deleted) return &p;
  }
  return nullptr;
}

std::uint32_t PtpIpCamera::Impl::ParentOf(std::uint32_t handle) {
  if (handle == kDcimHandle) return 0;
  if (handle == kFolderHandle) return kDcimHandle;
  return kFolderHandle;
}

std::vector<std::uint32_t> PtpIpCamera::Impl::Handles(std::uint32_t format,
                                                      std::uint32_t parent) const {
  std::vector<std::uint32_t> all = {kDcimHandle, kFolderHandle};
  for (const PtpIpPhoto& p : photos_) {
    if (!p.deleted) all.push_back(p.handle);
  }
  std::vector<std::uint32_t> out;
  for (const std::uint32_t h : all) {
    const std::uint16_t f = h < kFirstPhotoHandle ? kFormatAssociation : kFormatJpeg;
    if (format != 0 && format != f) continue;
    if (parent == 0xFFFFFFFF && ParentOf(h) != 0) continue;
    if (parent != 0 && parent != 0xFFFFFFFF && ParentOf(h) != parent) continue;
    out.push_back(h);
  }
  return out;
}

// ---- the operations ----

void PtpIpCamera::Impl::Dispatch(const Command& c) {
  if (c.code == kGetDeviceInfo) return DeviceInfo(c);
  if (c.code == kOpenSession) {
    if (session_open_) return Respond(c, kSessionAlreadyOpen);
    session_open_ = true;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      ++counters_.sessions;
    }
    return Respond(c, kOk);
  }
  if (!session_open_) return Respond(c, kSessionNotOpen);
  switch (c.code) {
    case kCloseSession:
      session_open_ = false;
      return Respond(c, kOk);
    case kGetStorageIds: {
      Writer w;
      w.Array32({kStorageId});
      SendData(c, w);
      return Respond(c, kOk);
    }
    case kGetStorageInfo: {
      if (c.params[0] != kStorageId) return Respond(c, kInvalidStorageId);
      std::uint64_t used = 0;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        for (const PtpIpPhoto& p : photos_) used += p.deleted ? 0 : p.bytes.size();
      }
      const std::uint64_t capacity = 32ULL << 30;
      Writer w;
      w.U16(4);  // removable RAM (a memory card)
      w.U16(2);  // generic hierarchical
      w.U16(0);  // read-write
      w.U64(capacity);
      w.U64(capacity - std::min(used, capacity));
      w.U32(0xFFFFFFFF);
      w.Str("SD card");
      w.Str("CAROUSEL");
      SendData(c, w);
      return Respond(c, kOk);
    }
    case kGetNumObjects:
    case kGetObjectHandles: {
      if (c.params[0] != kStorageId && c.params[0] != 0xFFFFFFFF) {
        return Respond(c, kInvalidStorageId);
      }
      const std::uint32_t parent = c.params[2];
      std::vector<std::uint32_t> handles;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (parent != 0 && parent != 0xFFFFFFFF && parent != kDcimHandle &&
            parent != kFolderHandle) {
          return Respond(c, FindPhoto(parent) ? kInvalidParentObject : kInvalidObjectHandle);
        }
        handles = Handles(c.params[1], parent);
      }
      if (c.code == kGetNumObjects) {
        return Respond(c, kOk, {static_cast<std::uint32_t>(handles.size())});
      }
      Writer w;
      w.Array32(handles);
      SendData(c, w);
      return Respond(c, kOk);
    }
    case kGetObjectInfo:
      return ObjectInfo(c);
    case kGetObject:
    case kGetPartialObject:
      return GetObject(c);
    case kDeleteObject:
      return DeleteObject(c);
    case kInitiateCapture:
      return InitiateCapture(c);
    case kGetDevicePropDesc:
    case kGetDevicePropValue:
      return PropertyDesc(c);
    case kSetDevicePropValue:
      return SetProperty(c);
    case kGetStreamInfo: {
      Writer w;
      w.U64(36);                             // dataset size
      w.U64(1000000);                        // time resolution: microseconds
      for (int i = 0; i < 5; ++i) w.U32(0);  // no frame/packet headers, sizes unbounded
      SendData(c, w);
      return Respond(c, kOk);
    }
    case kGetStream:
      return Stream(c);
    default:
      return Respond(c, kOperationNotSupported);
  }
}

void PtpIpCamera::Impl::DeviceInfo(const Command& c) {
  Writer w;
  w.U16(100);  // PTP 1.00
  w.U32(0);    // no vendor extension: libgphoto2 takes its generic paths
  w.U16(0);
  w.Str("");
  w.U16(0);
  w.Array16({kGetDeviceInfo, kOpenSession, kCloseSession, kGetStorageIds, kGetStorageInfo,
             kGetNumObjects, kGetObjectHandles, kGetObjectInfo, kGetObject, kDeleteObject,
             kInitiateCapture, kGetDevicePropDesc, kGetDevicePropValue, kSetDevicePropValue,
             kGetPartialObject, kGetStreamInfo, kGetStream});
  w.Array16({kObjectAdded, 0x4003, 0x4006, kCaptureComplete});
  std::vector<std::uint16_t> props;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& [code, p] : properties_) props.push_back(code);
  }
  w.Array16(props);
  w.Array16({kFormatJpeg});
  w.Array16({kFormatJpeg, kFormatAssociation});
  w.Str(options_.manufacturer);
  w.Str(options_.model);
  w.Str("1.0");
  w.Str(options_.serial);
  SendData(c, w);
  Respond(c, kOk);
}

void PtpIpCamera::Impl::ObjectInfo(const Command& c) {
  const std::uint32_t h = c.params[0];
  Writer w;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const PtpIpPhoto* photo = FindPhoto(h);
    if (!photo && h != kDcimHandle && h != kFolderHandle) {
      return Respond(c, kInvalidObjectHandle);
    }
    w.U32(kStorageId);
    w.U16(photo ? kFormatJpeg : kFormatAssociation);
    w.U16(0);  // no protection
    w.U32(photo ? static_cast<std::uint32_t>(photo->bytes.size()) : 0);
    w.U16(0);  // no thumbnail
    w.U32(0);
    w.U32(0);
    w.U32(0);
    w.U32(0);  // image width and height: not known without decoding
    w.U32(0);
    w.U32(photo ? 24 : 0);
    w.U32(ParentOf(h));
    w.U16(photo ? 0 : 1);  // folders: generic folder association
    w.U32(0);
    w.U32(0);
    w.Str(photo ? photo->name : (h == kDcimHandle ? "DCIM" : "100CAROU"));
    w.Str("20261201T120000");
    w.Str("20261201T120000");
    w.Str("");
  }
  SendData(c, w);
  Respond(c, kOk);
}

void PtpIpCamera::Impl::GetObject(const Command& c) {
  std::vector<std::uint8_t> bytes;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const PtpIpPhoto* photo = FindPhoto(c.params[0]);
    if (!photo) return Respond(c, kInvalidObjectHandle);
    bytes = photo->bytes;
  }
  std::size_t offset = 0;
  std::size_t size = bytes.size();
  if (c.code == kGetPartialObject) {
    offset = std::min<std::size_t>(c.params[1], bytes.size());
    size = std::min<std::size_t>(c.params[2], bytes.size() - offset);
  }
  SendData(c, bytes.data() + offset, size, true);
  if (c.code == kGetPartialObject) return Respond(c, kOk, {static_cast<std::uint32_t>(size)});
  Respond(c, kOk);
}

void PtpIpCamera::Impl::DeleteObject(const Command& c) {
  std::lock_guard<std::mutex> lock(mutex_);
  const std::uint32_t h = c.params[0];
  if (h == 0xFFFFFFFF) {
    for (PtpIpPhoto& p : photos_) p.deleted = true;
    return Respond(c, kOk);
  }
  if (h == kDcimHandle || h == kFolderHandle) return Respond(c, kObjectWriteProtected);
  for (PtpIpPhoto& p : photos_) {
    if (p.handle == h && !p.deleted) {
      p.deleted = true;
      return Respond(c, kOk);
    }
  }
  Respond(c, kInvalidObjectHandle);
}

void PtpIpCamera::Impl::InitiateCapture(const Command& c) {
  const Clock::time_point arrived = Clock::now();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (busy_ > 0) {
      --busy_;
      ++counters_.busy_answers;
      return Respond(c, kDeviceBusy);
    }
    ++counters_.captures;
  }
  // Answer first, like a camera: the photo appears later, announced by the events.
  Respond(c, kOk);
  TakePhoto(c.tid, arrived);
}

void PtpIpCamera::Impl::TakePhoto(std::uint32_t tid, Clock::time_point arrived) {
  PtpIpEvents events;
  std::chrono::milliseconds delay;
  std::map<std::string, std::string> settings;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    events = events_;
    delay = capture_delay_;
    settings[rig::kSettingIso] = std::to_string(properties_[kExposureIndex].value);
    settings[rig::kSettingAperture] = FormatAperture(properties_[kFNumber].value);
    settings[rig::kSettingShutterSpeed] = FormatShutter(properties_[kExposureTime].value);
    settings[rig::kSettingWhiteBalance] = WhiteBalanceName(properties_[kWhiteBalance].value);
  }
  PtpIpPhoto photo;
  photo.bytes = shutter_(settings);
  photo.triggered_at = arrived;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const int number = static_cast<int>(photos_.size()) + 1;
    photo.handle = kFirstPhotoHandle + static_cast<std::uint32_t>(photos_.size());
    photo.name = "IMG_" + std::to_string(10000 + number % 10000).substr(1) + ".JPG";
    photos_.push_back(photo);
  }
  const Clock::time_point due = std::max(Clock::now(), arrived + delay);
  if (events == PtpIpEvents::kAll || events == PtpIpEvents::kAddedOnly) {
    pending_events_.push_back({due, kObjectAdded, tid, photo.handle});
  }
  if (events == PtpIpEvents::kAll || events == PtpIpEvents::kCompleteOnly) {
    pending_events_.push_back({due, kCaptureComplete, tid, tid});
  }
}

void PtpIpCamera::Impl::Stream(const Command& c) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if ((properties_[kEnabledStreams].value & 1) == 0) return Respond(c, kAccessDenied);
    ++counters_.preview_frames;
  }
  std::vector<std::uint8_t> frame =
      preview_ ? preview_() : shutter_(std::map<std::string, std::string>{});
  SendData(c, frame.data(), frame.size());
  Respond(c, kOk);
}

void PtpIpCamera::Impl::PropertyDesc(const Command& c) {
  Writer w;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = properties_.find(static_cast<std::uint16_t>(c.params[0]));
    if (it == properties_.end()) return Respond(c, kDevicePropNotSupported);
    const Property& p = it->second;
    if (c.code == kGetDevicePropValue) {
      w.Value(p.type, p.value);
    } else {
      w.U16(it->first);
      w.U16(p.type);
      w.U8(p.writable ? 1 : 0);
      w.Value(p.type, p.default_value);
      w.Value(p.type, p.value);
      if (p.values.empty()) {
        w.U8(1);  // range 0..100 step 1
        w.Value(p.type, 0);
        w.Value(p.type, 100);
        w.Value(p.type, 1);
      } else {
        w.U8(2);  // enumeration
        w.U16(static_cast<std::uint32_t>(p.values.size()));
        for (const std::uint32_t v : p.values) w.Value(p.type, v);
      }
    }
  }
  SendData(c, w);
  Respond(c, kOk);
}

void PtpIpCamera::Impl::SetProperty(const Command& c) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = properties_.find(static_cast<std::uint16_t>(c.params[0]));
  if (it == properties_.end()) return Respond(c, kDevicePropNotSupported);
  Property& p = it->second;
  if (!p.writable) return Respond(c, kAccessDenied);
  const std::optional<std::uint32_t> v = ptpip::DecodeValue(p.type, c.data);
  if (!v) return Respond(c, kInvalidDevicePropFormat);
  if (std::find(p.values.begin(), p.values.end(), *v) == p.values.end()) {
    return Respond(c, kInvalidDevicePropValue);
  }
  p.value = *v;
  Respond(c, kOk);
}

}  // namespace carousel::sim
