#include "carousel/app/cli.h"
#include "carousel/core/mesh_io.h"
#include "carousel/sim/avr_turntable.h"
#include "carousel/studio/defaults.h"
#include "carousel/studio/session.h"

#include <sys/wait.h>

#include <chrono>
#include <csignal>
#include <cstdlib>
#include <thread>

#include <opencv2/core.hpp>

#include "carousel/core/image_io.h"

#include <cstdio>
#include <regex>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "carousel/testing/testing.h"

namespace carousel::studio {
namespace {

using namespace carousel::app;  // NOLINT(google-build-using-namespace): the program under test

using ::testing::HasSubstr;

struct CliResult {
  int code;
  std::string out;
  std::string err;
};

CliResult RunCarousel(std::vector<const char*> args) {
  args.insert(args.begin(), "carousel");
  std::ostringstream out, err;
  const int code = RunCli(static_cast<int>(args.size()), args.data(), out, err);
  return {code, out.str(), err.str()};
}

constexpr const char* kSubcommands[] = {"sim", "import", "reconstruct", "texture",  "process",
                                        "run", "camera", "turntable",   "calibrate"};

TEST(CliTest, HelpListsEverySubcommand) {
  const CliResult result = RunCarousel({"--help"});
  EXPECT_EQ(result.code, kExitOk);
  for (const char* name : kSubcommands) EXPECT_THAT(result.out, HasSubstr(name)) << name;
  EXPECT_THAT(result.out, HasSubstr("self-check"));
}

TEST(CliTest, VersionNamesTheLibraries) {
  const CliResult result = RunCarousel({"--version"});
  EXPECT_EQ(result.code, kExitOk);
  EXPECT_THAT(result.out, HasSubstr("carousel 0."));
  EXPECT_THAT(result.out, HasSubstr("OpenCV 4."));
  EXPECT_THAT(result.out, HasSubstr("OpenMesh 9."));
}

TEST(CliTest, UsageErrorsExitWith64) {
  EXPECT_EQ(RunCarousel({}).code, kExitUsage);
  EXPECT_EQ(RunCarousel({"frobnicate"}).code, kExitUsage);
  const CliResult bad_level = RunCarousel({"--log-level", "chatty", "self-check"});
  EXPECT_EQ(bad_level.code, kExitUsage);
  EXPECT_THAT(bad_level.err, HasSubstr("unknown log level 'chatty'"));
  const CliResult bad_points = RunCarousel({"self-check", "--points", "0"});
  EXPECT_EQ(bad_points.code, kExitUsage);
  EXPECT_THAT(bad_points.err, HasSubstr("--points must be >= 1"));
}

TEST(CliTest, AnUnknownCommandIsNamedWithTheNearestOne) {
  const CliResult typo = RunCarousel({"proces", "sessions/x"});
  EXPECT_EQ(typo.code, kExitUsage);
  EXPECT_THAT(typo.err, HasSubstr("'proces' is not a command"));
  EXPECT_THAT(typo.err, HasSubstr("did you mean 'process'?"));
  // After a global option with a value, and one level down.
  const CliResult nested = RunCarousel({"--log-level", "warn", "sim", "captur", "--out", "x"});
  EXPECT_EQ(nested.code, kExitUsage);
  EXPECT_THAT(nested.err, HasSubstr("carousel sim: 'captur' is not a command"));
  EXPECT_THAT(nested.err, HasSubstr("did you mean 'capture'?"));
  // Nothing near: no suggestion, still a usage error.
  const CliResult far = RunCarousel({"zzzzzzzz"});
  EXPECT_EQ(far.code, kExitUsage);
  EXPECT_THAT(far.err, ::testing::Not(HasSubstr("did you mean")));
  // A session folder where `texture` also takes a subcommand is not mistaken for one.
  testing::TempDir dir;
  const std::string missing = (dir.path() / "no-session").string();
  EXPECT_EQ(RunCarousel({"texture", missing.c_str()}).code, kExitIoError);
}

TEST(CliTest, OptionErrorsNameTheFlag) {
  testing::TempDir dir;
  const std::string session = (dir.path() / "s").string();
  const CliResult faces = RunCarousel({"reconstruct", session.c_str(), "--faces", "50"});
  EXPECT_EQ(faces.code, kExitUsage);
  EXPECT_THAT(faces.err, HasSubstr("--faces must be >= 100"));
  EXPECT_THAT(faces.err, ::testing::Not(HasSubstr("target_faces")));
  const CliResult method = RunCarousel({"reconstruct", session.c_str(), "--method", "magic"});
  EXPECT_EQ(method.code, kExitUsage);
  EXPECT_THAT(method.err, HasSubstr("--method must be auto, key, difference or backlit"));
  const std::string out = (dir.path() / "t").string();
  const CliResult size = RunCarousel({"sim", "capture", "--out", out.c_str(), "--size", "12x"});
  EXPECT_EQ(size.code, kExitUsage);
  EXPECT_THAT(size.err, HasSubstr("--size must look like 5184x3456"));
  const CliResult views = RunCarousel({"sim", "capture", "--out", out.c_str(), "--views", "0"});
  EXPECT_EQ(views.code, kExitUsage);
  EXPECT_THAT(views.err, HasSubstr("--views must be 1..3600, got 0"));
  EXPECT_FALSE(std::filesystem::exists(out));
}

TEST(CliTest, OutCreatesAMissingParentFolder) {
  testing::TempDir dir;
  const std::filesystem::path out = dir.path() / "a" / "b";
  const std::string out_text = out.string();
  const std::string data = testing::SharedDataDir().string();
  const CliResult result =
      RunCarousel({"sim", "capture", "--scene", "duck", "--data", data.c_str(), "--views", "2",
                   "--size", "96x64", "--out", out_text.c_str()});
  ASSERT_EQ(result.code, kExitOk) << result.err;
  EXPECT_TRUE(std::filesystem::is_regular_file(out / "session.json"));
  const std::string board = (dir.path() / "c" / "d" / "board.png").string();
  EXPECT_EQ(RunCarousel({"calibrate", "board", "--board", "chessboard:5x4:0.02", "--out",
                         board.c_str(), "--px-per-square", "20"})
                .code,
            kExitOk);
  EXPECT_TRUE(std::filesystem::is_regular_file(board));
}

TEST(CliTest, SelfCheckPassesOnThisBuild) {
  testing::TempDir scratch;
  const std::string data = testing::SharedDataDir().string();
  const std::string scratch_dir = scratch.path().string();
  const CliResult result =
      RunCarousel({"self-check", "--data", data.c_str(), "--scratch", scratch_dir.c_str()});
  EXPECT_EQ(result.code, kExitOk) << result.out << result.err;
  EXPECT_THAT(result.out, HasSubstr("PASS  camera model vs OpenCV"));
  EXPECT_THAT(result.out, HasSubstr("PASS  shared test data"));
  EXPECT_THAT(result.out, HasSubstr("self-check passed"));
  EXPECT_THAT(result.err, HasSubstr("self-check: 100%"));
  // The scratch folder given by the user is kept; only the check's own files go.
  EXPECT_TRUE(std::filesystem::is_directory(scratch.path()));
  EXPECT_TRUE(std::filesystem::is_empty(scratch.path()));
}

TEST(CliTest, SelfCheckReportsABrokenDataFolder) {
  testing::TempDir data;  // exists, but holds none of the expected files
  const std::string dir = data.path().string();
  const CliResult result = RunCarousel({"self-check", "--data", dir.c_str()});
  EXPECT_EQ(result.code, kExitFailure);
  EXPECT_THAT(result.out, HasSubstr("FAIL  shared test data"));
  EXPECT_THAT(result.out, HasSubstr("Duck.obj: no such file"));
}

// The installed program as a user runs it, in a child process.
CliResult RunBinary(const std::string& arguments) {
  testing::ShellResult result = testing::RunShell(testing::CarouselExecutable() + " " + arguments);
  return {result.code, std::move(result.out), ""};
}

TEST(CliBinaryTest, HelpAndUsageErrorsFromTheExecutable) {
  const CliResult help = RunBinary("--help");
  EXPECT_EQ(help.code, 0) << help.out;
  for (const char* name : kSubcommands) EXPECT_THAT(help.out, HasSubstr(name));
  // `run` needs to know where to capture; the simulated rig needs a product; a rig file
  // that is not there is named.
  const CliResult run = RunBinary("run --product X");
  EXPECT_EQ(run.code, kExitUsage) << run.out;
  EXPECT_THAT(run.out, HasSubstr("--rig RIG.json"));
  const CliResult no_rig = RunBinary("run --product X --rig /nonexistent/rig.json");
  EXPECT_EQ(no_rig.code, kExitIoError) << no_rig.out;
  EXPECT_THAT(no_rig.out, HasSubstr("/nonexistent/rig.json"));
  const CliResult no_product = RunBinary("run --sim");
  EXPECT_EQ(no_product.code, kExitUsage) << no_product.out;
  EXPECT_THAT(no_product.out, HasSubstr("--product"));
  // A session that does not exist is named.
  const CliResult texture = RunBinary("texture /nonexistent/session");
  EXPECT_EQ(texture.code, kExitIoError) << texture.out;
  EXPECT_THAT(texture.out, HasSubstr("/nonexistent/session"));
}

}  // namespace
}  // namespace carousel::studio

