// The one-button session on the hardware backends, with every device path real except the
// hardware itself: the turntable firmware runs in simavr behind a PTY (rig::SerialTurntable),
// and each camera is a PTP/IP camera emulator driven through real libgphoto2
// (rig::GPhotoCamera). The emulators photograph the simulated studio at the angle the
// simulated motor has actually turned to.
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <iostream>
#include <map>
#include <memory>
#include <numbers>
#include <thread>

#include "carousel/calib/rig_calibration.h"
#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/progress.h"
#include "carousel/sim/avr_turntable.h"
#include "carousel/sim/ptpip_camera.h"
#include "carousel/sim/scene.h"
#include "carousel/sim/sim_rig.h"
#include "carousel/studio/defaults.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/run_session.h"
#include "carousel/studio/session.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

using ::testing::HasSubstr;
using namespace std::chrono_literals;

constexpr int kStepsPerRev = 9600;  // the firmware's default gear

class HardwareRunTest : public ::testing::Test {
 protected:
  void SetUp() override {
    ::setenv("HOME", home_.path().c_str(), 1);  // libgphoto2's ~/.gphoto/settings
    sim::AvrTurntableOptions o;
    o.firmware = DefaultFirmwarePath();
    o.time_scale = 20.0;
    o.link = dir_.path() / "ttyTT";
    controller_ = std::make_unique<sim::AvrTurntable>(o);

    scene_ = std::make_shared<sim::Scene>(
        sim::LoadScene(ResolveScene("shoe", testing::SharedDataDir())));
    sim::PlaceOnTurntable(*scene_, {});
    sim::SimRigOptions rig;
    rig.width = 360;
    rig.height = 240;
    rig.elevations_deg = {15.0, 45.0};
    models_ = sim::MakeSimRig(rig, scene_->Bounds());
    table_ = std::make_shared<sim::SimTurntable>(sim::SimTurntableOptions{.time_scale = 0.0});
    for (std::size_t c = 0; c < models_.size(); ++c) {
      auto camera = std::make_shared<sim::SimCamera>(scene_, models_[c], table_);
      sim::PtpIpCameraOptions options;
      options.serial = "EMU" + std::to_string(c);
      emulators_.push_back(std::make_unique<sim::PtpIpCamera>(
          [this, camera](const std::map<std::string, std::string>& settings) {
            // The angle the motor has turned to since the first photo (stop 0 = home).
            const std::int64_t position = controller_->table_position();
            if (!home_position_) home_position_ = position;
            const double angle = 2.0 * std::numbers::pi *
                                 static_cast<double>(position - *home_position_) / kStepsPerRev;
            table_->StartMoveTo(angle);
            table_->WaitUntilStopped(1s);
            // The studio's backlight, as the controller's light output has it now.
            table_->SetBacklight(controller_->backlight_on());
            for (const auto& [name, value] : settings) camera->SetSetting(name, value, 0ms);
            return camera->Shoot();
          },
          options));
    }
  }

  RigConfig Config() const {
    RigConfig config;
    config.turntable.port = controller_->port();
    for (std::size_t c = 0; c < emulators_.size(); ++c) {
      RigCameraConfig camera;
      camera.port = emulators_[c]->gphoto_port();
      camera.serial = "EMU" + std::to_string(c);
      camera.settings = {{"iso", "200"}};
      camera.calibration = models_[c];
      config.cameras.push_back(camera);
    }
    config.capture.stops = 16;
    config.capture.settle_ms = 20;
    return config;
  }

  testing::TempDir home_;
  testing::TempDir dir_;
  std::unique_ptr<sim::AvrTurntable> controller_;
  std::shared_ptr<sim::Scene> scene_;
  std::vector<CameraModel> models_;
  std::shared_ptr<sim::SimTurntable> table_;
  std::vector<std::unique_ptr<sim::PtpIpCamera>> emulators_;
  std::optional<std::int64_t> home_position_;
};

