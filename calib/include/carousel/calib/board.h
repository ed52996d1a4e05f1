// calib: calibration boards: plain chessboards and ChArUco boards (OpenCV's aruco module),
// their corners in the board's own frame, detection with sub-pixel refinement and the reasons a
// photo's board is refused, and the board drawn as an image (to print, or to texture the
// simulated rig's calibration scene).
//
//   BoardSpec board = BoardSpec::Parse("charuco:5x7:0.04:0.03:DICT_6X6_250");
//   BoardDetection d = DetectBoard(photo, board);   // d.ids index board.ObjectPoints()
//
// Board frame: metres, the board's plane is z = 0, its normal (+z) points away from the printed
// side (OpenCV's convention: a camera looking at the board sees +z pointing away from it).
// Chessboard corners are row by row from OpenCV's first corner; ChArUco corners are OpenCV's
// chessboardCorners, identified by the markers, so a partly visible ChArUco board still gives
// the corners it shows.
#pragma once

#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace carousel::calib {

enum class BoardKind { kChessboard, kCharuco };

// A calibration board. Written
//   "chessboard:COLSxROWS:SQUARE_M"   COLS x ROWS inner corners (OpenCV's convention: a board
//                                     of 10 x 7 squares has 9 x 6 inner corners), squares of
//                                     SQUARE_M metres;
//   "charuco:SXxSY:SQUARE_M:MARKER_M:DICT"   SX x SY squares (markers in the white ones),
//                                     square and marker sides in metres, and the ArUco
//                                     dictionary by OpenCV's name (DICT_4X4_50 ... DICT_7X7_1000,
//                                     DICT_ARUCO_ORIGINAL).
struct BoardSpec {
  BoardKind kind = BoardKind::kChessboard;
  int cols = 9;             // chessboard: inner corners per row; charuco: squares along x
  int rows = 6;             // chessboard: inner corners per column; charuco: squares along y
  double square_m = 0.025;  // side of a square, metres (> 0)
  double marker_m = 0.0;    // charuco: side of a marker, metres (0 < marker < square)
  std::string dictionary;   // charuco: e.g. "DICT_6X6_250"

  // \throw InvalidArgument naming what is wrong with the text.
  static BoardSpec Parse(const std::string& text);
  std::string ToString() const;
  // \throw InvalidArgument naming the field.
  void Validate() const;
  // Every corner the board has, in the board frame (z = 0, metres); a detection's ids index it.
  std::vector<cv::Point3f> ObjectPoints() const;
  // Inner corners along x and y (both board kinds).
  int CornersX() const;
  int CornersY() const;
  // The printed area (all squares), metres.
  double WidthM() const;
  double HeightM() const;
};

struct DetectOptions {
  // A board whose corners found cover less than this fraction of the image (their convex
  // hull) is refused: its corners constrain the lens too little. Range [0, 1).
  double min_board_area_fraction = 0.005;
  // Fewest corners a usable view shows (ChArUco may be partly visible; a chessboard must be
  // whole). >= 4.
  int min_corners = 8;
  // A board whose black-to-white edges are wider than this (10-90 % rise, pixels, measured
  // across the square edges between detected corners) is refused as blurred. > 0.
  double max_edge_width_px = 5.0;
  // A board seen so obliquely that its squares look this many times narrower one way than the
  // other is refused: its corners are found poorly (2.5: about 66 degrees from face-on;
  // ChArUco corners seen beyond 70 degrees came out 1-4 px off on the simulated rig). >= 1.
  double max_foreshortening = 2.5;
  // Smallest square side in the image (along its most foreshortened direction), pixels.
  double min_square_px = 6.0;
  // Detection runs on a copy at most this large (DSLR photos are slow to search); corners are
  // refined on the full image. >= 640.
  int detect_max_side = 2000;
  void Validate() const;
};

// One photo's board.
struct BoardDetection {
  bool found = false;
  std::string reason;                // why not, when !found
  std::vector<int> ids;              // corner ids, indices into BoardSpec::ObjectPoints()
  std::vector<cv::Point2f> corners;  // sub-pixel image positions, one per id
  int markers = 0;                   // charuco: markers decoded
  double area_fraction = 0.0;        // convex hull of the corners / image area
  double edge_width_px = 0.0;        // blur: median 10-90 % edge rise (smaller is sharper)
  double square_px = 0.0;            // square side in the image, shortest direction
  double foreshortening = 1.0;       // longest / shortest apparent square side (>= 1)
};

// Finds the board in an 8-bit image (grey or BGR). A found board with too few corners, too
// small, blurred, or with all its corners on one line, comes back !found with the reason (and
// the corners it had, for drawing).
BoardDetection DetectBoard(const cv::Mat& image, const BoardSpec& board,
                           const DetectOptions& options = {});

// The board drawn for printing or texturing: white margin, black squares (and markers).
struct BoardImage {
  cv::Mat image;  // CV_8UC1
  // Board-frame metres (x, y; z = 0) of an image position (OpenCV pixel convention):
  // board_xy = board_from_pixel * (u, v, 1).
  Eigen::Matrix<double, 2, 3> board_from_pixel;
};
// \throw InvalidArgument for a bad spec or sizes.
BoardImage DrawBoard(const BoardSpec& board, int pixels_per_square, int margin_px);

}  // namespace carousel::calib
