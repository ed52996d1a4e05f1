#include "carousel/studio/cli.h"

#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <iomanip>
#include <iostream>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "carousel/calib/intrinsics.h"
#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/logging.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/progress.h"
#include "carousel/core/timer.h"
#include "carousel/core/version.h"
#include "carousel/studio/calibrate_session.h"
#include "carousel/studio/camera_command.h"
#include "carousel/studio/import.h"
#include "carousel/studio/pipeline.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/run_session.h"
#include "carousel/studio/self_check.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/studio/terminal_progress.h"
#include "carousel/studio/texture_session.h"
#include "carousel/studio/turntable_command.h"
#include "carousel/texture/atlas.h"

namespace carousel::studio {
namespace {

// Ctrl-C cancels the running stage through its token (lock-free atomic store: signal-safe).
CancellationToken* g_interrupt_token = nullptr;
extern "C" void OnInterrupt(int) {
  if (g_interrupt_token != nullptr) g_interrupt_token->Cancel();
}

class InterruptScope {
 public:
  explicit InterruptScope(CancellationToken* token) {
    g_interrupt_token = token;
    previous_ = std::signal(SIGINT, OnInterrupt);
  }
  ~InterruptScope() {
    std::signal(SIGINT, previous_);
    g_interrupt_token = nullptr;
  }
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;

