// `carousel camera list|watch|summary|config|capture` (cameras through libgphoto2: USB DSLRs, or
// network cameras by their ptpip: port) and `carousel sim camera` (the PTP/IP camera emulator
// photographing the simulated rig, for trying the former without a camera).
#pragma once

#include <cstdint>
#include <filesystem>
#include <ostream>
#include <string>
#include <vector>

namespace carousel::app {

struct CameraArgs {
  std::string action;  // list, watch, summary, config, capture
  std::string port;    // libgphoto2 port ("usb:001,005", "ptpip:HOST:P:P"); empty: the only one
  std::string model;   // libgphoto2 model; empty: detected ("PTP/IP Camera" for ptpip:)
  // config: NAME=VALUE to set, by rig setting name (iso, aperture, shutterspeed, whitebalance,
  // imageformat, capturetarget) or libgphoto2 widget name.
  std::vector<std::string> set;
  std::filesystem::path out = ".";  // capture: folder for the photos
  int count = 1;                    // capture: photos
  bool delete_after = false;        // capture: delete each photo from the camera once saved
  double timeout_s = 30.0;          // per operation
  double seconds = 0.0;             // watch: how long, 0 = until interrupted
};

int RunCamera(const CameraArgs& args, std::ostream& out, std::ostream& err);

struct SimCameraArgs {
  std::string scene = "shoe";
  std::filesystem::path data_dir;
  int port = 15740;  // 0: any free port
  std::string size = "1296x864";
  double elevation_deg = 20.0;
  std::string serial = "EMU0001";
  double turn_deg = 0.0;  // turn the simulated table this far after every capture
  int capture_delay_ms = 0;
  int busy = 0;                        // the first N captures answer Device Busy
  std::string events = "all";          // all, added-only, complete-only, none
  std::uint64_t drop_after_bytes = 0;  // drop the connection this far into each download (0: no)
  int download_delay_ms = 0;           // wait before each 256 KiB chunk of a download
  double seconds = 0.0;                // run time, 0 = until interrupted
};

int RunSimCamera(const SimCameraArgs& args, std::ostream& out, std::ostream& err);

}  // namespace carousel::app