TEST_F(HardwareRunTest, SixteenStopsThroughTheFirmwareAndLibgphoto2IntoASession) {
  // The rig file round-trips.
  WriteRigConfig(dir_ / "rig.json", Config());
  RunOptions options;
  options.hardware = ReadRigConfig(dir_ / "rig.json");
  options.product = "hw-demo";
  options.out = dir_.path() / "sessions";
  options.texture.grouping.exclude_views = {3};
  Progress progress;
  const RunResult result = RunSession(options, progress);

  EXPECT_EQ(result.photos_taken, 32);
  const Session session = ReadSession(result.session);
  ASSERT_EQ(session.views.size(), 32u);
  // Every photo is the one its camera served, at the planned name, with its checksum.
  for (std::size_t c = 0; c < emulators_.size(); ++c) {
    const std::vector<sim::PtpIpPhoto> served = emulators_[c]->Photos();
    ASSERT_EQ(served.size(), 16u) << c;
    for (int stop = 0; stop < 16; ++stop) {
      const auto file = result.session / "images" / (ViewStem(static_cast<int>(c), stop) + ".jpg");
      EXPECT_EQ(ReadFileBytes(file), served[stop].bytes) << file;
      EXPECT_TRUE(served[stop].deleted) << "left on the camera: " << file;
    }
    // The camera settings of the rig file reached the cameras.
    EXPECT_EQ(emulators_[c]->PropertyValues().at(0x500F), 200u);
  }
  for (const SessionView& v : session.views) {
    EXPECT_EQ(v.sha256, FileSha256(result.session / v.image));
    EXPECT_NEAR(v.table_angle_deg, 22.5 * v.stop, 1e-9);
  }
  // The motor turned through every stop and came back to rest at the last one.
  EXPECT_EQ(controller_->table_position() - *home_position_, 15 * kStepsPerRev / 16);
  // And the pipeline ran to a textured model.
  EXPECT_TRUE(std::filesystem::exists(result.session / "model" / "model.glb"));
  EXPECT_TRUE(std::filesystem::exists(result.session / "model" / "model.obj"));
  ASSERT_EQ(result.texture.held_out.size(), 1u);
  std::cout << "held-out view 3: PSNR " << result.texture.held_out[0].psnr_db << " dB\n";
  EXPECT_GT(result.texture.held_out[0].psnr_db, 17.0);
}

// Backlit mask shots on hardware: at every stop the controller's light output goes on (LIGHT,
// protocol 1.1), both cameras fire again through libgphoto2, and it goes off; the emulators
// photograph the studio as that output lights it. The silhouettes come from those shots.
TEST_F(HardwareRunTest, BacklitMaskShotsThroughTheControllersLightOutput) {
  RigConfig config = Config();
  config.capture.stops = 8;
  config.capture.mask_shots = "backlit";
  config.capture.backlight_settle_ms = 20;
  WriteRigConfig(dir_ / "rig.json", config);
  RunOptions options;
  options.hardware = ReadRigConfig(dir_ / "rig.json");
  EXPECT_EQ(options.hardware->capture.mask_shots, "backlit");
  options.product = "hw-backlit";
  options.out = dir_.path() / "sessions";
  options.publish_model = false;
  Progress progress;
  const RunResult result = RunSession(options, progress);
  EXPECT_EQ(result.photos_taken, 32);
  const Session session = ReadSession(result.session);
  ASSERT_EQ(session.views.size(), 16u);
  for (std::size_t c = 0; c < emulators_.size(); ++c) {
    const std::vector<sim::PtpIpPhoto> served = emulators_[c]->Photos();
    ASSERT_EQ(served.size(), 16u) << c;
    for (int stop = 0; stop < 8; ++stop) {
      const std::string stem = ViewStem(static_cast<int>(c), stop);
      const auto photo = result.session / "images" / (stem + ".jpg");
      const auto shot = result.session / "images" / (stem + "_backlit.jpg");
      EXPECT_EQ(ReadFileBytes(photo), served[2 * stop].bytes) << photo;
      EXPECT_EQ(ReadFileBytes(shot), served[2 * stop + 1].bytes) << shot;
      // The mask shot shows the product dark against the lit panel: where it is dark, the
      // front-lit photo is much lighter.
      const cv::Mat lit = ReadImage(photo), backlit = ReadImage(shot);
      cv::Mat grey;
      cv::cvtColor(backlit, grey, cv::COLOR_BGR2GRAY);
      const cv::Mat dark = grey < 100;
      EXPECT_GT(cv::countNonZero(dark), 500) << shot;
      EXPECT_GT(cv::mean(lit, dark)[1], cv::mean(backlit, dark)[1] + 30.0) << shot;
      EXPECT_GT(cv::mean(grey, ~dark)[0], 200.0) << shot;  // the panel and the plate glow
    }
  }
  for (const SessionView& v : session.views)
    EXPECT_EQ(v.mask_shot_sha256, FileSha256(result.session / v.mask_shot));
  // One on-time of the light per stop, each over by the next stop's move, none left on.
  int on_times = 0;
  for (const sim::OutputPulse& p : controller_->output_pulses()) {
    if (p.output != sim::kBacklightOutput) continue;
    ++on_times;
    EXPECT_NE(p.end_cycle, 0u);
  }
  EXPECT_EQ(on_times, 8);
  EXPECT_FALSE(controller_->backlight_on());
  ReconstructOptions reconstruct;
  EXPECT_EQ(ReconstructSession(result.session, reconstruct, progress).method, "backlit");
}