namespace carousel::studio {
namespace {

using namespace carousel::app;  // NOLINT(google-build-using-namespace): the program under test

TEST(CliBinaryTest, SimCaptureAndImportFromTheExecutable) {
  testing::TempDir dir;
  const std::string data = testing::SharedDataDir().string();
  const CliResult capture =
      RunBinary("sim capture --data " + data + " --scene avocado --views 3 --size 200x150 " +
                "--elevations 10,50 --target-height 0.1 --backdrop '#20a040' --out " +
                (dir / "avo").string());
  EXPECT_EQ(capture.code, 0) << capture.out;
  EXPECT_THAT(capture.out, HasSubstr("6 views"));
  EXPECT_TRUE(std::filesystem::exists(dir / "avo/images/cam1_stop02.jpg"));
  // Again without --force: refused, the session stays.
  const CliResult again =
      RunBinary("sim capture --data " + data + " --scene avocado --views 1 --size 200x150 --out " +
                (dir / "avo").string());
  EXPECT_EQ(again.code, kExitIoError) << again.out;
  EXPECT_THAT(again.out, HasSubstr("--force"));
  EXPECT_TRUE(std::filesystem::exists(dir / "avo/images/cam1_stop02.jpg"));
  const CliResult bad = RunBinary("sim capture --scene teapot --out " + (dir / "x").string());
  EXPECT_EQ(bad.code, kExitUsage);
  EXPECT_THAT(bad.out, HasSubstr("unknown scene 'teapot'"));
  const CliResult imported =
      RunBinary("import " + data + "/middlebury/templeSparseRing/templeSR_par.txt --out " +
                (dir / "temple").string() + " --link hard");
  EXPECT_EQ(imported.code, 0) << imported.out;
  EXPECT_THAT(imported.out, HasSubstr("16 views imported"));
}

}  // namespace
}  // namespace carousel::studio