 private:
  void (*previous_)(int) = SIG_DFL;
};

// The shared test data: $CAROUSEL_SHARED_DATA_DIR, else the folder this build was configured
// with (../shared/data beside the checkout).
std::filesystem::path DefaultDataDir() {
  if (const char* env = std::getenv("CAROUSEL_SHARED_DATA_DIR"); env != nullptr && *env) {
    return env;
  }
  return CAROUSEL_DEFAULT_SHARED_DATA_DIR;
}

// "5184x3456" -> width, height.
void ParseSize(const std::string& text, int* width, int* height) {
  const std::size_t x = text.find('x');
  try {
    std::size_t used_w = 0, used_h = 0;
    *width = std::stoi(text.substr(0, x), &used_w);
    const std::string rest = x == std::string::npos ? "" : text.substr(x + 1);
    *height = std::stoi(rest, &used_h);
    if (used_w != x || used_h != rest.size()) throw std::invalid_argument(text);
  } catch (const std::logic_error&) {
    throw InvalidArgument("--size must look like 5184x3456, got '" + text + "'");
  }
}

// "white", "grey", "green", "black" or "#rrggbb" -> sRGB 0..1.
Eigen::Vector3d ParseColour(const std::string& text) {
  if (text == "white") return {0.96, 0.96, 0.96};
  if (text == "grey" || text == "gray") return {0.5, 0.5, 0.5};
  if (text == "green") return {0.1, 0.65, 0.25};
  if (text == "black") return {0.03, 0.03, 0.03};
  if (text.size() == 7 && text[0] == '#') {
    try {
      Eigen::Vector3d colour;
      for (int c = 0; c < 3; ++c) {
        std::size_t used = 0;
        colour[c] = std::stoi(text.substr(1 + 2 * c, 2), &used, 16) / 255.0;
        if (used != 2) throw std::invalid_argument(text);
      }
      return colour;
    } catch (const std::logic_error&) {
    }
  }
  throw InvalidArgument("--backdrop must be white, grey, green, black or #rrggbb, got '" + text +
                        "'");
}

// A Progress drawn on stderr (a bar on a terminal, lines otherwise), cancelled by Ctrl-C.
struct CliProgress {
  CancellationToken token;
  InterruptScope interrupt{&token};
  TerminalProgress bar;
  Progress progress;
  explicit CliProgress(std::ostream& err)
      : bar(err, ::isatty(STDERR_FILENO) == 1 && &err == &std::cerr),
        progress(bar.Listener(), token) {}
};

struct SimCaptureArgs {
  SimCaptureOptions options;
  std::string size = "5184x3456";
  std::string backdrop;
  std::filesystem::path out;
  double yaw_deg = 0.0;
  bool unlit = false;
};

int RunSimCapture(SimCaptureArgs& args, std::ostream& out, std::ostream& err) {
  SimCaptureOptions& options = args.options;
  ParseSize(args.size, &options.rig.width, &options.rig.height);
  if (!args.backdrop.empty()) {
    const Eigen::Vector3d colour = ParseColour(args.backdrop);
    options.render.backdrop_top = colour;
    options.render.backdrop_bottom = 0.9 * colour;
  }
  options.placement.yaw_rad = args.yaw_deg * 3.14159265358979323846 / 180.0;
  options.render.lit = !args.unlit;
  CliProgress cli(err);
  const SimCaptureResult result = SimulateCapture(options, args.out, cli.progress);
  out << "session " << result.session.string() << ": " << result.views << " views, " << std::fixed
      << std::setprecision(1) << result.render_seconds << " s rendering\n";
  return kExitOk;
}

struct ImportArgs {
  ImportOptions options;
  std::string format = "middlebury";
  std::string link = "copy";
  std::filesystem::path out;
};

int RunImport(ImportArgs& args, std::ostream& out, std::ostream& err) {
  if (args.format == "middlebury") {
    args.options.format = ImportOptions::Format::kMiddlebury;
  } else if (args.format == "colmap") {
    args.options.format = ImportOptions::Format::kColmap;
  } else {
    throw InvalidArgument("--format must be middlebury or colmap, got '" + args.format + "'");
  }
  if (args.link == "copy") {
    args.options.transfer = ImportOptions::Transfer::kCopy;
  } else if (args.link == "hard") {
    args.options.transfer = ImportOptions::Transfer::kHardLink;
  } else if (args.link == "symbolic") {
    args.options.transfer = ImportOptions::Transfer::kSymlink;
  } else {
    throw InvalidArgument("--link must be copy, hard or symbolic, got '" + args.link + "'");
  }
  CliProgress cli(err);
  const ImportResult result = ImportDataset(args.options, args.out, cli.progress);
  out << "session " << result.session.string() << ": " << result.views << " views imported\n";
  return kExitOk;
}

struct ReconstructArgs {
  ReconstructOptions options;
  std::filesystem::path session;
  std::string method = "key";
};

void PrintReconstruct(const std::filesystem::path& s, const ReconstructResult& result,
                      std::ostream& out) {
  out << std::fixed << std::setprecision(2) << "masks " << (s / "masks").string() << ": "
      << result.views << " silhouettes (" << result.seconds_silhouettes << " s)\n"
      << "hull " << (s / "recon/hull.ply").string() << ": " << result.hull_faces << " faces, "
      << std::setprecision(3) << result.voxel_size_m * 1e3 << " mm voxels (" << std::setprecision(2)
      << result.seconds_hull << " s)\n"
      << "mesh " << (s / "recon/mesh.ply").string() << ": " << result.mesh_faces << " faces ("
      << result.seconds_mesh << " s)\n";
  if (!result.agreement.empty()) {
    double mean = 0.0;
    const recon::SilhouetteAgreement* worst = &result.agreement.front();
    for (const recon::SilhouetteAgreement& a : result.agreement) {
      mean += a.mean_deviation_px / static_cast<double>(result.agreement.size());
      if (a.mean_deviation_px > worst->mean_deviation_px) worst = &a;
    }
    out << "mesh vs silhouettes: outline deviation " << mean << " px on average, worst "
        << worst->view << " " << worst->mean_deviation_px << " px (IoU " << std::setprecision(4)
        << worst->iou << ")\n";
  }
}

int RunReconstruct(ReconstructArgs& args, std::ostream& out, std::ostream& err) {
  args.options.silhouettes.method = recon::ParseSilhouetteMethod(args.method);
  CliProgress cli(err);
  PrintReconstruct(args.session, ReconstructSession(args.session, args.options, cli.progress), out);
  return kExitOk;
}

struct TextureArgs {
  TextureSessionOptions options;
  std::filesystem::path session;
  std::string packing = "obb";
  bool no_blend = false, no_correction = false, no_gain = false;
};

void PrepareTexture(TextureArgs& args) {
  args.options.atlas.packing.mode = texture::ParsePackingMode(args.packing);
  args.options.transfer.blend = !args.no_blend;
  args.options.grouping.correction = !args.no_correction;
  args.options.transfer.gain = !args.no_gain;
}

void PrintTexture(const std::filesystem::path& session, const TextureSessionResult& r,
                  std::ostream& out) {
  out << std::fixed << std::setprecision(2) << "model " << r.files.obj.string() << ", "
      << r.files.glb.string() << ": " << r.faces << " faces, " << r.charts << " charts, " << r.size
      << "^2 texture from " << r.views << " views\n"
      << "grouping: " << r.grouping.corrected_faces << " faces moved off the background, "
      << r.grouping.uncorrectable_faces << " with background in every view, "
      << r.grouping.island_faces_switched << " island faces switched, " << r.grouping.unseen_faces
      << " seen by no view (filled from neighbours)\n"
      << "texel density: " << std::setprecision(1) << 100.0 * r.dense_fraction
      << " % of faces get at least one texel per photo pixel; " << r.blended_texels
      << " texels blended across seams\n"
      << std::setprecision(2) << "time: grouping " << r.seconds_grouping << " s, atlas "
      << r.seconds_atlas << " s, transfer " << r.seconds_transfer << " s, export "
      << r.seconds_export << " s (PNG " << r.files.seconds_png << " s, GLB " << r.files.seconds_glb
      << " s), total " << r.seconds_total << " s; report "
      << (session / "model" / "report.json").string() << "\n";
  for (const HeldOutScore& h : r.held_out)
    out << "held-out view " << h.view << ": PSNR " << h.psnr_db << " dB, SSIM "
        << std::setprecision(4) << h.ssim << ", silhouette IoU " << h.mask_agreement
        << std::setprecision(2) << "\n";
  if (!r.held_out.empty())
    out << "held-out mean: PSNR " << r.mean_psnr_db << " dB, SSIM " << std::setprecision(4)
        << r.mean_ssim << "\n";
}

int RunTexture(TextureArgs& args, std::ostream& out, std::ostream& err) {
  PrepareTexture(args);
  CliProgress cli(err);
  const TextureSessionResult result = TextureSession(args.session, args.options, cli.progress);
  PrintTexture(args.session, result, out);
  return kExitOk;
}

struct RunArgs {
  RunOptions options;
  bool sim = false;
  std::filesystem::path rig;  // a rig file: the hardware backends
  std::filesystem::path resume;
  std::string size = "5184x3456";
  bool calibration = false;  // a calibration session
  CalibrationPlan plan;
};

// Hardware calibration: the operator places the board; Enter continues (on a terminal).
void AskForBoardPlacement(int index, int placements, std::ostream& err) {
  err << "\nboard placement " << index + 1 << " of " << placements
      << (index == 0 ? ": stand the board on the turntable"
                     : ": lean the board differently (e.g. further back) without moving the "
                       "cameras")
      << (::isatty(STDIN_FILENO) ? ", then press Enter" : "") << std::endl;
  if (::isatty(STDIN_FILENO)) {
    std::string line;
    std::getline(std::cin, line);
  }
}

void PrintCalibration(const CalibrateSessionResult& r, std::ostream& out) {
  const calib::RigCalibration& c = r.result.calibration;
  int used = 0;
  for (const calib::RigPhotoReport& p : r.result.photos) used += p.used;
  out << std::fixed << std::setprecision(3) << "rig calibration " << r.file.string() << ": "
      << c.cameras.size() << " camera(s), " << used << " of " << r.result.photos.size()
      << " photos, " << c.corners << " corners, " << c.rms_px << " px RMS\n";
  for (const calib::RigCameraCalibration& camera : c.cameras) {
    const CameraModel& m = camera.camera;
    const Eigen::Vector3d centre = m.Centre();
    out << std::setprecision(2) << "  " << camera.name << ": fx " << m.fx << " fy " << m.fy
        << " cx " << m.cx << " cy " << m.cy << " k1 " << std::setprecision(4) << m.distortion.k1
        << " k2 " << m.distortion.k2 << std::setprecision(1) << "; centre (" << centre.x() * 1e3
        << ", " << centre.y() * 1e3 << ", " << centre.z() * 1e3 << ") mm, " << std::setprecision(1)
        << std::hypot(centre.x(), centre.y()) * 1e3 << " mm from the axis; " << camera.views
        << " photos, " << std::setprecision(3) << camera.rms_px << " px RMS\n";
  }
  out << std::setprecision(4) << "  turntable: observed/reported angle " << c.angle_scale
      << ", largest deviation " << std::setprecision(3) << c.angle_residual_max_deg << " deg\n";
  for (const std::string& w : r.result.warnings) out << "  warning: " << w << "\n";
}

int RunOneButton(RunArgs& args, std::ostream& out, std::ostream& err) {
  CliProgress cli(err);
  RunResult result;
  if (args.calibration) {
    if (args.options.product.empty()) args.options.product = "rig-calibration";
    args.options.calibration = args.plan;
    args.options.place_board = [&err](int index, int placements) {
      AskForBoardPlacement(index, placements, err);
    };
  }
  if (!args.resume.empty()) {
    result = ResumeSession(args.resume, cli.progress);
  } else if (args.sim) {
    ParseSize(args.size, &args.options.sim.rig.width, &args.options.sim.rig.height);
    CAROUSEL_THROW_IF(args.options.product.empty(), InvalidArgument,
                      "carousel run: --product SKU is required");
    result = RunSession(args.options, cli.progress);
  } else if (!args.rig.empty()) {
    CAROUSEL_THROW_IF(args.options.product.empty(), InvalidArgument,
                      "carousel run: --product SKU is required");
    args.options.hardware = ReadRigConfig(args.rig);
    result = RunSession(args.options, cli.progress);
  } else {
    err << "carousel run: say where to capture: --sim (the simulated rig), --rig RIG.json "
           "(the studio's turntable and cameras), or --resume SESSION\n";
    return kExitUsage;
  }
  if (result.calibration || std::filesystem::exists(result.session / "calibration")) {
    out << "session " << result.session.string() << ": " << result.photos_taken << " photos taken, "
        << result.photos_kept << " kept from before, " << result.photos_retaken << " retaken\n";
    if (result.calibration) PrintCalibration(*result.calibration, out);
    out << "calibration: " << (result.session / "calibration" / "rig_calibration.json").string()
        << " (carousel run --calibration-file FILE, or \"calibration_file\" in rig.json)\n";
    return kExitOk;
  }
  out << "session " << result.session.string() << ": " << result.photos_taken << " photos taken, "
      << result.photos_kept << " kept from before, " << result.photos_adopted << " adopted, "
      << result.photos_retaken << " retaken; reconstruct "
      << (result.reconstructed ? "ran" : "was current") << ", texture "
      << (result.textured ? "ran" : "was current") << "\n";
  if (result.photos_taken > 0 && result.max_trigger_skew_ms > 0)
    out << std::fixed << std::setprecision(1) << "trigger skew between cameras: at most "
        << result.max_trigger_skew_ms << " ms\n";
  if (result.textured) PrintTexture(result.session, result.texture, out);
  const auto model = result.session / "model";
  out << "model: " << (model / "model.obj").string() << " (+ model.mtl, model.png), "
      << (model / "model.glb").string() << "\n";
  return kExitOk;
}

struct CalibrateArgs {
  // intrinsics
  std::vector<std::filesystem::path> images;
  calib::IntrinsicsOptions intrinsics;
  // rig
  std::filesystem::path session;
  CalibrateSessionOptions rig;
  double board_height_m = -1.0;
  // board
  int pixels_per_square = 200;
  // all
  std::string board;
  std::filesystem::path out;
};

int RunCalibrateIntrinsics(CalibrateArgs& args, std::ostream& out, std::ostream& err) {
  CAROUSEL_THROW_IF(args.board.empty(), InvalidArgument,
                    "carousel calibrate intrinsics: --board is required");
  CAROUSEL_THROW_IF(args.out.empty(), InvalidArgument,
                    "carousel calibrate intrinsics: --out FILE is required");
  const calib::BoardSpec board = calib::BoardSpec::Parse(args.board);
  CliProgress cli(err);
  const calib::IntrinsicsResult r =
      calib::CalibrateIntrinsics(args.images, board, args.intrinsics, cli.progress);
  calib::WriteOpenCvIntrinsics(args.out, r, board);
  for (const calib::ViewReport& v : r.views) {
    out << "  " << v.name << ": "
        << (v.used ? "used, " + std::to_string(v.corners) + " corners" : "refused: " + v.reason);
    if (v.used) out << std::fixed << std::setprecision(3) << ", " << v.rms_px << " px RMS";
    out << "\n";
  }
  const CameraModel& c = r.camera;
  out << std::fixed << std::setprecision(3) << "intrinsics " << args.out.string() << ": "
      << r.UsedViews() << " of " << r.views.size() << " photos, " << r.rms_px << " px RMS; fx "
      << c.fx << " fy " << c.fy << " cx " << c.cx << " cy " << c.cy << ", distortion "
      << std::setprecision(5) << c.distortion.k1 << " " << c.distortion.k2 << " " << c.distortion.p1
      << " " << c.distortion.p2 << " " << c.distortion.k3 << "; " << std::setprecision(0)
      << 100.0 * r.cell_coverage << " % of the image covered\n";
  for (const std::string& w : r.warnings) out << "  warning: " << w << "\n";
  return kExitOk;
}

int RunCalibrateRig(CalibrateArgs& args, std::ostream& out, std::ostream& err) {
  args.rig.board = args.board;
  if (args.board_height_m >= 0) args.rig.board_origin_height_m = args.board_height_m;
  CliProgress cli(err);
  PrintCalibration(CalibrateSession(args.session, args.rig, args.out, cli.progress), out);
  return kExitOk;
}

int RunCalibrateBoard(CalibrateArgs& args, std::ostream& out) {
  CAROUSEL_THROW_IF(args.board.empty() || args.out.empty(), InvalidArgument,
                    "carousel calibrate board: --board and --out are required");
  const calib::BoardSpec board = calib::BoardSpec::Parse(args.board);
  const calib::BoardImage drawn =
      calib::DrawBoard(board, args.pixels_per_square, args.pixels_per_square / 2);
  WriteImage(args.out, drawn.image);
  const double dpi = args.pixels_per_square / (board.square_m / 0.0254);
  out << std::fixed << std::setprecision(1) << "board " << args.out.string() << ": "
      << drawn.image.cols << "x" << drawn.image.rows << " px; print at " << dpi
      << " dpi for squares of " << board.square_m * 1e3 << " mm, then measure them\n";
  return kExitOk;
}

struct AtlasArgs {
  texture::AtlasOptions options;
  std::filesystem::path mesh;
  std::filesystem::path out;
  std::filesystem::path charts_image;
  std::string packing = "obb";
};

int RunTextureAtlas(AtlasArgs& args, std::ostream& out, std::ostream& err) {
  args.options.packing.mode = texture::ParsePackingMode(args.packing);
  CliProgress cli(err);
  Mesh mesh = ReadMesh(args.mesh, {.read_uvs = false});
  Stopwatch total;
  const texture::AtlasResult result = texture::BuildAtlas(&mesh, args.options, cli.progress);
  const double seconds = total.ElapsedSeconds() - result.seconds_quality;
  WriteMesh(mesh, args.out);
  if (!args.charts_image.empty())
    WriteImage(args.charts_image,
               texture::DrawCharts(mesh, std::min(args.options.packing.size, 4096)));
  const texture::AtlasQuality& q = result.quality;
  out << std::fixed << std::setprecision(3) << "atlas " << args.out.string() << ": "
      << mesh.n_faces() << " faces, " << q.charts << " charts (" << result.charts_split
      << " split to flatten validly), " << texture::PackingModeName(args.options.packing.mode)
      << " packing in " << args.options.packing.size << "x" << args.options.packing.size << "\n"
      << "stretch: L2 " << std::setprecision(4) << q.l2_stretch << " (worst face "
      << std::setprecision(2) << q.max_face_stretch << "), angle distortion "
      << q.angle_distortion_deg << " deg\n"
      << "utilization " << std::setprecision(1) << 100.0 * q.utilization << " %, "
      << std::setprecision(0) << q.texels_per_metre << " texels per metre\n"
      << std::setprecision(3) << "time " << seconds << " s: charts " << result.seconds_charts
      << " s, flattening " << result.seconds_parameterization << " s, packing "
      << result.seconds_packing << " s\n";
  if (!q.Valid()) {
    err << "carousel texture atlas: the atlas failed its checks (flipped " << q.flipped_faces
        << ", overlapping texels " << q.overlapping_texels << ", gutter " << q.gutter_violations
        << ")\n";
    return kExitFailure;
  }
  return kExitOk;
}

int RunSelfCheckCommand(const SelfCheckOptions& options, std::ostream& out, std::ostream& err) {
  CliProgress cli(err);
  const SelfCheckResult result = RunSelfCheck(options, cli.progress);
  for (const SelfCheckItem& item : result.items) {
    const char* status = item.status == SelfCheckItem::Status::kPassed    ? "PASS"
                         : item.status == SelfCheckItem::Status::kSkipped ? "SKIP"
                                                                          : "FAIL";
    out << status << "  " << item.name << ": " << item.detail << '\n';
  }
  out << (result.AllPassed() ? "self-check passed" : "self-check FAILED") << '\n';
  return result.AllPassed() ? kExitOk : kExitFailure;
}

int ExitCodeFor(const std::exception& error) {
  if (dynamic_cast<const Cancelled*>(&error)) return kExitCancelled;
  if (dynamic_cast<const InvalidArgument*>(&error)) return kExitUsage;
  if (dynamic_cast<const FormatError*>(&error)) return kExitDataError;
  if (dynamic_cast<const IoError*>(&error)) return kExitIoError;
  if (dynamic_cast<const DeviceError*>(&error)) return kExitDeviceError;
  if (dynamic_cast<const ProtocolError*>(&error)) return kExitProtocol;
  return kExitFailure;
}

struct ProcessArgs {
  std::vector<std::filesystem::path> sessions;
  bool force = false;
  int faces = ReconstructOptions{}.mesh.target_faces;
  std::vector<int> exclude_views;
};

// Every session in turn; a failing one is reported and the batch goes on. The exit code is
// the first failure's (0 when every session is processed).
int RunProcess(ProcessArgs& args, std::ostream& out, std::ostream& err) {
  ProcessOptions options;
  options.force = args.force;
  options.reconstruct.mesh.target_faces = args.faces;
  options.texture.grouping.exclude_views = args.exclude_views;
  int status = kExitOk;
  int failed = 0;
  for (const std::filesystem::path& session : args.sessions) {
    out << "session " << session.string() << "\n";
    try {
      CliProgress cli(err);
      const ProcessResult result = ProcessSession(session, options, cli.progress);
      if (result.reconstruct) {
        PrintReconstruct(session, *result.reconstruct, out);
      } else {
        out << "reconstruct: current, skipped\n";
      }
      if (result.texture) {
        PrintTexture(session, *result.texture, out);
      } else {
        out << "texture: current, skipped\n";
      }
    } catch (const std::exception& e) {
      err << "carousel process: " << session.string() << ": error: " << e.what() << '\n';
      if (status == kExitOk) status = ExitCodeFor(e);
      ++failed;
      if (dynamic_cast<const Cancelled*>(&e)) break;
    }
  }
  if (args.sessions.size() > 1) {
    out << args.sessions.size() - static_cast<std::size_t>(failed) << " of " << args.sessions.size()
        << " sessions processed";
    if (failed > 0) out << ", " << failed << " failed";
    out << "\n";
  }
  return status;
}

}  // namespace

int RunCli(int argc, const char* const* argv, std::ostream& out, std::ostream& err) {
  CLI::App app{"Carousel: one button from a product on a turntable to a textured 3D model.",
               "carousel"};
  app.set_version_flag("--version",
                       std::string("carousel ") + kVersion + " (" + LibraryVersions() + ")");
  app.require_subcommand(1);
  std::string log_level = "info";
  std::string log_file;
  app.add_option("--log-level", log_level, "debug, info, warn, error or off")
      ->capture_default_str();
  app.add_option("--log-file", log_file, "also append the log to this file");
  app.footer(
      "Exit codes: 0 ok, 1 failure, 64 usage, 65 malformed input file, 69 not built yet,\n"
      "74 file I/O error, 75 device error, 76 protocol error, 130 cancelled.");

  SelfCheckOptions self_check;
  self_check.data_dir = DefaultDataDir();
  CLI::App* self_check_command =
      app.add_subcommand("self-check",
                         "check this build: camera model vs OpenCV, image and "
                         "mesh files, shared test data");
  self_check_command->add_option("--data", self_check.data_dir,
                                 "shared test data folder (default: $CAROUSEL_SHARED_DATA_DIR)");
  self_check_command->add_option("--scratch", self_check.scratch_dir,
                                 "folder for temporary files (default: the system's)");
  self_check_command
      ->add_option("--points", self_check.points, "random points in the camera-model check")
      ->capture_default_str();

  // carousel sim capture
  CLI::App* sim_command =
      app.add_subcommand("sim", "simulated rig: render capture sessions of product models");
  sim_command->require_subcommand(1);
  SimCaptureArgs sim_capture;
  sim_capture.options.data_dir = DefaultDataDir();
  CLI::App* capture = sim_command->add_subcommand(
      "capture", "photograph a scene on the simulated turntable into a new session folder");
  SimCaptureOptions& sc = sim_capture.options;
  capture->add_option("--scene", sc.scene, "shoe, bottle, avocado, duck, or a .gltf/.glb/.obj file")
      ->capture_default_str();
  capture->add_option("--out", sim_capture.out, "session folder to create")->required();
  capture->add_option("--views", sc.stops, "turntable stops per camera")->capture_default_str();
  capture->add_option("--size", sim_capture.size, "image size WxH")->capture_default_str();
  capture
      ->add_option("--elevations", sc.rig.elevations_deg,
                   "camera elevations in degrees, one camera each (e.g. 15,35,60)")
      ->delimiter(',')
      ->capture_default_str();
  capture->add_option("--focal-mm", sc.rig.focal_length_mm, "lens focal length (APS-C sensor)")
      ->capture_default_str();
  capture
      ->add_option("--distance", sc.rig.distance_m,
                   "camera distance in metres (0: frame the object)")
      ->capture_default_str();
  capture->add_option("--noise", sc.render.noise_sigma, "sensor noise, 8-bit levels")
      ->capture_default_str();
  capture->add_option("--seed", sc.render.seed, "noise seed")->capture_default_str();
  capture->add_option("--jpeg-quality", sc.jpeg_quality, "JPEG quality of the photos")
      ->capture_default_str();
  capture
      ->add_option("--samples", sc.render.samples_per_axis,
                   "anti-aliasing samples per pixel and axis (1..4)")
      ->capture_default_str();
  capture->add_option("--backdrop", sim_capture.backdrop, "white, grey, green, black or #rrggbb");
  capture
      ->add_option("--plate-radius", sc.render.plate_radius_m,
                   "turntable plate radius in metres (0: no plate)")
      ->capture_default_str();
  capture
      ->add_option("--target-height", sc.placement.target_height_m,
                   "scale the model to this height in metres (0: as authored)")
      ->capture_default_str();
  capture->add_option("--scale", sc.placement.scale, "scale factor when no --target-height")
      ->capture_default_str();
  capture->add_option("--yaw-deg", sim_capture.yaw_deg, "turn the model on the plate first")
      ->capture_default_str();
  capture->add_flag("--unlit", sim_capture.unlit, "no lighting: render the albedo");
  capture->add_option("--product", sc.product, "product name for the manifest");
  capture->add_option("--data", sc.data_dir, "shared test data folder (for model names)");
  capture->add_flag("--force", sc.overwrite, "replace an existing session folder");

  // carousel import
  ImportArgs import_args;
  CLI::App* import_command = app.add_subcommand(
      "import", "turn a calibrated dataset (Middlebury, COLMAP text) into a session folder");
  import_command
      ->add_option("source", import_args.options.source,
                   "Middlebury *_par.txt, or a COLMAP sparse text model folder")
      ->required();
  import_command->add_option("--format", import_args.format, "middlebury or colmap")
      ->capture_default_str();
  import_command->add_option("--images", import_args.options.images_dir,
                             "folder of the photos (default: beside the par file)");
  import_command->add_option("--out", import_args.out, "session folder to create")->required();
  import_command->add_option("--link", import_args.link, "copy, hard or symbolic")
      ->capture_default_str();
  import_command->add_option("--product", import_args.options.product, "product name");
  import_command->add_flag("--force", import_args.options.overwrite,
                           "replace an existing session folder");

  // carousel reconstruct
  ReconstructArgs reconstruct;
  CLI::App* reconstruct_command =
      app.add_subcommand("reconstruct", "silhouettes, visual hull and optimized mesh of a session");
  reconstruct_command->add_option("session", reconstruct.session, "session folder")->required();
  reconstruct_command
      ->add_option("--faces", reconstruct.options.mesh.target_faces, "faces of the optimized mesh")
      ->capture_default_str();
  reconstruct_command
      ->add_option("--resolution", reconstruct.options.hull.resolution,
                   "hull voxels along the object's longest side (0 = from --voxel-px)")
      ->capture_default_str();
  reconstruct_command
      ->add_option("--voxel-px", reconstruct.options.hull.voxel_px,
                   "hull voxel size in pixels of the sharpest view, when no --resolution ...")
      ->capture_default_str();
  reconstruct_command
      ->add_option("--max-resolution", reconstruct.options.hull.max_resolution,
                   "... but at most this many voxels along the object's longest side")
      ->capture_default_str();
  reconstruct_command
      ->add_option("--method", reconstruct.method,
                   "silhouettes: key (backdrop colour) or difference (background plates in "
                   "backgrounds/cam<C>.jpg)")
      ->capture_default_str();
  reconstruct_command
      ->add_option("--plate-radius-m", reconstruct.options.silhouettes.plate_radius_m,
                   "turntable plate radius to remove from the silhouettes (0 = none)")
      ->capture_default_str();

  // carousel run: the one-button session
  RunArgs run_args;
  run_args.options.sim.data_dir = DefaultDataDir();
  CLI::App* run_command =
      app.add_subcommand("run", "the one-button session: capture, reconstruct, texture, export");
  run_command->add_flag("--sim", run_args.sim, "on the simulated rig");
  run_command->add_option("--resume", run_args.resume, "continue a killed or failed session");
  run_command->add_option("--rig", run_args.rig,
                          "rig file (turntable port, cameras, calibration, capture plan): "
                          "capture with the studio's hardware");
  run_command->add_option("--product", run_args.options.product,
                          "product SKU (names the session folder)");
  run_command->add_option("--out", run_args.options.out, "folder of the sessions")
      ->capture_default_str();
  run_command
      ->add_option("--scene", run_args.options.sim.scene,
                   "simulated product: shoe, bottle, avocado, duck or a model file")
      ->capture_default_str();
  run_command->add_option("--views", run_args.options.sim.stops, "turntable stops per camera")
      ->capture_default_str();
  run_command->add_option("--size", run_args.size, "image size WxH")->capture_default_str();
  run_command
      ->add_option("--elevations", run_args.options.sim.rig.elevations_deg,
                   "camera elevations, degrees")
      ->delimiter(',')
      ->capture_default_str();
  run_command
      ->add_option("--exclude-views", run_args.options.texture.grouping.exclude_views,
                   "views held out of the texture and scored")
      ->delimiter(',');
  run_command->add_option("--data", run_args.options.sim.data_dir,
                          "shared test data folder (model names)");
  run_command->add_flag("--force", run_args.options.force,
                        "start over (the old session is kept beside it)");
  run_command->add_flag("--calibration", run_args.calibration,
                        "a calibration session: the table turns with the board on it (once per "
                        "placement), the photos become calibration/rig_calibration.json");
  run_command->add_option("--board", run_args.plan.board, "calibration: the board")
      ->capture_default_str();
  run_command
      ->add_option("--placements", run_args.plan.placements,
                   "calibration: passes of the table, the board placed anew for each")
      ->capture_default_str();
  run_command
      ->add_option("--leans", run_args.plan.sim_leans_deg,
                   "calibration, simulated rig: the board's lean back from vertical per pass, deg")
      ->delimiter(',')
      ->capture_default_str();
  run_command->add_option("--board-height", run_args.plan.board_origin_height_m,
                          "calibration on hardware: height of the board's origin (first corner) "
                          "above the plate in the first placement, metres");
  run_command->add_option("--calibration-file", run_args.options.calibration_file,
                          "the photos' cameras from this rig calibration (carousel run "
                          "--calibration) instead of the rig's own");
  run_command->get_option("--resume")->excludes("--sim");
  run_command->get_option("--rig")->excludes("--sim");
  run_command->get_option("--rig")->excludes("--resume");

  // carousel calibrate intrinsics|rig|board
  CalibrateArgs calibrate;
  CLI::App* calibrate_command = app.add_subcommand(
      "calibrate", "camera intrinsics from board photos, the rig from a calibration session");
  calibrate_command->require_subcommand(1);
  CLI::App* intrinsics_command = calibrate_command->add_subcommand(
      "intrinsics", "one camera's intrinsics and lens distortion from photos of a board");
  intrinsics_command->add_option("images", calibrate.images, "photos of the board")->required();
  intrinsics_command
      ->add_option("--board", calibrate.board,
                   "chessboard:COLSxROWS:SQUARE_M or charuco:SXxSY:SQUARE_M:MARKER_M:DICT")
      ->required();
  intrinsics_command->add_option("--out", calibrate.out, "OpenCV YAML to write")->required();
  intrinsics_command->add_flag("--fix-aspect", calibrate.intrinsics.fix_aspect_ratio, "fx = fy");
  intrinsics_command->add_flag("--fix-k3", calibrate.intrinsics.fix_k3, "k3 = 0");
  intrinsics_command->add_flag("--zero-tangential", calibrate.intrinsics.zero_tangential,
                               "p1 = p2 = 0");
  CLI::App* rig_calibrate_command = calibrate_command->add_subcommand(
      "rig", "the turntable axis and every camera's pose (and lens) from a calibration session");
  rig_calibrate_command->add_option("session", calibrate.session, "session folder")->required();
  rig_calibrate_command->add_option(
      "--out", calibrate.out,
      "rig calibration file (default SESSION/calibration/rig_calibration.json)");
  rig_calibrate_command->add_option("--board", calibrate.board,
                                    "the board (default: the calibration session's)");
  rig_calibrate_command->add_option(
      "--board-height", calibrate.board_height_m,
      "height of the first placement's board origin above the plate, metres");
  rig_calibrate_command->add_option("--stops-per-placement", calibrate.rig.stops_per_placement,
                                    "stops per board placement (default: the session's plan)");
  rig_calibrate_command
      ->add_option("--intrinsics", calibrate.rig.intrinsics,
                   "per camera, OpenCV YAML intrinsics calibrated beforehand (empty: none)")
      ->delimiter(',');
  rig_calibrate_command->add_flag(
      "--free-k3", [&calibrate](std::int64_t) { calibrate.rig.rig.fix_k3 = false; },
      "estimate k3 too (wide lenses; needs the board near every image corner)");
  rig_calibrate_command->add_flag(
      "--keep-intrinsics",
      [&calibrate](std::int64_t) { calibrate.rig.rig.refine_intrinsics = false; },
      "hold the given intrinsics fixed");
  rig_calibrate_command
      ->add_option("--max-angle-error", calibrate.rig.rig.max_angle_error_deg,
                   "largest disagreement of a reported table angle with the board, degrees")
      ->capture_default_str();
  CLI::App* board_command =
      calibrate_command->add_subcommand("board", "draw a board to print (PNG)");
  board_command->add_option("--board", calibrate.board, "the board")->required();
  board_command->add_option("--out", calibrate.out, "PNG to write")->required();
  board_command->add_option("--px-per-square", calibrate.pixels_per_square, "pixels per square")
      ->capture_default_str();

  // carousel turntable
  TurntableArgs turntable;
  CLI::App* turntable_command = app.add_subcommand(
      "turntable", "identify, home, move, trigger and configure the turntable controller");
  turntable_command->add_option("--port", turntable.port, "serial port, e.g. /dev/ttyACM0")
      ->required();
  turntable_command
      ->add_option("action", turntable.action, "identify, home, goto, status, trigger or config")
      ->required();
  turntable_command->add_option("degrees", turntable.degrees, "goto: absolute table angle");
  turntable_command->add_option("--timeout", turntable.timeout_s, "home/goto timeout, seconds")
      ->capture_default_str();
  turntable_command->add_option("--cameras", turntable.cameras, "trigger: cameras 0..3")
      ->delimiter(',')
      ->capture_default_str();
  turntable_command->add_flag("--focus", turntable.focus, "trigger: focus instead of shutter");
  turntable_command->add_option("--ms", turntable.duration_ms, "trigger: pulse length, ms")
      ->capture_default_str();
  turntable_command->add_option("--steps-per-rev", turntable.steps_per_rev, "config: motor steps");
  turntable_command->add_option("--microsteps", turntable.microsteps, "config: microstepping");
  turntable_command->add_option("--gear", turntable.gear,
                                "config: NUM:DEN, table revs = motor revs x DEN / NUM");
  turntable_command->add_option("--max-speed", turntable.max_speed, "config: microsteps/s");
  turntable_command->add_option("--acceleration", turntable.acceleration, "config: microsteps/s^2");
  turntable_command->add_option("--homing-speed", turntable.homing_speed, "config: microsteps/s");
  turntable_command->add_option("--backlash", turntable.backlash, "config: microsteps");

  // carousel camera
  CameraArgs camera_args;
  CLI::App* camera_command = app.add_subcommand(
      "camera", "list, inspect, configure and fire cameras (libgphoto2: USB or ptpip:)");
  camera_command
      ->add_option("action", camera_args.action, "list, watch, summary, config or capture")
      ->required();
  camera_command->add_option("--port", camera_args.port,
                             "libgphoto2 port: usb:BUS,DEV or ptpip:HOST:PORT:PORT "
                             "(default: the only camera found)");
  camera_command->add_option("--model", camera_args.model,
                             "libgphoto2 model (default: detected; \"PTP/IP Camera\" for ptpip:)");
  camera_command->add_option("--camera", camera_args.model, "same as --model (gphoto2's name)");
  camera_command->add_option("--set", camera_args.set,
                             "config: NAME=VALUE, e.g. iso=400, aperture=f/8 (repeatable)");
  camera_command->add_option("--out", camera_args.out, "capture: folder for the photos")
      ->capture_default_str();
  camera_command->add_option("--count", camera_args.count, "capture: photos to take")
      ->capture_default_str();
  camera_command->add_flag("--delete", camera_args.delete_after,
                           "capture: delete each photo from the camera once saved");
  camera_command->add_option("--seconds", camera_args.seconds,
                             "watch: how long to watch, 0 = until Ctrl-C");
  camera_command->add_option("--timeout", camera_args.timeout_s, "per operation, seconds")
      ->capture_default_str();

  // carousel sim camera
  SimCameraArgs sim_camera;
  sim_camera.data_dir = DefaultDataDir();
  CLI::App* sim_camera_command = sim_command->add_subcommand(
      "camera", "a PTP/IP camera on 127.0.0.1 photographing the simulated rig");
  sim_camera_command->add_option("--port", sim_camera.port, "TCP port (0: any free)")
      ->capture_default_str();
  sim_camera_command
      ->add_option("--scene", sim_camera.scene, "shoe, bottle, avocado, duck or a file")
      ->capture_default_str();
  sim_camera_command->add_option("--data", sim_camera.data_dir, "shared test data folder");
  sim_camera_command->add_option("--size", sim_camera.size, "photo size WxH")
      ->capture_default_str();
  sim_camera_command->add_option("--elevation", sim_camera.elevation_deg, "camera elevation, deg")
      ->capture_default_str();
  sim_camera_command->add_option("--serial", sim_camera.serial, "serial number")
      ->capture_default_str();
  sim_camera_command
      ->add_option("--turn-deg", sim_camera.turn_deg, "turn the table this far after every capture")
      ->capture_default_str();
  sim_camera_command
      ->add_option("--capture-delay", sim_camera.capture_delay_ms,
                   "ms from the trigger to the new-photo event")
      ->capture_default_str();
  sim_camera_command->add_option("--busy", sim_camera.busy,
                                 "fault: the first N captures answer Device Busy");
  sim_camera_command
      ->add_option("--events", sim_camera.events, "fault: all, added-only, complete-only or none")
      ->capture_default_str();
  sim_camera_command->add_option("--drop-after", sim_camera.drop_after_bytes,
                                 "fault: drop the connection this many bytes into every download");
  sim_camera_command->add_option("--download-delay", sim_camera.download_delay_ms,
                                 "fault: ms before each 256 KiB chunk of a download (slow link)");
  sim_camera_command->add_option("--seconds", sim_camera.seconds, "run time, 0 = until Ctrl-C")
      ->capture_default_str();

  // carousel sim turntable
  SimTurntableArgs sim_turntable;
  CLI::App* sim_turntable_command = sim_command->add_subcommand(
      "turntable", "the turntable firmware in simavr, its serial port on a PTY");
  sim_turntable_command->add_option("--firmware", sim_turntable.firmware, "firmware ELF");
  sim_turntable_command->add_option("--link", sim_turntable.link, "symlink to the PTY");
  sim_turntable_command->add_option("--time-scale", sim_turntable.time_scale, "simulated s per s")
      ->capture_default_str();
  sim_turntable_command
      ->add_option("--seconds", sim_turntable.seconds, "run time, 0 = until Ctrl-C")
      ->capture_default_str();

  // carousel texture SESSION | carousel texture atlas MESH
  TextureArgs texture_args;
  AtlasArgs atlas;
  CLI::App* texture_command =
      app.add_subcommand("texture", "texture atlas and texture map of a session's mesh");
  texture_command->require_subcommand(0, 1);
  texture_command->add_option("session", texture_args.session,
                              "session folder (with recon/mesh.ply)");
  texture_command
      ->add_option("--size", texture_args.options.size, "texture side in texels, 0 = automatic")
      ->capture_default_str();
  texture_command->add_option("--max-size", texture_args.options.max_size, "largest automatic size")
      ->capture_default_str();
  texture_command
      ->add_option("--exclude-views", texture_args.options.grouping.exclude_views,
                   "views not to texture from (held out), e.g. 3,11")
      ->delimiter(',');
  texture_command->add_flag("--no-blend", texture_args.no_blend, "no seam blending");
  texture_command->add_flag("--no-correction", texture_args.no_correction, "no mask correction");
  texture_command->add_flag("--no-gain", texture_args.no_gain, "no per-view colour gains");
  texture_command->add_option("--packing", texture_args.packing, "obb or aabb")
      ->capture_default_str();

  // carousel process SESSION...: reconstruct + texture
  ProcessArgs process_args;
  CLI::App* process_command = app.add_subcommand(
      "process",
      "the processing stages (reconstruct, texture) of one or more sessions, each skipped when "
      "its outputs are current");
  process_command->add_option("sessions", process_args.sessions, "session folders")->required();
  process_command->add_flag("--force", process_args.force, "run every stage, current or not");
  process_command->add_option("--faces", process_args.faces, "faces of the optimized mesh")
      ->capture_default_str();
  process_command
      ->add_option("--exclude-views", process_args.exclude_views,
                   "views not to texture from (held out and scored), e.g. 3,11")
      ->delimiter(',');
  CLI::App* atlas_command = texture_command->add_subcommand(
      "atlas", "charts, flattening and packing of a mesh: an OBJ with UVs");
  atlas_command->add_option("mesh", atlas.mesh, "mesh file (OBJ, PLY, OFF)")->required();
  atlas_command->add_option("--out", atlas.out, "output OBJ with UVs")->required();
  atlas_command->add_option("--seeds", atlas.options.charts.seeds, "chart growth seeds")
      ->capture_default_str();
  atlas_command->add_option("--packing", atlas.packing, "obb or aabb")->capture_default_str();
  atlas_command->add_option("--size", atlas.options.packing.size, "atlas size in texels")
      ->capture_default_str();
  atlas_command
      ->add_option("--gutter", atlas.options.packing.gutter_texels, "texels between charts")
      ->capture_default_str();
  atlas_command
      ->add_option("--rectify-stretch", atlas.options.parameterization.rectify_max_stretch,
                   "charts pulled towards rectangles (tighter packing) while their L2 stretch "
                   "stays under this; 1 = angle-preserving flattening only")
      ->capture_default_str();
  atlas_command->add_option("--charts-image", atlas.charts_image, "PNG of the charts");

  try {
    app.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app.exit(e, out, err);
  } catch (const CLI::CallForAllHelp& e) {
    return app.exit(e, out, err);
  } catch (const CLI::CallForVersion& e) {
    return app.exit(e, out, err);
  } catch (const CLI::ParseError& e) {
    app.exit(e, out, err);
    return kExitUsage;
  }

  try {
    SetLogLevel(ParseLogLevel(log_level));
    if (!log_file.empty()) SetLogFile(log_file);
    if (self_check_command->parsed()) return RunSelfCheckCommand(self_check, out, err);
    if (intrinsics_command->parsed()) return RunCalibrateIntrinsics(calibrate, out, err);
    if (rig_calibrate_command->parsed()) return RunCalibrateRig(calibrate, out, err);
    if (board_command->parsed()) return RunCalibrateBoard(calibrate, out);
    if (capture->parsed()) return RunSimCapture(sim_capture, out, err);
    if (import_command->parsed()) return RunImport(import_args, out, err);
    if (reconstruct_command->parsed()) return RunReconstruct(reconstruct, out, err);
    if (atlas_command->parsed()) return RunTextureAtlas(atlas, out, err);
    if (turntable_command->parsed()) return RunTurntable(turntable, out, err);
    if (camera_command->parsed()) return RunCamera(camera_args, out, err);
    if (sim_camera_command->parsed()) return RunSimCamera(sim_camera, out, err);
    if (run_command->parsed()) return RunOneButton(run_args, out, err);
    if (sim_turntable_command->parsed()) return RunSimTurntable(sim_turntable, out, err);
    if (texture_command->parsed()) {
      if (texture_args.session.empty()) {
        err << "carousel texture: a session folder (or `atlas MESH --out OUT.obj`) is required\n";
        return kExitUsage;
      }
      return RunTexture(texture_args, out, err);
    }
    if (process_command->parsed()) return RunProcess(process_args, out, err);
    err << "carousel: no subcommand\n";
    return kExitUsage;
  } catch (const std::exception& e) {
    err << "carousel: error: " << e.what() << '\n';
    return ExitCodeFor(e);
  }
}

}  // namespace carousel::studio
