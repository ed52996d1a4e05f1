// The libgphoto2 backend driving real, unmodified Debian libgphoto2 against our PTP/IP camera
// emulator on 127.0.0.1, and the Debian gphoto2 client against the same emulator.
// Every test runs with a temporary HOME (libgphoto2 keeps ~/.gphoto/settings).
#include <gtest/gtest.h>
#include <sys/stat.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <future>
#include <iostream>
#include <random>
#include <sstream>
#include <thread>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/rig/gphoto_camera.h"
#include "carousel/sim/ptpip_camera.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/sim/test_scenes.h"
#include "carousel/testing/testing.h"

namespace carousel {
namespace {

using namespace std::chrono_literals;
using Clock = std::chrono::steady_clock;

// Every photo differs (a counter in the first bytes), with a chosen size.
sim::PtpIpShutter RandomShutter(std::size_t size) {
  auto counter = std::make_shared<int>(0);
  return [size, counter](const std::map<std::string, std::string>&) {
    std::mt19937 random(static_cast<unsigned>(++*counter));
    std::vector<std::uint8_t> bytes(size);
    for (std::uint8_t& b : bytes) b = static_cast<std::uint8_t>(random());
    bytes[0] = 0xFF;
    bytes[1] = 0xD8;
    return bytes;
  };
}

// "c<camera>_<round>.jpg"
std::string ShotName(int camera, int round) {
  std::ostringstream name;
  name << "c" << camera << "_" << round << ".jpg";
  return name.str();
}

class GPhotoTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // libgphoto2 reads and writes $HOME/.gphoto/settings: keep the user's untouched.
    ::setenv("HOME", home_.path().c_str(), 1);
  }

  rig::GPhotoCameraOptions Options(const sim::PtpIpCamera& emulator) {
    rig::GPhotoCameraOptions options;
    options.port = emulator.gphoto_port();
    options.busy_backoff = 20ms;
    return options;
  }

  testing::TempDir home_;
  testing::TempDir dir_;
};

TEST_F(GPhotoTest, CapturesAndDownloadsPhotosIdenticalToWhatTheCameraServed) {
  sim::PtpIpCamera emulator(RandomShutter(2'500'000), {.serial = "EMU42"});  // > 1 MiB: chunks
  rig::GPhotoCamera camera(Options(emulator));
  const rig::CameraInfo info = camera.Identify();
  EXPECT_EQ(info.serial, "EMU42");
  EXPECT_EQ(info.model, "PTP/IP Emulator");
  EXPECT_EQ(info.port, emulator.gphoto_port());
  EXPECT_NE(info.driver.find("libgphoto2"), std::string::npos);

  constexpr int kShots = 4;
  for (int i = 0; i < kShots; ++i) {
    const rig::CapturedPhoto photo = camera.Capture(10s);
    EXPECT_EQ(photo.size_bytes, 2'500'000u);
    EXPECT_EQ(photo.camera_path.rfind("/store_00010001/DCIM/100CAROU/IMG_", 0), 0u)
        << photo.camera_path;
    camera.Download(photo, dir_ / ("shot" + std::to_string(i) + ".jpg"), i % 2 == 1, 20s);
  }
  const std::vector<sim::PtpIpPhoto> served = emulator.Photos();
  ASSERT_EQ(served.size(), static_cast<std::size_t>(kShots));
  for (int i = 0; i < kShots; ++i) {
    EXPECT_EQ(ReadFileBytes(dir_ / ("shot" + std::to_string(i) + ".jpg")), served[i].bytes) << i;
    EXPECT_EQ(served[i].deleted, i % 2 == 1) << i;
  }
  // Nothing but the photos in the folder (no temporaries left behind).
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir_.path()), {}), kShots);
  // One session for all the shots: the connection was kept open.
  EXPECT_EQ(emulator.Counters().sessions, 1);

  // A photo is never downloaded over an existing file.
  const rig::CapturedPhoto again = camera.Capture(10s);
  EXPECT_THROW(camera.Download(again, dir_ / "shot0.jpg", false, 10s), IoError);
  EXPECT_EQ(ReadFileBytes(dir_ / "shot0.jpg"), served[0].bytes);
}