namespace carousel::studio {
namespace {

using namespace carousel::app;  // NOLINT(google-build-using-namespace): the program under test

// The texture atlas of a shared model: an OBJ with UVs, the figures printed, bad input
// refused with the exit code of its kind.
TEST(CliBinaryTest, TextureAtlasOfAMesh) {
  testing::TempDir dir;
  const std::string duck = testing::SharedDataFile("models/Duck/obj_derived/Duck.obj").string();
  const std::string out = (dir / "duck.obj").string();
  const CliResult atlas = RunBinary("texture atlas " + duck + " --out " + out +
                                    " --size 512 --charts-image " + (dir / "charts.png").string());
  ASSERT_EQ(atlas.code, 0) << atlas.out;
  EXPECT_THAT(atlas.out, HasSubstr("charts"));
  EXPECT_THAT(atlas.out, HasSubstr("utilization"));
  const Mesh mesh = ReadMesh(dir / "duck.obj");
  EXPECT_TRUE(mesh.has_uvs());
  EXPECT_EQ(mesh.n_faces(), ReadMesh(duck).n_faces());
  EXPECT_TRUE(std::filesystem::exists(dir / "charts.png"));
  EXPECT_EQ(RunBinary("texture atlas " + duck + " --out " + out + " --packing round").code,
            kExitUsage);
  EXPECT_EQ(RunBinary("texture atlas " + (dir / "missing.obj").string() + " --out " + out).code,
            kExitIoError);
  // Three faces on one edge (non-manifold): reading repairs it by duplicating the edge's
  // vertices for the third face; no face goes missing and every face gets UVs.
  testing::WriteBytes(dir / "fin.obj",
                      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\n"
                      "f 1 2 3\nf 2 1 4\nf 1 2 5\n");
  const CliResult fin = RunBinary("texture atlas " + (dir / "fin.obj").string() + " --out " +
                                  (dir / "fin_atlas.obj").string() + " --size 256");
  ASSERT_EQ(fin.code, 0) << fin.out;
  const Mesh fin_atlas = ReadMesh(dir / "fin_atlas.obj");
  EXPECT_EQ(fin_atlas.n_faces(), 3u);
  EXPECT_TRUE(fin_atlas.has_uvs());
}

// The reconstruction stage on a small simulated session: masks, hull and mesh appear, the
// manifest records them, the photos are untouched; bad input is refused with a clear error.
TEST(CliBinaryTest, ReconstructASimulatedSession) {
  testing::TempDir dir;
  const std::string data = testing::SharedDataDir().string();
  const std::string session = (dir / "bottle").string();
  const CliResult capture = RunBinary("sim capture --data " + data +
                                      " --scene bottle --views 8 --size 480x320 --out " + session);
  ASSERT_EQ(capture.code, 0) << capture.out;
  const std::string photo_before = testing::ReadBytes(dir / "bottle/images/cam0_stop03.jpg");
  const CliResult reconstructed =
      RunBinary("reconstruct " + session + " --faces 800 --resolution 64");
  ASSERT_EQ(reconstructed.code, 0) << reconstructed.out;
  EXPECT_THAT(reconstructed.out, HasSubstr("800 faces"));
  // The mesh reproduces the silhouettes to a couple of pixels (480x320 photos, 800 faces).
  std::smatch deviation;
  ASSERT_TRUE(std::regex_search(reconstructed.out, deviation,
                                std::regex("outline deviation ([0-9.]+) px on average")))
      << reconstructed.out;
  EXPECT_LT(std::stod(deviation[1].str()), 2.0) << reconstructed.out;
  EXPECT_TRUE(std::filesystem::exists(dir / "bottle/masks/cam0_stop03.png"));
  EXPECT_TRUE(std::filesystem::exists(dir / "bottle/recon/hull.ply"));
  EXPECT_EQ(testing::ReadBytes(dir / "bottle/images/cam0_stop03.jpg"), photo_before);
  const Session manifest = ReadSession(dir / "bottle");
  EXPECT_EQ(manifest.stages.at("reconstruct"), "done");
  EXPECT_EQ(manifest.views[3].mask, "masks/cam0_stop03.png");
  const Mesh mesh = ReadMesh(dir / "bottle/recon/mesh.ply");
  EXPECT_NEAR(static_cast<double>(mesh.n_faces()), 800.0, 8.0);

  // The difference method uses the session's background plates.
  const CliResult difference =
      RunBinary("reconstruct " + session + " --faces 600 --resolution 64 --method difference");
  EXPECT_EQ(difference.code, 0) << difference.out;
  std::filesystem::remove(dir / "bottle/backgrounds/cam0.jpg");
  const CliResult no_plate = RunBinary("reconstruct " + session + " --method difference");
  EXPECT_EQ(no_plate.code, kExitIoError) << no_plate.out;
  EXPECT_THAT(no_plate.out, HasSubstr("backgrounds/cam0.jpg"));
  // A corrupt photo is named.
  testing::WriteBytes(dir / "bottle/images/cam0_stop05.jpg", "not a jpeg");
  const CliResult corrupt = RunBinary("reconstruct " + session);
  EXPECT_NE(corrupt.code, 0);
  EXPECT_THAT(corrupt.out, HasSubstr("cam0_stop05.jpg"));
  EXPECT_EQ(RunBinary("reconstruct " + (dir / "missing").string()).code, kExitIoError);
}

}  // namespace
}  // namespace carousel::studio

