// USB discovery: the classification of devices by their descriptors, the arrive/leave diff, and
// graceful degradation where the machine has no USB (this CI sandbox has no /dev/bus/usb).
#include <gtest/gtest.h>

#include <chrono>
#include <string>

#include "carousel/core/error.h"
#include "carousel/rig/usb_devices.h"

namespace carousel::rig {
namespace {

using namespace std::chrono_literals;

constexpr UsbInterfaceClass kPtp{6, 1, 1};
constexpr UsbInterfaceClass kMassStorage{8, 6, 80};
constexpr UsbInterfaceClass kHid{3, 1, 1};
constexpr UsbInterfaceClass kCdcAcm{2, 2, 1};
constexpr UsbInterfaceClass kVendorSpecific{0xFF, 0xFF, 0xFF};

TEST(UsbDevicesTest, PtpInterfacesAreCamerasNamedByTheirMaker) {
  UsbDevice d;
  ASSERT_TRUE(ClassifyUsbDevice(0x04a9, 0x327f, {kPtp}, &d));
  EXPECT_EQ(d.kind, UsbDeviceKind::kCamera);
  EXPECT_EQ(d.vendor, "Canon");
  EXPECT_EQ(d.ids(), "04a9:327f");
  ASSERT_TRUE(ClassifyUsbDevice(0x04b0, 0x0437, {kMassStorage, kPtp}, &d));
  EXPECT_EQ(d.vendor, "Nikon");
  // A PTP device of a maker we do not know is still a camera.
  ASSERT_TRUE(ClassifyUsbDevice(0x1234, 0x0001, {kPtp}, &d));
  EXPECT_EQ(d.kind, UsbDeviceKind::kCamera);
  EXPECT_EQ(d.vendor, "1234");
  // A camera in mass-storage mode cannot be driven; a keyboard is not ours.
  EXPECT_FALSE(ClassifyUsbDevice(0x04a9, 0x3270, {kMassStorage}, &d));
  EXPECT_FALSE(ClassifyUsbDevice(0x046d, 0xc31c, {kHid}, &d));
}

TEST(UsbDevicesTest, SerialAdaptersAndBoardsAreRecognised) {
  UsbDevice d;
  ASSERT_TRUE(ClassifyUsbDevice(0x0403, 0x6001, {kVendorSpecific}, &d));
  EXPECT_EQ(d.kind, UsbDeviceKind::kSerialAdapter);
  EXPECT_EQ(d.vendor, "FTDI");
  ASSERT_TRUE(ClassifyUsbDevice(0x1a86, 0x7523, {kVendorSpecific}, &d));
  EXPECT_EQ(d.description, "CH340 USB-serial");
  ASSERT_TRUE(ClassifyUsbDevice(0x10c4, 0xea60, {kVendorSpecific}, &d));
  EXPECT_EQ(d.vendor, "Silicon Labs");
  ASSERT_TRUE(ClassifyUsbDevice(0x2341, 0x0043, {kCdcAcm}, &d));
  EXPECT_EQ(d.description, "Arduino Uno");
  ASSERT_TRUE(ClassifyUsbDevice(0x2341, 0x0999, {kCdcAcm}, &d));  // any Arduino product
  EXPECT_EQ(d.description, "Arduino board");
  // An unknown board with a native CDC ACM port.
  ASSERT_TRUE(ClassifyUsbDevice(0xcafe, 0x4001, {kCdcAcm}, &d));
  EXPECT_EQ(d.kind, UsbDeviceKind::kSerialAdapter);
  // FTDI's vendor id alone does not make an unknown product a serial adapter.
  EXPECT_FALSE(ClassifyUsbDevice(0x0403, 0x1234, {kVendorSpecific}, &d));
}

TEST(UsbDevicesTest, PortNamesAndDiffs) {
  UsbDevice camera;
  ClassifyUsbDevice(0x04a9, 0x327f, {kPtp}, &camera);
  camera.bus = 1;
  camera.address = 5;
  EXPECT_EQ(camera.gphoto_port(), "usb:001,005");
  UsbDevice adapter;
  ClassifyUsbDevice(0x1a86, 0x7523, {kVendorSpecific}, &adapter);
  adapter.bus = 2;
  adapter.address = 3;
  UsbDevice replugged = camera;
  replugged.address = 9;  // the same camera on another address after re-plugging

  const UsbChanges changes = DiffUsbDevices({camera, adapter}, {adapter, replugged});
  ASSERT_EQ(changes.arrived.size(), 1u);
  EXPECT_EQ(changes.arrived[0].address, 9);
  ASSERT_EQ(changes.left.size(), 1u);
  EXPECT_EQ(changes.left[0].address, 5);
  EXPECT_TRUE(DiffUsbDevices({camera}, {camera}).arrived.empty());
}

TEST(UsbDevicesTest, MachinesWithoutUsbDegradeGracefully) {
  bool listed = false;
  try {
    for (const UsbDevice& d : ListUsbDevices()) {
      EXPECT_GT(d.bus, 0);
      EXPECT_FALSE(d.description.empty());
    }
    listed = true;
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("libusb cannot reach the USB bus"), std::string::npos)
        << e.what();
  }
  int events = 0;
  {
    UsbMonitor monitor([&](const UsbDevice&, bool) { ++events; }, 50ms);
    if (listed) {
      EXPECT_NE(monitor.mode(), UsbMonitorMode::kUnavailable);
    } else {
      EXPECT_EQ(monitor.mode(), UsbMonitorMode::kUnavailable);
      EXPECT_NE(monitor.reason().find("libusb"), std::string::npos);
      EXPECT_TRUE(monitor.initial().empty());
    }
  }  // stops promptly
  if (!listed) {
    EXPECT_EQ(events, 0);
  }
}

}  // namespace
}  // namespace carousel::rig