TEST_F(GPhotoTest, SettingsRoundTripThroughThePtpProperties) {
  sim::PtpIpCamera emulator(RandomShutter(1000));
  rig::GPhotoCamera camera(Options(emulator));
  std::map<std::string, std::string> settings = camera.Settings(10s);
  ASSERT_TRUE(settings.count(rig::kSettingIso)) << "no iso";
  ASSERT_TRUE(settings.count(rig::kSettingAperture)) << "no aperture";
  ASSERT_TRUE(settings.count(rig::kSettingShutterSpeed)) << "no shutter speed";
  ASSERT_TRUE(settings.count(rig::kSettingWhiteBalance)) << "no white balance";
  EXPECT_EQ(settings[rig::kSettingIso], "100");
  EXPECT_EQ(settings[rig::kSettingAperture], "f/8");

  camera.SetSetting(rig::kSettingIso, "400", 10s);
  camera.SetSetting(rig::kSettingAperture, "f/11", 10s);
  settings = camera.Settings(10s);
  EXPECT_EQ(settings[rig::kSettingIso], "400");
  EXPECT_EQ(settings[rig::kSettingAperture], "f/11");
  // The camera itself holds the new values (PTP ExposureIndex and FNumber).
  const auto values = emulator.PropertyValues();
  EXPECT_EQ(values.at(0x500F), 400u);
  EXPECT_EQ(values.at(0x5007), 1100u);

  // Shutter speed, white balance and image format (PTP ExposureTime, WhiteBalance and
  // CompressionSetting, libgphoto2's imagequality) the same way.
  camera.SetSetting(rig::kSettingShutterSpeed, "1/250", 10s);
  camera.SetSetting(rig::kSettingWhiteBalance, "Tungsten", 10s);
  const std::string quality = camera.Settings(10s)[rig::kSettingImageFormat];
  ASSERT_FALSE(quality.empty()) << "no image format";
  camera.SetSetting(rig::kSettingImageFormat, "Unknown value 0001", 10s);
  settings = camera.Settings(10s);
  EXPECT_EQ(settings[rig::kSettingShutterSpeed], "0.0040s");  // as libgphoto2 presents it
  EXPECT_EQ(settings[rig::kSettingWhiteBalance], "Tungsten");
  EXPECT_EQ(settings[rig::kSettingImageFormat], "Unknown value 0001");
  EXPECT_EQ(emulator.PropertyValues().at(0x500D), 40u);  // 1/250 s in 0.1 ms
  EXPECT_EQ(emulator.PropertyValues().at(0x5005), 6u);   // PTP white balance: tungsten
  EXPECT_EQ(emulator.PropertyValues().at(0x5004), 1u);
  // A generic PTP camera has no capture target (card/RAM is a Canon and Nikon setting):
  // asking for one is a clear refusal naming the camera and the setting.
  try {
    camera.SetSetting(rig::kSettingCaptureTarget, "card", 10s);
    FAIL() << "capture target on a generic camera";
  } catch (const InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("capturetarget"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(emulator.gphoto_port()), std::string::npos) << e.what();
  }

  // Values the camera does not offer, and unknown settings, are refused before the camera sees
  // them; the old values stay.
  EXPECT_THROW(camera.SetSetting(rig::kSettingIso, "333", 10s), InvalidArgument);
  EXPECT_THROW(camera.SetSetting("flux", "1", 10s), InvalidArgument);
  EXPECT_EQ(camera.Settings(10s)[rig::kSettingIso], "400");

  // The whole libgphoto2 configuration tree, with choices.
  std::map<std::string, std::vector<std::string>> choices;
  const auto config = camera.Configuration(10s, &choices);
  const auto iso = std::find_if(config.begin(), config.end(),
                                [](const auto& kv) { return kv.first.ends_with("/iso"); });
  ASSERT_NE(iso, config.end());
  EXPECT_EQ(iso->second, "400");
  EXPECT_EQ(choices[iso->first].size(), 7u);
}

