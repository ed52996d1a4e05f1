// carousel calibrate intrinsics|rig|board
#include <iomanip>
#include <memory>

#include "carousel/calib/board.h"
#include "carousel/calib/intrinsics.h"
#include "carousel/core/image_io.h"
#include "carousel/studio/calibrate_session.h"
#include "command.h"
#include "print.h"

namespace carousel::app {
namespace {

struct CalibrateArgs {
  // intrinsics
  std::vector<std::filesystem::path> images;
  calib::IntrinsicsOptions intrinsics;
  // rig
  std::filesystem::path session;
  studio::CalibrateSessionOptions rig;
  double board_height_m = -1.0;
  // board
  int pixels_per_square = 200;
  // all
  std::string board;
  std::filesystem::path out;
};

int RunIntrinsics(CalibrateArgs& args, Io& io) {
  const calib::BoardSpec board = calib::BoardSpec::Parse(args.board);
  calib::CheckIntrinsicsPath(args.out);
  CreateParentFolder(args.out);
  CliProgress cli(io.err);
  const calib::IntrinsicsResult r =
      calib::CalibrateIntrinsics(args.images, board, args.intrinsics, cli.progress());
  calib::WriteIntrinsics(args.out, r, board);
  for (const calib::ViewReport& v : r.views) {
    io.out << "  " << v.name << ": "
           << (v.used ? "used, " + std::to_string(v.corners) + " corners" : "refused: " + v.reason);
    if (v.used) io.out << std::fixed << std::setprecision(3) << ", " << v.rms_px << " px RMS";
    io.out << "\n";
  }
  const CameraModel& c = r.camera;
  io.out << std::fixed << std::setprecision(3) << "intrinsics " << args.out.string() << ": "
         << r.UsedViews() << " of " << r.views.size() << " photos, " << r.rms_px << " px RMS; fx "
         << c.fx << " fy " << c.fy << " cx " << c.cx << " cy " << c.cy << ", distortion "
         << std::setprecision(5) << c.distortion.k1 << " " << c.distortion.k2 << " "
         << c.distortion.p1 << " " << c.distortion.p2 << " " << c.distortion.k3 << "; "
         << std::setprecision(0) << 100.0 * r.cell_coverage << " % of the image covered\n"
         << std::setprecision(2) << "  one standard deviation: fx " << r.std_fx << " fy "
         << r.std_fy << " cx " << r.std_cx << " cy " << r.std_cy << " px";
  if (!r.held.empty()) {
    io.out << "; held at 0:";
    for (const std::string& term : r.held) io.out << " " << term;
  }
  io.out << "\n";
  for (const std::string& w : r.warnings) io.out << "  warning: " << w << "\n";
  return kExitOk;
}

int RunRig(CalibrateArgs& args, Io& io) {
  args.rig.board = args.board;
  if (args.board_height_m >= 0) args.rig.board_origin_height_m = args.board_height_m;
  if (!args.out.empty()) CreateParentFolder(args.out);
  CliProgress cli(io.err);
  PrintCalibration(studio::CalibrateSession(args.session, args.rig, args.out, cli.progress()),
                   io.out);
  return kExitOk;
}

int RunBoard(CalibrateArgs& args, Io& io) {
  const calib::BoardSpec board = calib::BoardSpec::Parse(args.board);
  CAROUSEL_THROW_IF(args.pixels_per_square < 10 || args.pixels_per_square > 2000, InvalidArgument,
                    "--px-per-square must be 10..2000, got " << args.pixels_per_square);
  const calib::BoardImage drawn =
      calib::DrawBoard(board, args.pixels_per_square, args.pixels_per_square / 2);
  CreateParentFolder(args.out);
  WriteImage(args.out, drawn.image);
  const double dpi = args.pixels_per_square / (board.square_m / 0.0254);
  io.out << std::fixed << std::setprecision(1) << "board " << args.out.string() << ": "
         << drawn.image.cols << "x" << drawn.image.rows << " px; print at " << dpi
         << " dpi for squares of " << board.square_m * 1e3 << " mm, then measure them\n";
  return kExitOk;
}

}  // namespace

void AddCalibrateCommands(CLI::App& command, Dispatch& dispatch) {
  auto args = std::make_shared<CalibrateArgs>();
  command.require_subcommand(1);
  const std::string board_help =
      "chessboard:COLSxROWS:SQUARE_M or charuco:SXxSY:SQUARE_M:MARKER_M:DICT";

  CLI::App* intrinsics = command.add_subcommand(
      "intrinsics", "one camera's intrinsics and lens distortion from photos of a board");
  intrinsics->add_option("images", args->images, "photos of the board")->required();
  intrinsics->add_option("--board", args->board, board_help)->required();
  intrinsics
      ->add_option("--out", args->out,
                   "file to write: .json (the camera as session.json has it, with the standard "
                   "deviations and every photo's report) or .yml/.yaml/.xml (OpenCV's)")
      ->required();
  AddOptionFlags(intrinsics, args->intrinsics, calib::IntrinsicsOptions::Fields());
  dispatch.On(intrinsics, [args](Io& io) { return RunIntrinsics(*args, io); });

  CLI::App* rig = command.add_subcommand(
      "rig", "the turntable axis and every camera's pose (and lens) from a calibration session");
  rig->add_option("session", args->session, "session folder")->required();
  rig->add_option("--out", args->out,
                  "rig calibration file (default SESSION/calibration/rig_calibration.json)");
  rig->add_option("--board", args->board, "the board (default: the calibration session's)");
  rig->add_option("--board-height", args->board_height_m,
                  "height of the first placement's board origin above the plate, metres");
  rig->add_option("--stops-per-placement", args->rig.stops_per_placement,
                  "stops per board placement (default: the session's plan)");
  rig->add_option("--intrinsics", args->rig.intrinsics,
                  "per camera, intrinsics calibrated beforehand (.json from `calibrate "
                  "intrinsics`, or OpenCV YAML/XML; empty: none)")
      ->delimiter(',');
  AddOptionFlags(rig, args->rig.rig, calib::RigCalibrationOptions::Fields());
  dispatch.On(rig, [args](Io& io) { return RunRig(*args, io); });

  CLI::App* board = command.add_subcommand("board", "draw a board to print (PNG)");
  board->add_option("--board", args->board, board_help)->required();
  board->add_option("--out", args->out, "PNG to write")->required();
  board->add_option("--px-per-square", args->pixels_per_square, "pixels per square")
      ->capture_default_str();
  dispatch.On(board, [args](Io& io) { return RunBoard(*args, io); });
}

}  // namespace carousel::app