namespace carousel::studio {
namespace {

using namespace carousel::app;  // NOLINT(google-build-using-namespace): the program under test

// `carousel turntable` against the real firmware in simavr.
TEST(CliTest, TurntableCommandsDriveTheController) {
  testing::TempDir dir;
  sim::AvrTurntableOptions o;
  o.firmware = DefaultFirmwarePath();
  o.time_scale = 20.0;
  o.link = dir.path() / "ttyTT";
  sim::AvrTurntable controller(o);
  const std::string port = controller.port();
  CliResult r = RunCarousel({"turntable", "--port", port.c_str(), "identify"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("Carousel TT-328, firmware 1.1.0 (protocol 1.1)"));
  r = RunCarousel({"turntable", "--port", port.c_str(), "goto", "90"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("angle 90.000 deg (2400 microsteps)"));
  EXPECT_EQ(controller.motor_steps(), 2400);
  r = RunCarousel({"turntable", "--port", port.c_str(), "config", "--backlash", "64"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("backlash 64 microsteps"));
  r = RunCarousel({"turntable", "--port", port.c_str(), "config", "--acceleration", "5"});
  EXPECT_EQ(r.code, kExitUsage);
  r = RunCarousel(
      {"turntable", "--port", port.c_str(), "trigger", "--cameras", "0,2", "--ms", "20"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("shutter outputs 5 on for 20 ms"));
  r = RunCarousel({"turntable", "--port", port.c_str(), "backlight", "--on"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("backlight on"));
  EXPECT_TRUE(controller.backlight_on());
  r = RunCarousel({"turntable", "--port", port.c_str(), "status"});
  EXPECT_THAT(r.out, HasSubstr("backlight on"));
  r = RunCarousel({"turntable", "--port", port.c_str(), "backlight", "--off"});
  EXPECT_THAT(r.out, HasSubstr("backlight off"));
  EXPECT_FALSE(controller.backlight_on());
  r = RunCarousel({"turntable", "--port", port.c_str(), "spin"});
  EXPECT_EQ(r.code, kExitUsage);
  const std::string missing = (dir.path() / "ttyNONE").string();
  r = RunCarousel({"turntable", "--port", missing.c_str(), "status"});
  EXPECT_EQ(r.code, kExitDeviceError);
  EXPECT_THAT(r.err, HasSubstr(missing));
}

// `carousel sim camera` (the program, as a user starts it) photographed through
// `carousel camera` (libgphoto2 over PTP/IP).
TEST(CliTest, CameraCommandsDriveTheSimulatedPtpIpCamera) {
  testing::TempDir home;
  ::setenv("HOME", home.path().c_str(), 1);  // libgphoto2's ~/.gphoto/settings
  testing::TempDir dir;
  const std::filesystem::path log = dir / "sim.log";
  const std::string command = "timeout -k 5 120 " + (testing::BinDir() / "carousel").string() +
                              " sim camera --port 0 --size 320x240 --turn-deg 90 --seconds 60 >'" +
                              log.string() + "' 2>&1 & echo $!";
  FILE* pipe = ::popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  char pid_text[32] = {};
  ASSERT_NE(std::fgets(pid_text, sizeof pid_text, pipe), nullptr);
  ::pclose(pipe);
  const pid_t pid = static_cast<pid_t>(std::atoi(pid_text));
  std::string port;
  for (int i = 0; i < 600 && port.empty(); ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
    const std::string text = testing::ReadBytes(log);
    const std::size_t at = text.find("--port ptpip:");
    if (at != std::string::npos && text.find(" --camera", at) != std::string::npos) {
      port = text.substr(at + 7, text.find(' ', at + 7) - at - 7);
    }
  }
  ASSERT_FALSE(port.empty()) << testing::ReadBytes(log);

  // The listing: libgphoto2's auto-detected cameras and the USB bus through libusb (or a clear
  // word that this machine has none); network cameras are named, not detected.
  CliResult r = RunCarousel({"camera", "list"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("libgphoto2 2.5"));
  EXPECT_THAT(r.out, HasSubstr("cameras (libgphoto2): "));
  EXPECT_THAT(r.out, HasSubstr("USB devices (libusb): "));
  EXPECT_THAT(r.out, HasSubstr("--port ptpip:"));
  // Watching for cameras arriving and leaving: hotplug, polling, or a clear word why not.
  r = RunCarousel({"camera", "watch", "--seconds", "0.3"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, ::testing::AnyOf(HasSubstr("watching USB through libusb hotplug events"),
                                      HasSubstr("watching USB by listing the bus"),
                                      HasSubstr("USB cannot be watched here: ")));

  r = RunCarousel({"camera", "summary", "--port", port.c_str()});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("serial EMU0001"));
  EXPECT_THAT(r.out, HasSubstr("iso = 100"));
  r = RunCarousel(
      {"camera", "config", "--port", port.c_str(), "--set", "iso=400", "--set", "aperture=f/5.6"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  EXPECT_THAT(r.out, HasSubstr("/iso = 400"));
  EXPECT_THAT(r.out, HasSubstr("/f-number = f/5.6"));
  r = RunCarousel({"camera", "config", "--port", port.c_str(), "--set", "iso=12345"});
  EXPECT_EQ(r.code, kExitUsage);
  EXPECT_THAT(r.err, HasSubstr("not a value of iso"));
  const std::string out = (dir / "photos").string();
  r = RunCarousel({"camera", "capture", "--port", port.c_str(), "--count", "2", "--out",
                   out.c_str(), "--delete"});
  ASSERT_EQ(r.code, kExitOk) << r.err;
  const cv::Mat first = ReadImage(dir / "photos/IMG_0001.JPG");
  const cv::Mat second = ReadImage(dir / "photos/IMG_0002.JPG");
  EXPECT_EQ(first.cols, 320);
  EXPECT_EQ(second.rows, 240);
  EXPECT_GT(cv::norm(first, second, cv::NORM_L1) / first.total(), 1.0);  // the table turned
  // A camera that is not there: a device error naming it.
  r = RunCarousel({"camera", "summary", "--port", "ptpip:127.0.0.1:1:1", "--timeout", "3"});
  EXPECT_EQ(r.code, kExitDeviceError);
  EXPECT_THAT(r.err, HasSubstr("ptpip:127.0.0.1:1:1"));
  ::kill(pid, SIGTERM);
  for (int i = 0; i < 100 && ::kill(pid, 0) == 0; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  EXPECT_THAT(testing::ReadBytes(log), HasSubstr("served 2 captures"));
}

}  // namespace
}  // namespace carousel::studio

namespace carousel::studio {
namespace {

// A manifest whose number overflows (1e999): the program names the file and the field and
// exits 65 (a malformed input file), not 1.
TEST(CliBinaryTest, AManifestNumberOutOfRangeExitsWith65) {
  testing::TempDir dir;
  std::filesystem::create_directories(dir / "s");
  testing::WriteBytes(dir / "s" / kManifestName,
                      R"({"format": "carousel-session", "version": 1, "product": "x",
                          "frame": "turntable", "views": [{"image": "images/a.jpg", "camera": 0,
                          "stop": 0, "table_angle_deg": 1e999}]})");
  const CliResult r = RunBinary("reconstruct " + (dir / "s").string());
  EXPECT_EQ(r.code, kExitDataError) << r.out;
  EXPECT_THAT(r.out, HasSubstr((dir / "s" / kManifestName).string()));
  EXPECT_THAT(r.out, HasSubstr("views[0].table_angle_deg"));
}

}  // namespace
}  // namespace carousel::studio