TEST_F(GPhotoTest, PhotosAreRenderedBySimulatedRigAtTheTablesAngle) {
  auto scene = std::make_shared<sim::Scene>(sim::MakeSphereScene(0.08, {0, 0, 0.08}, 3));
  auto table = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
  sim::SimRigOptions rig;
  rig.width = 320;
  rig.height = 240;
  auto sim_camera =
      std::make_shared<sim::SimCamera>(scene, sim::MakeSimRig(rig, scene->Bounds()).front(), table);
  sim::PtpIpCamera emulator(sim_camera, {.serial = "EMUSIM"});
  rig::GPhotoCamera camera(Options(emulator));

  const rig::CapturedPhoto bright = camera.Capture(10s);
  camera.Download(bright, dir_ / "bright.jpg", false, 10s);
  camera.SetSetting(rig::kSettingAperture, "f/22", 10s);  // three stops darker
  table->StartMoveTo(1.0);
  table->WaitUntilStopped(5s);
  const rig::CapturedPhoto dark = camera.Capture(10s);
  camera.Download(dark, dir_ / "dark.jpg", false, 10s);
  const cv::Mat a = ReadImage(dir_ / "dark.jpg");
  const cv::Mat b = ReadImage(dir_ / "bright.jpg");
  ASSERT_EQ(a.cols, 320);
  ASSERT_EQ(b.rows, 240);
  // The object fills the middle of the frame; the aperture reached the renderer.
  const cv::Rect middle(140, 100, 40, 40);
  const double dark_level = cv::mean(a(middle))[1];
  const double bright_level = cv::mean(b(middle))[1];
  EXPECT_LT(dark_level, bright_level * 0.5) << dark_level << " vs " << bright_level;
  EXPECT_GT(dark_level, 2.0);  // and the photo is not empty

  // Live view through libgphoto2's PTP 1.1 stream path: the simulated camera's preview.
  const cv::Mat frame = camera.PreviewFrame(5s);
  EXPECT_EQ(frame.cols, 640);
  EXPECT_EQ(frame.rows, 480);
  EXPECT_EQ(emulator.Counters().preview_frames, 1);
  EXPECT_EQ(emulator.PropertyValues().at(0x5021), 1u);  // libgphoto2 enabled the stream
}

TEST_F(GPhotoTest, BusyCameraIsRetriedWithBackoffAndGivesUpClearly) {
  sim::PtpIpCamera emulator(RandomShutter(5000));
  rig::GPhotoCamera camera(Options(emulator));
  emulator.SetBusy(3);
  const rig::CapturedPhoto photo = camera.Capture(10s);
  EXPECT_EQ(emulator.Counters().busy_answers, 3);
  EXPECT_EQ(camera.Counters().busy_retries, 3);
  camera.Download(photo, dir_ / "a.jpg", false, 10s);
  EXPECT_EQ(ReadFileBytes(dir_ / "a.jpg"), emulator.Photos().back().bytes);

  emulator.SetBusy(1000);
  const auto start = Clock::now();
  try {
    camera.Capture(3s);
    FAIL() << "a camera that stays busy must fail";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("busy"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(emulator.gphoto_port()), std::string::npos) << e.what();
  }
  EXPECT_LT(Clock::now() - start, 3.5s);
  EXPECT_EQ(emulator.Counters().busy_answers, 3 + 7);  // the first try and 6 retries
  emulator.SetBusy(0);
  EXPECT_NO_THROW(camera.Capture(10s));
}