TEST_F(HardwareRunTest, ControllerShutterOutputsReleaseTheCameras) {
  // The wiring: the controller's shutter output i goes to camera i's remote socket.
  std::atomic<bool> stop{false};
  std::thread wiring([&] {
    std::size_t seen = 0;
    while (!stop) {
      const std::vector<sim::OutputPulse> pulses = controller_->output_pulses();
      for (; seen < pulses.size(); ++seen) {
        const int output = pulses[seen].output;
        if (output < static_cast<int>(emulators_.size())) emulators_[output]->ReleaseShutter();
      }
      std::this_thread::sleep_for(2ms);
    }
  });
  RigConfig config = Config();
  config.capture.stops = 8;
  config.capture.shutter = "controller";
  config.capture.shutter_pulse_ms = 60;
  RunOptions options;
  options.hardware = config;
  options.product = "controller-shutter";
  options.out = dir_.path() / "sessions";
  Progress progress;
  RunResult result;
  EXPECT_NO_THROW(result = RunSession(options, progress));
  stop = true;
  wiring.join();
  EXPECT_EQ(result.photos_taken, 16);
  for (std::size_t c = 0; c < emulators_.size(); ++c) {
    const sim::PtpIpCounters counters = emulators_[c]->Counters();
    EXPECT_EQ(counters.external_releases, 8) << c;
    EXPECT_EQ(counters.captures, 0) << c;  // libgphoto2 never triggered them
    const std::vector<sim::PtpIpPhoto> served = emulators_[c]->Photos();
    ASSERT_EQ(served.size(), 8u);
    for (int stop_index = 0; stop_index < 8; ++stop_index) {
      const auto file =
          result.session / "images" / (ViewStem(static_cast<int>(c), stop_index) + ".jpg");
      EXPECT_EQ(ReadFileBytes(file), served[stop_index].bytes) << file;
    }
  }
  // Both shutters were pulsed together, 8 times, for 60 ms (16 MHz cycles).
  const std::vector<sim::OutputPulse> pulses = controller_->output_pulses();
  ASSERT_EQ(pulses.size(), 16u);
  for (std::size_t i = 0; i + 1 < pulses.size(); i += 2) {
    EXPECT_NEAR(static_cast<double>(pulses[i].start_cycle),
                static_cast<double>(pulses[i + 1].start_cycle), 160.0);  // within 10 us
    EXPECT_NEAR(static_cast<double>(pulses[i].end_cycle - pulses[i].start_cycle) / 16e6, 0.060,
                0.002);
  }
}

TEST_F(HardwareRunTest, CameraMissingAtStartIsAClearErrorAndWritesNothing) {
  RigConfig config = Config();
  config.cameras[1].port = "ptpip:127.0.0.1:1:1";  // nothing listens there
  RunOptions options;
  options.hardware = config;
  options.product = "missing-camera";
  options.out = dir_.path() / "sessions";
  Progress progress;
  try {
    RunSession(options, progress);
    FAIL() << "a session without its camera";
  } catch (const DeviceError& e) {
    EXPECT_THAT(e.what(), HasSubstr("ptpip:127.0.0.1:1:1"));
  }
  EXPECT_FALSE(std::filesystem::exists(dir_.path() / "sessions" / "missing-camera"));

  // A camera with another serial than the rig expects (swapped cables).
  config = Config();
  config.cameras[0].serial = "EMU1";
  options.hardware = config;
  try {
    RunSession(options, progress);
    FAIL() << "a swapped camera";
  } catch (const DeviceError& e) {
    EXPECT_THAT(e.what(), HasSubstr("the rig expects EMU1"));
  }
}

