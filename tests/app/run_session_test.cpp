// The one-button session: names, checksums, resume after damage, and SIGKILL at ten moments
// spread over a whole run (capture, downloads, each stage), each followed by --resume.
#include "carousel/studio/run_session.h"

#include <fcntl.h>
#include <signal.h>
#include <spawn.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include <algorithm>
#include <array>
#include <chrono>
#include <fstream>
#include <functional>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <thread>

#include "carousel/app/cli.h"
#include "carousel/core/error.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/timer.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/session.h"
#include "carousel/testing/testing.h"

extern char** environ;

namespace carousel::studio {
namespace {

using namespace carousel::app;  // NOLINT(google-build-using-namespace): the program under test

using testing::TempDir;

TEST(RunSessionTest, ProductNamesBecomeSafeFolderNames) {
  EXPECT_EQ(SessionNameForProduct("SHOE-42.blue_v2"), "SHOE-42.blue_v2");
  EXPECT_EQ(SessionNameForProduct("Shoe 42/blue"), "Shoe_42_blue");
  EXPECT_EQ(SessionNameForProduct("../../etc"), "_.._etc");
  EXPECT_EQ(SessionNameForProduct("..hidden"), "hidden");
  EXPECT_EQ(SessionNameForProduct(std::string(300, 'a')).size(), 100u);
  EXPECT_THROW(SessionNameForProduct("///"), InvalidArgument);
  EXPECT_THROW(SessionNameForProduct(""), InvalidArgument);
}

TEST(RunSessionTest, Sha256OfAKnownText) {
  TempDir dir;
  {
    std::ofstream out(dir / "abc");
    out << "abc";
  }
  EXPECT_EQ(FileSha256(dir / "abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  EXPECT_THROW(FileSha256(dir / "missing"), IoError);
}

// The program, as the operator runs it.
pid_t Spawn(const std::vector<std::string>& args) {
  std::vector<std::string> all = {(testing::BinDir() / "carousel").string(), "--log-level", "off"};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  argv.reserve(all.size() + 1);
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 1, "/dev/null", O_WRONLY, 0);
  posix_spawn_file_actions_addopen(&actions, 2, "/dev/null", O_WRONLY, 0);
  pid_t pid = -1;
  EXPECT_EQ(posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ), 0);
  posix_spawn_file_actions_destroy(&actions);
  return pid;
}

int Wait(pid_t pid) {
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -WTERMSIG(status);
}

// The publish stage's images at sizes that suit these small photos (its defaults are for
// DSLR photos: a 720 px spin of 24 renders alone takes 5 s under the sanitizers).
constexpr std::array<const char*, 8> kSmallPublish = {
    "--spin-size", "240", "--hero-size", "480", "--poster-size", "240", "--cutout-size", "480"};

// 8 stops at 480x320 with view 2 held out and scored; or, for the kill test (11 runs, 6 under
// the sanitizers), 6 stops at 360x240 and nothing held out. Both publish at kSmallPublish.
std::vector<std::string> RunArgs(const std::filesystem::path& out, bool small = false) {
  std::vector<std::string> args = {
      "run",   "--sim",      "--product", "kill-test",
      "--out", out.string(), "--data",    testing::SharedDataDir().string()};
  const std::vector<std::string> size =
      small
          ? std::vector<std::string>{"--size", "360x240", "--views", "6", "--mask-shots", "backlit"}
          : std::vector<std::string>{"--size", "480x320", "--views", "8", "--exclude-views", "2"};
  args.insert(args.end(), size.begin(), size.end());
  args.insert(args.end(), kSmallPublish.begin(), kSmallPublish.end());
  return args;
}

std::map<std::string, std::string> Recorded(const std::filesystem::path& session) {
  std::map<std::string, std::string> photos;
  if (!std::filesystem::exists(session / kManifestName)) return photos;
  for (const SessionView& v : ReadSession(session).views) {
    photos[v.image] = v.sha256;
    if (!v.mask_shot.empty()) photos[v.mask_shot] = v.mask_shot_sha256;
  }
  return photos;
}

TEST(RunSessionTest, ResumesAfterSigkillAtTenMomentsWithTheSamePhotosAndNoDuplicates) {
  TempDir dir;
  // A whole run first: its duration spreads the kills.
  Stopwatch watch;
  ASSERT_EQ(Wait(Spawn(RunArgs(dir / "reference", true))), 0);
  const double seconds = watch.ElapsedSeconds();
  const std::filesystem::path reference = dir / "reference" / "kill-test";
  ASSERT_EQ(Recorded(reference).size(), 12u);  // 6 photos, each with its backlit mask shot

  std::mt19937 random(20261201);
  std::uniform_real_distribution<double> jitter(0.0, 1.0);
  // Where each kill landed, judged from what the session held afterwards.
  std::map<std::string, int> landed;
  const auto count_files = [](const std::filesystem::path& folder) {
    std::error_code ec;
    int n = 0;
    for (auto it = std::filesystem::directory_iterator(folder, ec);
         !ec && it != std::filesystem::directory_iterator(); it.increment(ec))
      ++n;
    return n;
  };
  const auto manifest_has = [](const std::filesystem::path& session, const char* text) {
    std::ifstream in(session / kManifestName);
    const std::string manifest((std::istreambuf_iterator<char>(in)), {});
    return manifest.find(text) != std::string::npos;
  };
#if defined(CAROUSEL_SANITIZE_BUILD)
  // Under the sanitizers (10x slower) every third moment: start-up, capture (with the mask
  // shots), the hull and the texture stage still land where they do in the Release build.
  constexpr int kStep = 3;
#else
  constexpr int kStep = 1;
#endif
  for (int k = 0; k < 10; k += kStep) {
    const auto out = dir / ("run" + std::to_string(k));
    const auto session = out / "kill-test";
    // Each kill waits for a moment of the run (start-up, photos on disk, masks being written,
    // the hull, the mesh, the texture stage under way), then strikes after a random delay.
    const std::function<bool()> moment[10] = {
        [] { return true; },
        [&] { return count_files(session / "images") >= 1; },
        [&] { return count_files(session / "images") >= 3; },
        [&] { return count_files(session / "images") >= 8; },
        [&] { return count_files(session / "masks") >= 1; },
        [&] { return count_files(session / "masks") >= 4; },
        [&] { return std::filesystem::exists(session / "recon" / "hull.ply"); },
        [&] { return std::filesystem::exists(session / "recon" / "mesh.ply"); },
        [&] { return manifest_has(session, "stage_inputs"); },
        [&] { return count_files(session / "model") >= 1; }};
    const pid_t pid = Spawn(RunArgs(out, true));
    Stopwatch waited;
    while (!moment[k]() && waited.ElapsedSeconds() < 2.0 * seconds + 10.0) {
      std::this_thread::sleep_for(std::chrono::microseconds(500));
    }
    std::this_thread::sleep_for(std::chrono::duration<double>(jitter(random) * 0.02 * seconds));
    kill(pid, SIGKILL);
    Wait(pid);
    const std::map<std::string, std::string> before = Recorded(session);
    const Session at_kill =
        std::filesystem::exists(session / kManifestName) ? ReadSession(session) : Session();
    const std::string phase = !std::filesystem::exists(session / kManifestName) ? "start-up"
                              : at_kill.stages.count("capture") == 0            ? "capture"
                              : at_kill.stage_inputs.count("reconstruct") == 0  ? "reconstruct"
                              : at_kill.stage_inputs.count("texture") == 0      ? "texture"
                                                                                : "finished";
    ++landed[phase];
    if (!std::filesystem::exists(session / "run.json")) {
      // Killed before the session existed: a new run starts it.
      ASSERT_EQ(Wait(Spawn(RunArgs(out, true))), 0) << "kill " << k;
    } else {
      ASSERT_EQ(Wait(Spawn({"run", "--resume", session.string()})), 0) << "kill " << k;
    }
    const Session done = ReadSession(session);
    EXPECT_EQ(done.stages.at("capture"), "done");
    EXPECT_EQ(done.stages.at("reconstruct"), "done");
    EXPECT_EQ(done.stages.at("texture"), "done");
    // Every planned photo and mask shot once; none recorded before the kill was retaken.
    std::set<std::string> names;
    for (const SessionView& v : done.views) {
      for (const auto& [file, sha] :
           {std::pair{v.image, v.sha256}, std::pair{v.mask_shot, v.mask_shot_sha256}}) {
        ASSERT_FALSE(file.empty()) << "kill " << k << ": " << v.image << " without its mask shot";
        EXPECT_TRUE(names.insert(file).second) << "duplicate " << file;
        EXPECT_EQ(FileSha256(session / file), sha) << file;
        const auto it = before.find(file);
        if (it != before.end()) {
          EXPECT_EQ(it->second, sha) << "kill " << k << ": " << file << " retaken";
        }
      }
    }
    EXPECT_EQ(names.size(), 12u);
    int files = 0;
    for (const auto& entry : std::filesystem::directory_iterator(session / "images")) {
      ++files;
      EXPECT_TRUE(names.count("images/" + entry.path().filename().string())) << entry.path();
    }
    EXPECT_EQ(files, 12) << "kill " << k;
    for (const char* name :
         {"model/model.obj", "model/model.png", "model/model.glb", "recon/mesh.ply"})
      EXPECT_TRUE(std::filesystem::exists(session / name)) << "kill " << k << ": " << name;
    // The resumed run published with the flags the killed one was given (run.json).
    const nlohmann::json published =
        nlohmann::json::parse(testing::ReadBytes(session / "model/publish.json"));
    EXPECT_EQ(published["catalog"]["spin_renders"]["size"], 240) << "kill " << k;
    std::printf("kill %d: during %s, %zu photos recorded\n", k, phase.c_str(), before.size());
    // Nothing but the session (and hidden staging left by a kill) in the output folder.
    for (const auto& entry : std::filesystem::directory_iterator(out)) {
      const std::string name = entry.path().filename().string();
      EXPECT_TRUE(name == "kill-test" || name.rfind(".kill-test.partial-", 0) == 0) << name;
    }
  }
  // Every part of a run was hit: capture (and its downloads), reconstruct and texture.
  EXPECT_GE(landed["capture"], 1);
  EXPECT_GE(landed["reconstruct"], 1);
  EXPECT_GE(landed["texture"], 1);
}

// `carousel process`: each stage skipped when current, rerun when its inputs or options change;
// a batch goes on past a session that fails and reports it.
TEST(RunSessionTest, ProcessSkipsCurrentStagesAndRunsABatchPastAFailure) {
  TempDir dir;
  std::vector<std::string> run_args = RunArgs(dir.path(), true);
  run_args.insert(run_args.end(), {"--exclude-views", "2"});
  ASSERT_EQ(Wait(Spawn(run_args)), 0);
  const auto session = dir.path() / "kill-test";
  const auto run = [](const std::vector<std::string>& args, std::string* out_text) {
    std::vector<std::string> all = {"carousel", "--log-level", "off", "process"};
    all.insert(all.end(), args.begin(), args.end());
    std::vector<const char*> argv;
    argv.reserve(all.size());
    for (const auto& a : all) argv.push_back(a.c_str());
    std::ostringstream out, err;
    const int code = RunCli(static_cast<int>(argv.size()), argv.data(), out, err);
    *out_text = out.str() + err.str();
    return code;
  };
  std::string text;
  // The one-button run recorded its stages' inputs, and the held-out view and publish flags it
  // was given (report.json, publish.json), which `process` goes on with: nothing to do.
  const auto mesh_time = std::filesystem::last_write_time(session / "recon" / "mesh.ply");
  EXPECT_EQ(run({session.string()}, &text), 0) << text;
  EXPECT_THAT(text, ::testing::HasSubstr("reconstruct: current, skipped"));
  EXPECT_THAT(text, ::testing::HasSubstr("texture: current, skipped"));
  EXPECT_THAT(text, ::testing::HasSubstr("publish: current, skipped"));
  EXPECT_EQ(std::filesystem::last_write_time(session / "recon" / "mesh.ply"), mesh_time);
  // Another face count: both stages again.
  EXPECT_EQ(run({"--faces", "2000", session.string()}, &text), 0) << text;
  EXPECT_THAT(text, ::testing::HasSubstr("mesh " + (session / "recon/mesh.ply").string()));
  EXPECT_THAT(text, ::testing::Not(::testing::HasSubstr("skipped")));
  EXPECT_NEAR(static_cast<double>(ReadMesh(session / "recon" / "mesh.ply").n_faces()), 2000.0,
              20.0);
  // ... still holding out the view the run held out.
  EXPECT_EQ(
      nlohmann::json::parse(testing::ReadBytes(session / "model/report.json")).at("excluded_views"),
      nlohmann::json::array({2}));
  // The texture alone goes stale when its model files go.
  std::filesystem::remove(session / "model" / "model.glb");
  EXPECT_EQ(run({"--faces", "2000", session.string()}, &text), 0) << text;
  EXPECT_THAT(text, ::testing::HasSubstr("reconstruct: current, skipped"));
  EXPECT_THAT(text, ::testing::Not(::testing::HasSubstr("texture: current")));
  EXPECT_TRUE(std::filesystem::exists(session / "model" / "model.glb"));
  // A photo damaged since capture: its recorded checksum is not trusted, the file is read
  // again, so the reconstruction is stale and fails naming the photo (nothing is overwritten).
  const auto photo = session / "images" / "cam0_stop01.jpg";
  const std::string photo_bytes = testing::ReadBytes(photo);
  const std::string mesh_bytes = testing::ReadBytes(session / "recon" / "mesh.ply");
  testing::WriteBytes(photo, photo_bytes.substr(0, photo_bytes.size() / 3));
  {
    const std::vector<std::string> args = {
        "carousel", "--log-level", "info", "--log-file",    (dir / "process.log").string(),
        "process",  "--faces",     "2000", session.string()};
    std::vector<const char*> argv;
    argv.reserve(args.size());
    for (const auto& a : args) argv.push_back(a.c_str());
    std::ostringstream out, err;
    EXPECT_NE(RunCli(static_cast<int>(argv.size()), argv.data(), out, err), 0);
    text = out.str() + err.str() + testing::ReadBytes(dir / "process.log");
  }
  EXPECT_THAT(text, ::testing::HasSubstr("reconstruct runs (photo images/cam0_stop01.jpg changed "
                                         "since capture"));
  EXPECT_THAT(text, ::testing::HasSubstr("error: "));
  EXPECT_THAT(text.substr(text.find("error: ")), ::testing::HasSubstr("cam0_stop01.jpg"));
  EXPECT_EQ(testing::ReadBytes(session / "recon" / "mesh.ply"), mesh_bytes);
  // The photo as captured again: nothing to do.
  testing::WriteBytes(photo, photo_bytes);
  EXPECT_EQ(run({"--faces", "2000", session.string()}, &text), 0) << text;
  EXPECT_THAT(text, ::testing::HasSubstr("reconstruct: current, skipped"));
  // A recalibrated camera makes the reconstruction stale.
  Session manifest = ReadSession(session);
  manifest.views[0].camera_model.fx *= 1.001;
  WriteSessionManifest(session, manifest);
  EXPECT_NE(ReconstructFingerprint(session, {.mesh = {.target_faces = 2000}}),
            ReadSession(session).stage_inputs.at("reconstruct"));
  // A batch: a missing session fails with its name, the next one is still processed.
  EXPECT_EQ(run({"--faces", "2000", (dir / "nowhere").string(), session.string()}, &text),
            kExitIoError)
      << text;
  EXPECT_THAT(text, ::testing::HasSubstr((dir / "nowhere").string()));
  EXPECT_THAT(text, ::testing::HasSubstr("1 of 2 sessions processed, 1 failed"));
  EXPECT_THAT(text, ::testing::HasSubstr("mesh " + (session / "recon/mesh.ply").string()));
}

TEST(RunSessionTest, ResumeRetakesMissingAndDamagedPhotosAndKeepsTheDamagedCopy) {
  TempDir dir;
  ASSERT_EQ(Wait(Spawn(RunArgs(dir.path()))), 0);
  const auto session = dir.path() / "kill-test";
  // End to end: the held-out view (2) rendered from model.glb against its photo. Bound from
  // measurement: 20.2 dB and SSIM 0.76 for this shoe at 480x320, 8 stops.
  {
    std::ifstream in(session / "model" / "report.json");
    const auto report = nlohmann::json::parse(in);
    const double psnr = report.at("held_out").at("mean_psnr_db").get<double>();
    const double ssim = report.at("held_out").at("mean_ssim").get<double>();
    std::printf("one-button session, held-out view: PSNR %.2f dB, SSIM %.4f\n", psnr, ssim);
    EXPECT_GT(psnr, 19.5);
    EXPECT_GT(ssim, 0.7);
  }
  const auto before = Recorded(session);
  std::filesystem::remove(session / "images" / "cam0_stop03.jpg");
  {
    std::ofstream damage(session / "images" / "cam0_stop05.jpg",
                         std::ios::binary | std::ios::trunc);
    damage << "not a photo";
  }
  Progress progress;
  const RunResult result = ResumeSession(session, progress);
  EXPECT_EQ(result.photos_taken, 2);
  EXPECT_EQ(result.photos_kept, 6);
  EXPECT_EQ(result.photos_retaken, 2);
  EXPECT_TRUE(result.reconstructed);
  EXPECT_TRUE(result.textured);
  EXPECT_TRUE(std::filesystem::exists(session / "damaged" / "cam0_stop05.jpg.1"));
  const auto after = Recorded(session);
  for (const auto& [image, sha] : after)
    if (image != "images/cam0_stop03.jpg" && image != "images/cam0_stop05.jpg") {
      EXPECT_EQ(before.at(image), sha);
    }
  // Nothing to do the next time.
  const RunResult again = ResumeSession(session, progress);
  EXPECT_EQ(again.photos_kept, 8);
  EXPECT_FALSE(again.reconstructed);
  EXPECT_FALSE(again.textured);
  // An existing session is never replaced without --force.
  EXPECT_EQ(Wait(Spawn(RunArgs(dir.path()))), kExitIoError);
}

// Two orientations on the simulated rig (it lays the product down itself between the passes):
// a run killed (SIGKILL) as the second pass begins resumes with the first pass's photos kept
// byte for byte and lays the product down again; the second pass's photos are tagged and
// registered; a resume that has to retake the last photo of the first pass and the first of
// the second stands the product back up, lays it down again, and keeps every other photo.
TEST(RunSessionTest, TwoOrientationsAreRegisteredAndResumedAcrossThePassBoundary) {
  TempDir dir;
  std::vector<std::string> args = {"run",
                                   "--sim",
                                   "--product",
                                   "two-passes",
                                   "--out",
                                   dir.path().string(),
                                   "--data",
                                   testing::SharedDataDir().string(),
                                   "--size",
                                   "480x320",
                                   "--views",
                                   "8",
                                   "--orientations",
                                   "2",
                                   "--backdrop",
                                   "grey",
                                   "--no-publish"};
  const auto session = dir.path() / "two-passes";
  // Killed at the pass boundary: the second pass's first photo on disk.
  const pid_t pid = Spawn(args);
  Stopwatch waited;
  while (!std::filesystem::exists(session / "images" / "pass1_cam0_stop00.jpg") &&
         waited.ElapsedSeconds() < 300.0)
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  kill(pid, SIGKILL);
  Wait(pid);
  const auto at_kill = Recorded(session);
  int first_pass_at_kill = 0;
  for (const auto& [image, sha] : at_kill)
    first_pass_at_kill += image.find("pass1_") == std::string::npos ? 1 : 0;
  EXPECT_EQ(first_pass_at_kill, 8);
  ASSERT_EQ(Wait(Spawn({"run", "--resume", session.string()})), 0);
  const Session first = ReadSession(session);
  ASSERT_EQ(first.views.size(), 16u);
  for (const auto& [image, sha] : at_kill) {
    const auto it =
        std::find_if(first.views.begin(), first.views.end(),
                     [&image = image](const SessionView& v) { return v.image == image; });
    ASSERT_NE(it, first.views.end()) << image;
    EXPECT_EQ(it->sha256, sha) << image << " retaken";
  }
  ASSERT_EQ(first.passes.size(), 2u);
  EXPECT_EQ(first.passes[1].orientation, "side");
  EXPECT_EQ(first.passes[1].registration, "registered") << first.passes[1].registration_note;
  EXPECT_EQ(first.views[8].image, "images/pass1_cam0_stop00.jpg");
  for (std::size_t i = 0; i < first.views.size(); ++i)
    EXPECT_EQ(first.views[i].pass, i < 8 ? 0 : 1) << first.views[i].image;
  EXPECT_EQ(first.stages.at("texture"), "done");
  const auto before = Recorded(session);
  std::map<std::string, cv::Mat> originals;
  for (const char* image : {"cam0_stop07.jpg", "pass1_cam0_stop00.jpg"}) {
    originals[image] = cv::imread((session / "images" / image).string());
    std::filesystem::remove(session / "images" / image);
  }
  Progress progress;
  const RunResult result = ResumeSession(session, progress);
  EXPECT_EQ(result.photos_taken, 2);
  EXPECT_EQ(result.photos_kept, 14);
  EXPECT_TRUE(result.reconstructed);
  const Session after = ReadSession(session);
  ASSERT_EQ(after.views.size(), 16u);
  for (std::size_t i = 0; i < after.views.size(); ++i) {
    EXPECT_EQ(after.views[i].pass, i < 8 ? 0 : 1) << after.views[i].image;
    const std::string& image = after.views[i].image;
    if (image == "images/cam0_stop07.jpg" || image == "images/pass1_cam0_stop00.jpg") continue;
    EXPECT_EQ(before.at(image), after.views[i].sha256) << image;
  }
  EXPECT_EQ(after.passes[1].registration, "registered") << after.passes[1].registration_note;
  // The retaken photos show the product as their pass laid it: the same photos again but for
  // the sensor noise (upright instead of on its side, or the other way, differs by far more).
  for (const auto& [image, original] : originals) {
    const cv::Mat retaken = cv::imread((session / "images" / image).string());
    ASSERT_EQ(retaken.size(), original.size()) << image;
    cv::Mat difference;
    cv::absdiff(retaken, original, difference);
    EXPECT_LT(cv::mean(difference)[0], 3.0) << image;
  }
}

// Backlit mask shots: one beside every photo, with its own checksum; the silhouettes come from
// them. A resume retakes exactly what is missing or damaged: a mask shot alone when only it is,
// both shots of a view whose photo is lost; everything else stays byte for byte.
TEST(RunSessionTest, MaskShotsAreVerifiedAndRetakenWithTheirStop) {
  TempDir dir;
  RunOptions options;
  options.product = "backlit";
  options.out = dir.path();
  options.sim.scene = "bottle";
  options.sim.data_dir = testing::SharedDataDir();
  options.sim.rig.width = 360;
  options.sim.rig.height = 240;
  options.sim.stops = 5;
  options.sim.mask_shots = "backlit";
  options.sim.material = sim::MaterialOverride::kWhite;  // white on the light backdrop
  options.sim.render.exposure = 0.65;
  options.publish_model = false;
  Progress progress;
  const RunResult first = RunSession(options, progress);
  EXPECT_EQ(first.photos_taken, 10);
  const std::filesystem::path session = first.session;
  const Session captured = ReadSession(session);
  ASSERT_EQ(captured.views.size(), 5u);
  for (const SessionView& v : captured.views) {
    EXPECT_EQ(v.mask_shot, "images/" + ViewStem(v.camera, v.stop) + "_backlit.jpg");
    EXPECT_EQ(FileSha256(session / v.mask_shot), v.mask_shot_sha256);
    EXPECT_NE(v.mask_shot_sha256, v.sha256);
  }
  // The silhouettes came from the mask shots.
  ASSERT_TRUE(first.reconstruct.has_value());
  EXPECT_EQ(first.reconstruct->method, "backlit");
  for (const auto& view : first.reconstruct->agreement) EXPECT_GE(view.iou, 0.95) << view.view;
  const auto before = Recorded(session);
  std::filesystem::remove(session / "images/cam0_stop02_backlit.jpg");
  testing::WriteBytes(session / "images/cam0_stop04_backlit.jpg", "not a photo");
  std::filesystem::remove(session / "images/cam0_stop01.jpg");
  const RunResult resumed = ResumeSession(session, progress);
  // Two mask shots alone; the lost photo and its mask shot together.
  EXPECT_EQ(resumed.photos_taken, 4);
  EXPECT_EQ(resumed.photos_retaken, 4);
  EXPECT_EQ(resumed.photos_kept, 6);
  EXPECT_TRUE(resumed.reconstructed);
  EXPECT_TRUE(std::filesystem::exists(session / "damaged/cam0_stop04_backlit.jpg.1"));
  EXPECT_TRUE(std::filesystem::exists(session / "damaged/cam0_stop01_backlit.jpg.1"));
  const auto after = Recorded(session);
  ASSERT_EQ(after.size(), 10u);
  const std::set<std::string> retaken = {"images/cam0_stop02_backlit.jpg",
                                         "images/cam0_stop04_backlit.jpg", "images/cam0_stop01.jpg",
                                         "images/cam0_stop01_backlit.jpg"};
  for (const auto& [file, sha] : after) {
    EXPECT_EQ(FileSha256(session / file), sha) << file;
    if (retaken.count(file) == 0) {
      EXPECT_EQ(before.at(file), sha) << file;
    }
  }
  const RunResult nothing = ResumeSession(session, progress);
  EXPECT_EQ(nothing.photos_taken, 0);
  EXPECT_EQ(nothing.photos_kept, 10);
  EXPECT_FALSE(nothing.reconstructed);
}

// run.json holds what a resume needs from anywhere: the data folder as an absolute path (it was
// given relative to another working folder) and the rendering's material, exposure and contact
// shadow, so that a photo retaken on resume is the photo that was lost, byte for byte.
TEST(RunSessionTest, ResumesFromAnotherFolderWithTheRecordedRendering) {
  TempDir dir;
  std::filesystem::create_directories(dir / "a");
  std::filesystem::create_directories(dir / "b");
  const std::string data = std::filesystem::relative(testing::SharedDataDir(), dir / "a").string();
  const testing::ShellResult run = testing::RunShell(
      "cd '" + (dir / "a").string() + "' && " + testing::CarouselExecutable() +
      " --log-level off run --sim --product relative --out sessions --data '" + data +
      "' --scene bottle --views 4 --size 240x160 --material glossy --exposure 1.25 "
      "--contact-shadow 0.5 --no-publish");
  ASSERT_EQ(run.code, 0) << run.out;
  const auto session = dir / "a" / "sessions" / "relative";
  const nlohmann::json recorded =
      nlohmann::json::parse(testing::ReadBytes(session / "run.json")).at("sim");
  const std::filesystem::path data_dir = recorded.at("data_dir").get<std::string>();
  EXPECT_TRUE(data_dir.is_absolute()) << data_dir;
  EXPECT_EQ(std::filesystem::weakly_canonical(data_dir),
            std::filesystem::weakly_canonical(testing::SharedDataDir()));
  EXPECT_EQ(recorded.at("material"), "glossy");
  EXPECT_DOUBLE_EQ(recorded.at("exposure").get<double>(), 1.25);
  EXPECT_DOUBLE_EQ(recorded.at("contact-shadow").get<double>(), 0.5);
  // A retaken photo has its own sensor noise, so it is compared by its pixels: the fraction
  // that differ from the lost photo's by more than 16 levels (noise alone: hardly any).
  const auto photo = session / "images" / "cam0_stop02.jpg";
  const cv::Mat lost = cv::imread(photo.string());
  ASSERT_FALSE(lost.empty());
  const auto retake = [&] {
    std::filesystem::remove(photo);
    const testing::ShellResult resume =
        testing::RunShell("cd '" + (dir / "b").string() + "' && " + testing::CarouselExecutable() +
                          " --log-level off run --resume '" + session.string() + "'");
    EXPECT_EQ(resume.code, 0) << resume.out;
    const cv::Mat again = cv::imread(photo.string());
    if (again.size() != lost.size()) return 1.0;
    cv::Mat difference;
    cv::absdiff(lost, again, difference);
    cv::Mat channels[3];
    cv::split(difference, channels);
    const cv::Mat worst = cv::max(cv::max(channels[0], channels[1]), channels[2]);
    return cv::countNonZero(worst > 16) / static_cast<double>(lost.total());
  };
  const double recorded_difference = retake();
  // The same session as run.json recorded it before the rendering was kept: today's defaults.
  nlohmann::json run_json = nlohmann::json::parse(testing::ReadBytes(session / "run.json"));
  for (const char* key : {"material", "exposure", "contact-shadow"}) run_json["sim"].erase(key);
  testing::WriteBytes(session / "run.json", run_json.dump(2));
  const double default_difference = retake();
  std::printf(
      "retaken photo vs lost: %.4f of the pixels differ with the recorded rendering, "
      "%.4f without\n",
      recorded_difference, default_difference);
  EXPECT_LT(recorded_difference, 0.001);
  EXPECT_GT(default_difference, 0.004);
}

// The program under a file-size limit (a full disk as far as the writes can tell): its output
// goes to `log`.
int RunLimited(const std::vector<std::string>& args, rlim_t max_file_bytes,
               const std::filesystem::path& log) {
  std::vector<std::string> all = {(testing::BinDir() / "carousel").string()};
  all.insert(all.end(), args.begin(), args.end());
  std::vector<char*> argv;
  argv.reserve(all.size() + 1);
  for (auto& a : all) argv.push_back(a.data());
  argv.push_back(nullptr);
  const int out = ::open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  const pid_t pid = ::fork();
  if (pid == 0) {
    // Only async-signal-safe calls between fork and exec.
    const rlimit limit{max_file_bytes, max_file_bytes};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    ::dup2(out, 1);
    ::dup2(out, 2);
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  ::close(out);
  return Wait(pid);
}

TEST(RunSessionTest, FullDiskAndUnwritableFolderAreClearErrorsAndLoseNothing) {
  TempDir dir;
  // Enough for the photos (about 15 kB each), not for the hull mesh.
  const auto log = dir / "log.txt";
  const int code = RunLimited(RunArgs(dir.path() / "out", /*small=*/true), 60 * 1024, log);
  const std::string text = testing::ReadBytes(log);
  EXPECT_EQ(code, kExitIoError) << text;
  EXPECT_THAT(text, ::testing::HasSubstr("File too large"));
  EXPECT_THAT(
      text, ::testing::HasSubstr("kill-test/recon/"));  // names the file that could not be written
  const auto session = dir.path() / "out" / "kill-test";
  const auto photos = Recorded(session);
  // Every photo (and its mask shot) was taken and recorded before the failure.
  EXPECT_EQ(photos.size(), 12u);
  for (const auto& [image, sha] : photos) EXPECT_EQ(FileSha256(session / image), sha) << image;
  // With room again, the session resumes without retaking anything.
  Progress progress;
  const RunResult result = ResumeSession(session, progress);
  EXPECT_EQ(result.photos_kept, 12);
  EXPECT_EQ(result.photos_taken, 0);
  EXPECT_TRUE(std::filesystem::exists(session / "model" / "model.glb"));

  // An output folder that cannot be created (a file stands in the way).
  testing::WriteBytes(dir / "blocker", "x");
  std::vector<std::string> args = RunArgs(dir.path() / "blocker" / "sessions", true);
  const int blocked = RunLimited(args, RLIM_INFINITY, log);
  EXPECT_EQ(blocked, kExitIoError) << testing::ReadBytes(log);
  EXPECT_THAT(testing::ReadBytes(log), ::testing::HasSubstr("blocker"));
}

// `carousel sim rig`: a studio in a box until interrupted, its rig file naming a turntable
// that answers through the firmware and a camera that answers through libgphoto2.
TEST(SimRigCommandTest, ServesItsRigFileUntilInterrupted) {
  TempDir dir;
  ::setenv("HOME", dir.path().c_str(), 1);  // libgphoto2's ~/.gphoto/settings
  const std::filesystem::path rig_file = dir / "rig.json";
  const pid_t pid =
      Spawn({"sim", "rig", "--cameras", "1", "--size", "240x160", "--views", "4", "--data",
             testing::SharedDataDir().string(), "--out", rig_file.string()});
  for (int i = 0; i < 600 && !std::filesystem::exists(rig_file); ++i)
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  ASSERT_TRUE(std::filesystem::exists(rig_file));
  const RigConfig rig = ReadRigConfig(rig_file);
  ASSERT_EQ(rig.cameras.size(), 1u);
  EXPECT_EQ(rig.capture.stops, 4);
  EXPECT_EQ(rig.cameras[0].serial, "EMU0");
  EXPECT_EQ(rig.cameras[0].calibration.width, 240);
  const testing::ShellResult table = testing::RunShell(
      testing::CarouselExecutable() + " turntable --port " + rig.turntable.port + " identify 2>&1");
  EXPECT_EQ(table.code, 0) << table.out;
  EXPECT_THAT(table.out, ::testing::HasSubstr("firmware"));
  const testing::ShellResult camera = testing::RunShell(
      testing::CarouselExecutable() + " camera summary --port " + rig.cameras[0].port + " 2>&1");
  EXPECT_EQ(camera.code, 0) << camera.out;
  EXPECT_THAT(camera.out, ::testing::HasSubstr("EMU0"));
  ::kill(pid, SIGINT);
  EXPECT_EQ(Wait(pid), 0);
}

}  // namespace
}  // namespace carousel::studio