TEST_F(GPhotoTest, MissingEventsEndInADeviceErrorWithinTheDeadline) {
  for (const sim::PtpIpEvents events : {sim::PtpIpEvents::kNone, sim::PtpIpEvents::kCompleteOnly}) {
    sim::PtpIpCamera emulator(RandomShutter(5000));
    rig::GPhotoCamera camera(Options(emulator));
    emulator.SetEvents(events);
    const auto start = Clock::now();
    EXPECT_THROW(camera.Capture(1500ms), DeviceError);
    EXPECT_LT(Clock::now() - start, 2s);
    // The camera is usable again once it behaves.
    emulator.SetEvents(sim::PtpIpEvents::kAll);
    const rig::CapturedPhoto photo = camera.Capture(10s);
    camera.Download(photo, dir_ / ("ok" + std::to_string(static_cast<int>(events)) + ".jpg"), false,
                    10s);
  }
  // ObjectAdded without CaptureComplete is enough for us (not for libgphoto2's own capture).
  sim::PtpIpCamera emulator(RandomShutter(5000));
  rig::GPhotoCamera camera(Options(emulator));
  emulator.SetEvents(sim::PtpIpEvents::kAddedOnly);
  EXPECT_NO_THROW(camera.Capture(5s));
}

TEST_F(GPhotoTest, SlowCaptureIsWaitedForWithinItsDeadline) {
  sim::PtpIpCamera emulator(RandomShutter(5000));
  rig::GPhotoCamera camera(Options(emulator));
  emulator.SetCaptureDelay(800ms);
  const auto start = Clock::now();
  const rig::CapturedPhoto photo = camera.Capture(5s);
  EXPECT_GE(Clock::now() - start, 750ms);
  EXPECT_FALSE(photo.camera_path.empty());
  emulator.SetCaptureDelay(3s);
  const auto start2 = Clock::now();
  EXPECT_THROW(camera.Capture(1s), DeviceError);
  EXPECT_LT(Clock::now() - start2, 1.6s);
}

TEST_F(GPhotoTest, DroppedConnectionMidDownloadIsRetriedAfterAReconnect) {
  sim::PtpIpCamera emulator(RandomShutter(3'000'000));
  rig::GPhotoCamera camera(Options(emulator));
  const rig::CapturedPhoto photo = camera.Capture(10s);
  emulator.DropDuringDownloads(1'500'000);
  camera.Download(photo, dir_ / "a.jpg", true, 30s);
  EXPECT_EQ(emulator.Counters().drops, 1);
  EXPECT_EQ(camera.Counters().reconnects, 1);
  EXPECT_EQ(camera.Counters().download_retries, 1);
  EXPECT_EQ(ReadFileBytes(dir_ / "a.jpg"), emulator.Photos().back().bytes);
  EXPECT_TRUE(emulator.Photos().back().deleted);
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir_.path()), {}), 1);
  // The next capture goes through the new session.
  EXPECT_NO_THROW(camera.Capture(10s));
}

TEST_F(GPhotoTest, SlowDownloadPastItsDeadlineLeavesNoPhotoEvenWhenItFinishesLater) {
  sim::PtpIpCamera emulator(RandomShutter(2'000'000));  // 8 chunks of 256 KiB
  rig::GPhotoCamera camera(Options(emulator));
  const rig::CapturedPhoto photo = camera.Capture(10s);
  emulator.SetDownloadDelay(150ms);  // about 1.2 s for the photo
  const auto start = Clock::now();
  EXPECT_THROW(camera.Download(photo, dir_ / "late.jpg", false, 400ms), DeviceError);
  EXPECT_LT(Clock::now() - start, 1s);
  // The transfer goes on in the background and completes; its photo must not appear under the
  // name whose download was reported failed, nor linger as a temporary file.
  std::this_thread::sleep_for(2s);
  EXPECT_FALSE(std::filesystem::exists(dir_ / "late.jpg"));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir_.path()), {}), 0);
  // The photo is still on the camera: a retry with time enough gets it.
  emulator.SetDownloadDelay(0ms);
  camera.Download(photo, dir_ / "late.jpg", false, 10s);
  EXPECT_EQ(ReadFileBytes(dir_ / "late.jpg"), emulator.Photos().back().bytes);
}