TEST(RigConfigTest, MalformedRigFilesNameTheFieldAndTheFile) {
  testing::TempDir dir;
  const auto file = dir / "rig.json";
  WriteFileAtomic(file, std::string("{\"format\": \"carousel-rig\", \"version\": 1}"));
  EXPECT_THAT([&] { ReadRigConfig(file); },
              ::testing::ThrowsMessage<FormatError>(HasSubstr("turntable has no field 'port'")));
  WriteFileAtomic(file, std::string("{\"format\": \"carousel-rig\", \"version\": 1, "
                                    "\"turntable\": {\"port\": \"/dev/ttyACM0\"}, "
                                    "\"cameras\": [{\"port\": \"usb:001,002\"}]}"));
  EXPECT_THAT([&] { ReadRigConfig(file); },
              ::testing::ThrowsMessage<FormatError>(HasSubstr("cameras[0] has no calibration")));
  // The backdrop chooses the silhouette method; differencing needs the plates.
  const std::string rig =
      "{\"format\": \"carousel-rig\", \"version\": 1, \"turntable\": {\"port\": \"/dev/ttyACM0\"}, "
      "\"cameras\": [{\"port\": \"usb:001,002\", \"calibration\": " +
      CameraModelToJson(sim::MakeSimRig({}, Eigen::AlignedBox3d(Eigen::Vector3d(-0.1, -0.1, 0),
                                                                Eigen::Vector3d(0.1, 0.1, 0.2)))
                            .front())
          .dump() +
      "}]";
  WriteFileAtomic(file, rig + ", \"backdrop\": \"chroma\"}");
  EXPECT_THAT([&] { ReadRigConfig(file); },
              ::testing::ThrowsMessage<FormatError>(HasSubstr("backdrop must be")));
  WriteFileAtomic(file, rig + ", \"backdrop\": \"difference\"}");
  EXPECT_THAT([&] { ReadRigConfig(file); },
              ::testing::ThrowsMessage<FormatError>(HasSubstr("needs \"backgrounds\"")));
  WriteFileAtomic(file, rig + ", \"backdrop\": \"difference\", \"backgrounds\": \"plates\"}");
  const RigConfig config = ReadRigConfig(file);
  EXPECT_EQ(config.backdrop, "difference");
  EXPECT_EQ(config.backgrounds, dir / "plates");  // relative to the rig file
  EXPECT_EQ(ReadRigConfig(file).cameras.size(), 1u);
  // The cameras' calibration from a rig calibration file, camera i being its camera i.
  calib::RigCalibration calibration;
  calibration.created_utc = "2026-12-01T00:00:00Z";
  calibration.board = "charuco:9x7:0.04:0.03:DICT_6X6_250";
  calib::RigCameraCalibration calibrated;
  calibrated.name = "cam0";
  calibrated.serial = "032021001234";
  calibrated.camera = config.cameras[0].calibration;
  calibrated.camera.fx *= 1.01;
  calibration.cameras.push_back(calibrated);
  calib::WriteRigCalibration(dir / "calibration.json", calibration);
  const std::string with_file =
      "{\"format\": \"carousel-rig\", \"version\": 1, \"turntable\": {\"port\": \"/dev/ttyACM0\"}, "
      "\"calibration_file\": \"calibration.json\", \"cameras\": [{\"port\": \"usb:001,002\"";
  WriteFileAtomic(file, with_file + "}]}");
  EXPECT_DOUBLE_EQ(ReadRigConfig(file).cameras[0].calibration.fx, calibrated.camera.fx);
  EXPECT_EQ(ReadRigConfig(file).calibration_file, dir / "calibration.json");
  WriteFileAtomic(file, with_file + ", \"serial\": \"999\"}]}");
  EXPECT_THAT([&] { ReadRigConfig(file); },
              ::testing::ThrowsMessage<FormatError>(HasSubstr("is the camera 999")));
  WriteFileAtomic(file, with_file + "}, {\"port\": \"usb:001,003\"}]}");
  EXPECT_THAT(
      [&] { ReadRigConfig(file); },
      ::testing::ThrowsMessage<FormatError>(HasSubstr("calibrates 1 camera(s), the rig has 2")));
  WriteFileAtomic(file, std::string("{\"version\": 2}"));
  EXPECT_THROW(ReadRigConfig(file), FormatError);
  EXPECT_THROW(ReadRigConfig(dir / "none.json"), IoError);
}

}  // namespace
}  // namespace carousel::studio
