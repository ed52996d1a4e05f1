// rig: the devices of a capture rig (contract; issues 3, 7 and 8 build it).
//
// carousel_rig_api (this folder's headers) holds only interfaces, so that sim/ and tests need
// no libgphoto2:
//   Camera     identify, read/set settings, trigger/capture with a deadline, download to a
//              path, preview frame.
//   Turntable  home, move to an angle (radians in code, degrees in files and flags), status,
//              stop.
// carousel_rig holds the hardware backends: libgphoto2 cameras (USB and PTP/IP), the termios
// serial turntable speaking firmware-protocol, and libusb discovery with hotplug. Every
// blocking call takes a timeout; failures are carousel::DeviceError naming the device.
// rig knows nothing of sim; studio picks a backend through a factory.
#pragma once