TEST_F(GPhotoTest, CameraThatDropsOffAndReappearsIsReconnected) {
  auto emulator = std::make_unique<sim::PtpIpCamera>(RandomShutter(100'000),
                                                     sim::PtpIpCameraOptions{.serial = "EMU7"});
  const std::uint16_t port = emulator->port();
  rig::GPhotoCamera camera(Options(*emulator));
  camera.Download(camera.Capture(10s), dir_ / "before.jpg", true, 10s);
  // Switched off (the process listening on the port is gone) ...
  emulator.reset();
  EXPECT_THROW(camera.Capture(2s), DeviceError);
  // ... and on again at the same address: the same Camera object carries on.
  emulator = std::make_unique<sim::PtpIpCamera>(
      RandomShutter(100'000), sim::PtpIpCameraOptions{.serial = "EMU7", .port = port});
  const rig::CapturedPhoto photo = camera.Capture(10s);
  camera.Download(photo, dir_ / "after.jpg", true, 10s);
  EXPECT_EQ(ReadFileBytes(dir_ / "after.jpg"), emulator->Photos().back().bytes);
  EXPECT_GE(camera.Counters().reconnects, 1);
  EXPECT_EQ(camera.Identify().serial, "EMU7");
}

TEST_F(GPhotoTest, CameraGoneForGoodIsADeviceErrorAndNoHalfPhotoIsLeft) {
  auto emulator = std::make_unique<sim::PtpIpCamera>(RandomShutter(3'000'000));
  rig::GPhotoCameraOptions options = Options(*emulator);
  rig::GPhotoCamera camera(options);
  const rig::CapturedPhoto photo = camera.Capture(10s);
  // Drops during every attempt: the camera keeps failing mid-download.
  emulator->DropDuringDownloads(1'000'000, 100);
  const auto start = Clock::now();
  EXPECT_THROW(camera.Download(photo, dir_ / "a.jpg", false, 6s), DeviceError);
  EXPECT_LT(Clock::now() - start, 7s);
  EXPECT_EQ(emulator->Counters().drops, 3);  // the download attempts
  EXPECT_FALSE(std::filesystem::exists(dir_ / "a.jpg"));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir_.path()), {}), 0);

  // Unplugged: nothing listens any more.
  emulator.reset();
  const auto start2 = Clock::now();
  try {
    camera.Capture(3s);
    FAIL() << "capture from a camera that is gone";
  } catch (const DeviceError& e) {
    EXPECT_NE(std::string(e.what()).find("ptpip:127.0.0.1"), std::string::npos) << e.what();
  }
  EXPECT_LT(Clock::now() - start2, 4s);
  // Opening a camera that is not there fails in time too.
  options.connect_timeout = 2s;
  EXPECT_THROW(rig::GPhotoCamera{options}, DeviceError);
}

TEST_F(GPhotoTest, ThreeCamerasCaptureInParallelWithSmallTriggerSkew) {
  std::vector<std::unique_ptr<sim::PtpIpCamera>> emulators;
  std::vector<std::unique_ptr<rig::GPhotoCamera>> cameras;
  for (int i = 0; i < 3; ++i) {
    emulators.push_back(std::make_unique<sim::PtpIpCamera>(
        RandomShutter(1'500'000), sim::PtpIpCameraOptions{.serial = "EMU" + std::to_string(i)}));
    cameras.push_back(std::make_unique<rig::GPhotoCamera>(Options(*emulators.back())));
  }
  constexpr int kRounds = 5;
  double worst_skew_ms = 0;
  for (int round = 0; round < kRounds; ++round) {
    std::vector<std::future<void>> shots;
    shots.reserve(3);
    for (int i = 0; i < 3; ++i) {
      shots.push_back(std::async(std::launch::async, [&, i] {
        const rig::CapturedPhoto p = cameras[i]->Capture(10s);
        cameras[i]->Download(p, dir_ / ShotName(i, round), true, 20s);
      }));
    }
    for (auto& s : shots) s.get();
    std::vector<Clock::time_point> arrivals;
    arrivals.reserve(emulators.size());
    for (const auto& e : emulators) arrivals.push_back(e->Photos().back().triggered_at);
    const auto [lo, hi] = std::minmax_element(arrivals.begin(), arrivals.end());
    worst_skew_ms =
        std::max(worst_skew_ms, std::chrono::duration<double, std::milli>(*hi - *lo).count());
  }
  for (int i = 0; i < 3; ++i) {
    const auto photos = emulators[i]->Photos();
    ASSERT_EQ(photos.size(), static_cast<std::size_t>(kRounds));
    for (int round = 0; round < kRounds; ++round) {
      EXPECT_EQ(ReadFileBytes(dir_ / ShotName(i, round)), photos[round].bytes);
    }
  }
  RecordProperty("worst_trigger_skew_ms", std::to_string(worst_skew_ms));
  std::cout << "worst trigger skew over " << kRounds << " rounds: " << worst_skew_ms << " ms\n";
  EXPECT_LT(worst_skew_ms, 250.0);
}

TEST_F(GPhotoTest, DescriptorZeroStaysGuardedAcrossCameraExits) {
  // libgphoto2 2.5.30 closes descriptor 0 when a PTP/IP camera exits. In a process without
  // stdin, descriptor 0 would be the next socket opened: here, the second camera's listener.
  sim::PtpIpCamera first_emulator(RandomShutter(5000));
  ::close(0);
  rig::GPhotoCamera first(Options(first_emulator));  // occupies descriptor 0 with /dev/null
  sim::PtpIpCamera second_emulator(RandomShutter(5000), {.serial = "EMU2"});
  rig::GPhotoCamera second(Options(second_emulator));
  first.Reconnect(10s);  // exits the first session: closes descriptor 0
  first.Reconnect(10s);
  const rig::CapturedPhoto photo = second.Capture(5s);
  second.Download(photo, dir_ / "second.jpg", false, 5s);
  EXPECT_EQ(ReadFileBytes(dir_ / "second.jpg"), second_emulator.Photos().back().bytes);
  EXPECT_EQ(second_emulator.Counters().connections, 1);  // its session was never cut
  EXPECT_EQ(first.Counters().reconnects, 2);
  // Descriptor 0 stays a harmless /dev/null: never free, never a camera's socket.
  struct stat st {};
  ASSERT_EQ(::fstat(0, &st), 0);
  EXPECT_TRUE(S_ISCHR(st.st_mode));
}

// ---- the Debian gphoto2 client, a program we did not write ----

std::string ReadTextFile(const std::filesystem::path& path) {
  const std::vector<std::uint8_t> bytes = ReadFileBytes(path);
  return {bytes.begin(), bytes.end()};
}

int RunCommand(const std::string& command) {
  const int status = std::system(command.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

TEST_F(GPhotoTest, DebianGphoto2ClientCapturesAndDownloadsFromTheEmulator) {
  sim::PtpIpCamera emulator(RandomShutter(1'800'000), {.serial = "EMUCLI"});
  const std::filesystem::path out = dir_ / "cli.jpg";
  const std::string base =
      "timeout -k 5 60 gphoto2 --port " + emulator.gphoto_port() + " --camera 'PTP/IP Camera' ";
  ASSERT_EQ(RunCommand(base + "--capture-image-and-download --filename '" + out.string() + "' > '" +
                       (dir_ / "log.txt").string() + "' 2>&1"),
            0);
  ASSERT_TRUE(std::filesystem::exists(out)) << ReadTextFile(dir_ / "log.txt");
  ASSERT_EQ(emulator.Photos().size(), 1u);
  EXPECT_EQ(ReadFileBytes(out), emulator.Photos()[0].bytes);

  // --set-config reaches the camera.
  ASSERT_EQ(RunCommand(base + "--set-config iso=800 > /dev/null 2>&1"), 0);
  EXPECT_EQ(emulator.PropertyValues().at(0x500F), 800u);
  // --summary names our camera.
  const std::filesystem::path summary = dir_ / "summary.txt";
  ASSERT_EQ(RunCommand(base + "--summary > '" + summary.string() + "' 2>&1"), 0);
  EXPECT_NE(ReadTextFile(summary).find("EMUCLI"), std::string::npos) << ReadTextFile(summary);
}

}  // namespace
}  // namespace carousel
