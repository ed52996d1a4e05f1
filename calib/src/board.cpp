#include "carousel/calib/board.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>
#include <type_traits>

#include <Eigen/QR>
#include <opencv2/aruco/charuco.hpp>
#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "calib_internal.h"
#include "carousel/core/error.h"

namespace carousel::calib {
namespace {

using internal::Fixed;
using internal::Median;

const std::map<std::string, cv::aruco::PREDEFINED_DICTIONARY_NAME>& Dictionaries() {
  using namespace cv::aruco;
  static const std::map<std::string, PREDEFINED_DICTIONARY_NAME> kNames = {
      {"DICT_4X4_50", DICT_4X4_50},
      {"DICT_4X4_100", DICT_4X4_100},
      {"DICT_4X4_250", DICT_4X4_250},
      {"DICT_4X4_1000", DICT_4X4_1000},
      {"DICT_5X5_50", DICT_5X5_50},
      {"DICT_5X5_100", DICT_5X5_100},
      {"DICT_5X5_250", DICT_5X5_250},
      {"DICT_5X5_1000", DICT_5X5_1000},
      {"DICT_6X6_50", DICT_6X6_50},
      {"DICT_6X6_100", DICT_6X6_100},
      {"DICT_6X6_250", DICT_6X6_250},
      {"DICT_6X6_1000", DICT_6X6_1000},
      {"DICT_7X7_50", DICT_7X7_50},
      {"DICT_7X7_100", DICT_7X7_100},
      {"DICT_7X7_250", DICT_7X7_250},
      {"DICT_7X7_1000", DICT_7X7_1000},
      {"DICT_ARUCO_ORIGINAL", DICT_ARUCO_ORIGINAL}};
  return kNames;
}

cv::Ptr<cv::aruco::Dictionary> Dictionary(const BoardSpec& board) {
  return cv::aruco::getPredefinedDictionary(Dictionaries().at(board.dictionary));
}

cv::Ptr<cv::aruco::CharucoBoard> Charuco(const BoardSpec& board) {
  return cv::aruco::CharucoBoard::create(board.cols, board.rows, static_cast<float>(board.square_m),
                                         static_cast<float>(board.marker_m), Dictionary(board));
}

// A field of a board's text: a whole number, or a number of metres.
template <typename T>
T ParseField(const std::string& text, const std::string& what, const std::string& spec) {
  std::size_t used = 0;
  T value{};
  try {
    if constexpr (std::is_integral_v<T>) {
      value = std::stoi(text, &used);
    } else {
      value = std::stod(text, &used);
    }
  } catch (const std::exception&) {
    used = 0;
  }
  CAROUSEL_THROW_IF(used == 0 || used != text.size(), InvalidArgument,
                    "board \"" << spec << "\": " << what << " \"" << text << "\" is not "
                               << (std::is_integral_v<T> ? "a whole number" : "a number (metres)"));
  return value;
}

cv::Mat ToGray(const cv::Mat& image) {
  CAROUSEL_THROW_IF(image.empty() || image.depth() != CV_8U, InvalidArgument,
                    "an 8-bit image is needed to find the board");
  if (image.channels() == 1) return image;
  cv::Mat gray;
  cv::cvtColor(image, gray, image.channels() == 4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  return gray;
}

double Bilinear(const cv::Mat& gray, double x, double y) {
  const int x0 = static_cast<int>(std::floor(x));
  const int y0 = static_cast<int>(std::floor(y));
  if (x0 < 0 || y0 < 0 || x0 + 1 >= gray.cols || y0 + 1 >= gray.rows) return -1.0;
  const double fx = x - x0;
  const double fy = y - y0;
  const auto at = [&](int xx, int yy) {
    return static_cast<double>(gray.at<std::uint8_t>(yy, xx));
  };
  return (1 - fy) * ((1 - fx) * at(x0, y0) + fx * at(x0 + 1, y0)) +
         fy * ((1 - fx) * at(x0, y0 + 1) + fx * at(x0 + 1, y0 + 1));
}

// The 10-90 % rise of the intensity across the square edge midway between two adjacent corners
// (pixels), or < 0 when the profile is unusable (off the image, too little contrast).
double EdgeRise(const cv::Mat& gray, const cv::Point2f& a, const cv::Point2f& b) {
  const double dx = b.x - a.x;
  const double dy = b.y - a.y;
  const double length = std::hypot(dx, dy);
  if (length < 4.0) return -1.0;
  const double nx = -dy / length;
  const double ny = dx / length;
  const double mx = 0.5 * (a.x + b.x);
  const double my = 0.5 * (a.y + b.y);
  // Within a tenth of a square on either side: inside the two squares, clear of a ChArUco
  // marker's border (an eighth of a square in on the usual 0.75 marker ratio).
  const double half = std::max(3.0, 0.1 * length);
  constexpr double kStep = 0.25;
  std::vector<double> profile;
  for (double t = -half; t <= half + 1e-9; t += kStep) {
    const double v = Bilinear(gray, mx + t * nx, my + t * ny);
    if (v < 0) return -1.0;
    profile.push_back(v);
  }
  const auto [lo_it, hi_it] = std::minmax_element(profile.begin(), profile.end());
  const double lo = *lo_it;
  const double hi = *hi_it;
  if (hi - lo < 20.0) return -1.0;
  const bool rising = profile.back() > profile.front();
  const double low_level = lo + 0.1 * (hi - lo);
  const double high_level = lo + 0.9 * (hi - lo);
  const std::size_t centre = profile.size() / 2;
  // From the centre outwards: where the profile leaves the 10-90 % band on each side.
  std::size_t dark = centre;
  std::size_t bright = centre;
  if (rising) {
    while (dark > 0 && profile[dark] > low_level) --dark;
    while (bright + 1 < profile.size() && profile[bright] < high_level) ++bright;
  } else {
    while (bright > 0 && profile[bright] < high_level) --bright;
    while (dark + 1 < profile.size() && profile[dark] > low_level) ++dark;
  }
  return std::abs(static_cast<double>(bright) - static_cast<double>(dark)) * kStep;
}

// Blur of the detected board: the median edge rise over pairs of adjacent corners.
double EdgeWidth(const cv::Mat& gray, const BoardSpec& board, const std::vector<int>& ids,
                 const std::vector<cv::Point2f>& corners) {
  std::map<int, cv::Point2f> by_id;
  for (std::size_t i = 0; i < ids.size(); ++i) by_id[ids[i]] = corners[i];
  const int nx = board.CornersX();
  std::vector<double> rises;
  for (const auto& [id, p] : by_id) {
    const int cx = id % nx;
    for (const int other : {cx + 1 < nx ? id + 1 : -1, id + nx}) {
      const auto it = other < 0 ? by_id.end() : by_id.find(other);
      if (it == by_id.end()) continue;
      const double rise = EdgeRise(gray, p, it->second);
      if (rise >= 0) rises.push_back(rise);
    }
  }
  return rises.empty() ? 0.0 : Median(rises);
}

bool Collinear(const std::vector<cv::Point2f>& corners) {
  if (corners.size() < 3) return true;
  cv::Mat points(static_cast<int>(corners.size()), 2, CV_64F);
  for (std::size_t i = 0; i < corners.size(); ++i) {
    points.at<double>(static_cast<int>(i), 0) = corners[i].x;
    points.at<double>(static_cast<int>(i), 1) = corners[i].y;
  }
  cv::PCA pca(points, cv::Mat(), cv::PCA::DATA_AS_ROW);
  const double major = std::sqrt(std::max(0.0, pca.eigenvalues.at<double>(0)));
  const double minor = std::sqrt(std::max(0.0, pca.eigenvalues.at<double>(1)));
  return minor < 0.02 * major || minor < 1.0;
}

// A chessboard's corners in OpenCV's order may start at either end; the board frame is pinned
// to the end whose outer square is black (the printed convention), so every view of a rig
// calibration sees the same board frame.
void OrientChessboard(const cv::Mat& gray, const BoardSpec& board,
                      std::vector<cv::Point2f>* corners) {
  const int nx = board.cols;
  const std::vector<cv::Point2f>& c = *corners;
  const cv::Point2f first = c.front();
  const cv::Point2f diagonal_first = c[static_cast<std::size_t>(nx + 1)];
  const cv::Point2f last = c.back();
  const cv::Point2f diagonal_last = c[c.size() - static_cast<std::size_t>(nx) - 2];
  const cv::Point2f outer_first = first + 0.5F * (first - diagonal_first);
  const cv::Point2f outer_last = last + 0.5F * (last - diagonal_last);
  const double at_first = Bilinear(gray, outer_first.x, outer_first.y);
  const double at_last = Bilinear(gray, outer_last.x, outer_last.y);
  if (at_first >= 0 && at_last >= 0 && at_first > at_last) {
    std::reverse(corners->begin(), corners->end());
  }
}

// The board's apparent square side along its most foreshortened direction, pixels: the smaller
// singular value of the best affine map from the board plane to the image; and the larger one
// over it (the foreshortening).
void ApparentSquare(const BoardSpec& board, const std::vector<int>& ids,
                    const std::vector<cv::Point2f>& corners, double* square_px,
                    double* foreshortening) {
  const std::vector<cv::Point3f> all = board.ObjectPoints();
  Eigen::MatrixXd a(static_cast<Eigen::Index>(ids.size()), 3);
  Eigen::MatrixXd b(static_cast<Eigen::Index>(ids.size()), 2);
  for (std::size_t i = 0; i < ids.size(); ++i) {
    const cv::Point3f& p = all[static_cast<std::size_t>(ids[i])];
    a.row(static_cast<Eigen::Index>(i)) << p.x, p.y, 1.0;
    b.row(static_cast<Eigen::Index>(i)) << corners[i].x, corners[i].y;
  }
  const Eigen::MatrixXd affine = a.colPivHouseholderQr().solve(b);  // 3 x 2
  // Singular values of the 2 x 2 linear part, from the eigenvalues of its Gram matrix.
  const Eigen::Matrix2d m = affine.topRows<2>().transpose();
  const Eigen::Matrix2d gram = m.transpose() * m;
  const double mean = 0.5 * (gram(0, 0) + gram(1, 1));
  const double spread = std::hypot(0.5 * (gram(0, 0) - gram(1, 1)), gram(0, 1));
  const double longest = std::sqrt(std::max(0.0, mean + spread)) * board.square_m;
  const double shortest = std::sqrt(std::max(0.0, mean - spread)) * board.square_m;
  *square_px = shortest;
  *foreshortening = longest / std::max(shortest, 1e-9);
}

// interpolateCornersCharuco's own refinement is off by up to half a pixel (its window reaches
// the markers' borders). The corners are refined again in a window inside the white margin
// around the markers along the board's most foreshortened direction.
void RefineCharucoCorners(const cv::Mat& gray, const BoardSpec& board, double square_px,
                          std::vector<cv::Point2f>* corners) {
  const double margin = 0.5 * (board.square_m - board.marker_m) / board.square_m;
  const int half = std::min(15, static_cast<int>(0.7 * margin * square_px));
  if (half < 2) return;
  std::vector<cv::Point2f> refined = *corners;
  cv::cornerSubPix(gray, refined, cv::Size(half, half), cv::Size(-1, -1),
                   cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 0.001));
  for (std::size_t i = 0; i < refined.size(); ++i) {
    // A refinement that wanders off the corner is not taken.
    if (cv::norm(refined[i] - (*corners)[i]) < 0.5 * half) (*corners)[i] = refined[i];
  }
}

}  // namespace

// ---- BoardSpec ----

BoardSpec BoardSpec::Parse(const std::string& text) {
  std::vector<std::string> parts;
  std::string part;
  std::istringstream in(text);
  while (std::getline(in, part, ':')) parts.push_back(part);
  const bool chessboard = !parts.empty() && parts[0] == "chessboard";
  const bool charuco = !parts.empty() && parts[0] == "charuco";
  CAROUSEL_THROW_IF((!chessboard || parts.size() != 3) && (!charuco || parts.size() != 5),
                    InvalidArgument,
                    "board \"" << text
                               << "\": expected chessboard:COLSxROWS:SQUARE_M (inner corners, "
                                  "e.g. chessboard:9x6:0.025) or "
                                  "charuco:SQUARESXxSQUARESY:SQUARE_M:MARKER_M:DICT (e.g. "
                                  "charuco:5x7:0.04:0.03:DICT_6X6_250)");
  const std::size_t x = parts[1].find('x');
  CAROUSEL_THROW_IF(x == std::string::npos, InvalidArgument,
                    "board \"" << text << "\": the size must read COLSxROWS, e.g. 9x6");
  BoardSpec board;
  board.kind = chessboard ? BoardKind::kChessboard : BoardKind::kCharuco;
  board.cols = ParseField<int>(parts[1].substr(0, x), "the column count", text);
  board.rows = ParseField<int>(parts[1].substr(x + 1), "the row count", text);
  board.square_m = ParseField<double>(parts[2], "the square size", text);
  if (charuco) {
    board.marker_m = ParseField<double>(parts[3], "the marker size", text);
    board.dictionary = parts[4];
  }
  try {
    board.Validate();
  } catch (const InvalidArgument& e) {
    throw InvalidArgument("board \"" + text + "\": " + e.what());
  }
  return board;
}

std::string BoardSpec::ToString() const {
  std::ostringstream out;
  out.precision(10);
  if (kind == BoardKind::kChessboard) {
    out << "chessboard:" << cols << 'x' << rows << ':' << square_m;
  } else {
    out << "charuco:" << cols << 'x' << rows << ':' << square_m << ':' << marker_m << ':'
        << dictionary;
  }
  return out.str();
}

void BoardSpec::Validate() const {
  CAROUSEL_THROW_IF(!(square_m > 0) || !std::isfinite(square_m) || square_m > 1.0, InvalidArgument,
                    "the square size must be in (0, 1] m, got " << square_m);
  if (kind == BoardKind::kChessboard) {
    CAROUSEL_THROW_IF(
        cols < 3 || rows < 3 || cols > 100 || rows > 100, InvalidArgument,
        "a chessboard needs 3..100 inner corners each way, got " << cols << 'x' << rows);
    CAROUSEL_THROW_IF((cols + rows) % 2 == 0, InvalidArgument,
                      "a chessboard of " << cols << 'x' << rows
                                         << " inner corners looks the same turned half round, "
                                            "so its corners have no fixed order; use one even "
                                            "and one odd count, like 9x6");
    return;
  }
  CAROUSEL_THROW_IF(cols < 3 || rows < 3 || cols > 100 || rows > 100, InvalidArgument,
                    "a ChArUco board needs 3..100 squares each way, got " << cols << 'x' << rows);
  CAROUSEL_THROW_IF(!(marker_m > 0) || !(marker_m < square_m), InvalidArgument,
                    "the marker side must be in (0, square side), got " << marker_m);
  const auto it = Dictionaries().find(dictionary);
  if (it == Dictionaries().end()) {
    std::string names;
    for (const auto& [name, value] : Dictionaries()) names += (names.empty() ? "" : ", ") + name;
    throw InvalidArgument("unknown ArUco dictionary \"" + dictionary + "\" (one of " + names + ")");
  }
  const int markers = cols * rows / 2;
  const int codes = cv::aruco::getPredefinedDictionary(it->second)->bytesList.rows;
  CAROUSEL_THROW_IF(markers > codes, InvalidArgument,
                    "a " << cols << 'x' << rows << " ChArUco board needs " << markers
                         << " markers, " << dictionary << " has " << codes);
}

int BoardSpec::CornersX() const { return kind == BoardKind::kChessboard ? cols : cols - 1; }
int BoardSpec::CornersY() const { return kind == BoardKind::kChessboard ? rows : rows - 1; }
double BoardSpec::WidthM() const {
  return (kind == BoardKind::kChessboard ? cols + 1 : cols) * square_m;
}
double BoardSpec::HeightM() const {
  return (kind == BoardKind::kChessboard ? rows + 1 : rows) * square_m;
}

std::vector<cv::Point3f> BoardSpec::ObjectPoints() const {
  Validate();
  if (kind == BoardKind::kCharuco) return Charuco(*this)->chessboardCorners;
  std::vector<cv::Point3f> points;
  points.reserve(static_cast<std::size_t>(cols * rows));
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      points.emplace_back(static_cast<float>(c * square_m), static_cast<float>(r * square_m), 0.0F);
    }
  }
  return points;
}

void DetectOptions::Validate() const {
  CAROUSEL_THROW_IF(!(min_board_area_fraction >= 0 && min_board_area_fraction < 1), InvalidArgument,
                    "min_board_area_fraction must be in [0, 1)");
  CAROUSEL_THROW_IF(min_corners < 4, InvalidArgument, "min_corners must be >= 4");
  CAROUSEL_THROW_IF(!(max_edge_width_px > 0), InvalidArgument, "max_edge_width_px must be > 0");
  CAROUSEL_THROW_IF(detect_max_side < 640, InvalidArgument, "detect_max_side must be >= 640");
  CAROUSEL_THROW_IF(!(max_foreshortening >= 1), InvalidArgument, "max_foreshortening must be >= 1");
  CAROUSEL_THROW_IF(!(min_square_px > 0), InvalidArgument, "min_square_px must be > 0");
}

// ---- detection ----

BoardDetection DetectBoard(const cv::Mat& image, const BoardSpec& board,
                           const DetectOptions& options) {
  board.Validate();
  options.Validate();
  const cv::Mat gray = ToGray(image);
  BoardDetection detection;

  // Search on a reduced copy, refine on the original.
  const int max_dim = std::max(gray.cols, gray.rows);
  const double scale = max_dim > options.detect_max_side
                           ? static_cast<double>(options.detect_max_side) / max_dim
                           : 1.0;
  cv::Mat small = gray;
  if (scale < 1.0) cv::resize(gray, small, cv::Size(), scale, scale, cv::INTER_AREA);
  const auto to_full = [scale](cv::Point2f p) {
    return scale < 1.0 ? cv::Point2f(static_cast<float>((p.x + 0.5) / scale - 0.5),
                                     static_cast<float>((p.y + 0.5) / scale - 0.5))
                       : p;
  };
  const int total = board.CornersX() * board.CornersY();

  if (board.kind == BoardKind::kChessboard) {
    const cv::Size pattern(board.cols, board.rows);
    std::vector<cv::Point2f> corners;
    const bool found = cv::findChessboardCorners(
        small, pattern, corners,
        cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE | cv::CALIB_CB_FAST_CHECK);
    if (!found || corners.size() != static_cast<std::size_t>(total)) {
      detection.reason = "no complete " + std::to_string(board.cols) + "x" +
                         std::to_string(board.rows) +
                         " chessboard found (not in the picture, partly outside it, covered, or "
                         "a board of another size)";
      return detection;
    }
    for (cv::Point2f& p : corners) p = to_full(p);
    // Sub-pixel refinement in a window well inside one square.
    double spacing = 1e30;
    for (int r = 0; r < board.rows; ++r) {
      for (int c = 0; c + 1 < board.cols; ++c) {
        const std::size_t i = static_cast<std::size_t>(r * board.cols + c);
        spacing = std::min(spacing, static_cast<double>(cv::norm(corners[i] - corners[i + 1])));
      }
    }
    const int half = std::clamp(static_cast<int>(spacing * 0.4), 2, 15);
    cv::cornerSubPix(gray, corners, cv::Size(half, half), cv::Size(-1, -1),
                     cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 40, 0.01));
    OrientChessboard(gray, board, &corners);
    detection.corners = std::move(corners);
    detection.ids.resize(static_cast<std::size_t>(total));
    for (int i = 0; i < total; ++i) detection.ids[static_cast<std::size_t>(i)] = i;
  } else {
    const cv::Ptr<cv::aruco::CharucoBoard> charuco = Charuco(board);
    cv::Ptr<cv::aruco::DetectorParameters> parameters = cv::aruco::DetectorParameters::create();
    std::vector<std::vector<cv::Point2f>> markers;
    std::vector<std::vector<cv::Point2f>> rejected;
    std::vector<int> marker_ids;
    cv::aruco::detectMarkers(small, charuco->dictionary, markers, marker_ids, parameters, rejected);
    if (!marker_ids.empty()) {
      cv::aruco::refineDetectedMarkers(small, charuco, markers, marker_ids, rejected);
    }
    detection.markers = static_cast<int>(marker_ids.size());
    if (marker_ids.empty()) {
      detection.reason =
          "no marker of the ChArUco board found (not in the picture, turned "
          "away, or a board of another dictionary)";
      return detection;
    }
    for (auto& quad : markers) {
      for (cv::Point2f& p : quad) p = to_full(p);
    }
    std::vector<cv::Point2f> corners;
    std::vector<int> ids;
    cv::aruco::interpolateCornersCharuco(markers, marker_ids, gray, charuco, corners, ids);
    if (corners.size() >= 4) {
      double square_px = 0.0;
      double foreshortening = 1.0;
      ApparentSquare(board, ids, corners, &square_px, &foreshortening);
      RefineCharucoCorners(gray, board, square_px, &corners);
    }
    detection.corners = std::move(corners);
    detection.ids = std::move(ids);
  }

  const int found_corners = static_cast<int>(detection.corners.size());
  if (found_corners < options.min_corners) {
    detection.reason = "only " + std::to_string(found_corners) + " of the board's " +
                       std::to_string(total) + " corners found (at least " +
                       std::to_string(options.min_corners) +
                       " needed): the board is mostly outside the picture, covered or turned "
                       "too far away";
    return detection;
  }
  if (Collinear(detection.corners)) {
    detection.reason = "the corners found all lie on one line (a sliver of the board)";
    return detection;
  }
  ApparentSquare(board, detection.ids, detection.corners, &detection.square_px,
                 &detection.foreshortening);
  if (detection.square_px > 0 && detection.square_px < options.min_square_px) {
    detection.reason = "the board's squares are too small in the image (" +
                       Fixed(detection.square_px, 1) + " px, at least " +
                       Fixed(options.min_square_px, 1) + " px needed)";
    return detection;
  }
  if (detection.foreshortening > options.max_foreshortening) {
    detection.reason = "the board is seen too obliquely (its squares look " +
                       Fixed(detection.foreshortening, 1) + " times narrower one way, at most " +
                       Fixed(options.max_foreshortening, 1) + " allowed)";
    return detection;
  }
  std::vector<cv::Point2f> hull;
  cv::convexHull(detection.corners, hull);
  detection.area_fraction = cv::contourArea(hull) / (static_cast<double>(gray.cols) * gray.rows);
  detection.edge_width_px = EdgeWidth(gray, board, detection.ids, detection.corners);
  if (detection.area_fraction < options.min_board_area_fraction) {
    detection.reason = "the board is too small in the image (" +
                       Fixed(100.0 * detection.area_fraction, 2) + " % of it, at least " +
                       Fixed(100.0 * options.min_board_area_fraction, 2) + " % needed)";
    return detection;
  }
  if (!(detection.edge_width_px <= options.max_edge_width_px)) {
    detection.reason = "the board is blurred (edges " + Fixed(detection.edge_width_px, 2) +
                       " px wide, at most " + Fixed(options.max_edge_width_px, 2) +
                       " px allowed): out of focus or moving";
    return detection;
  }
  detection.found = true;
  return detection;
}

// ---- drawing ----

BoardImage DrawBoard(const BoardSpec& board, int pixels_per_square, int margin_px) {
  board.Validate();
  CAROUSEL_THROW_IF(pixels_per_square < 20 || pixels_per_square > 1000, InvalidArgument,
                    "pixels per square must be 20..1000");
  CAROUSEL_THROW_IF(margin_px < 0 || margin_px > 10 * pixels_per_square, InvalidArgument,
                    "the margin must be 0..10 squares");
  const int squares_x = board.kind == BoardKind::kChessboard ? board.cols + 1 : board.cols;
  const int squares_y = board.kind == BoardKind::kChessboard ? board.rows + 1 : board.rows;
  const cv::Size size(squares_x * pixels_per_square + 2 * margin_px,
                      squares_y * pixels_per_square + 2 * margin_px);
  BoardImage drawn;
  const double metres_per_px = board.square_m / pixels_per_square;
  if (board.kind == BoardKind::kChessboard) {
    drawn.image = cv::Mat(size, CV_8UC1, cv::Scalar(255));
    for (int y = 0; y < squares_y; ++y) {
      for (int x = 0; x < squares_x; ++x) {
        if ((x + y) % 2 != 0) continue;  // the first square is black
        cv::rectangle(drawn.image,
                      cv::Rect(margin_px + x * pixels_per_square, margin_px + y * pixels_per_square,
                               pixels_per_square, pixels_per_square),
                      cv::Scalar(0), cv::FILLED);
      }
    }
    // Inner corner (c, r), at board (c, r) * square, lies where four squares meet: pixel edge
    // margin + (c + 1) * p, i.e. position margin + (c + 1) * p - 0.5 (pixel centres).
    const double offset = (0.5 - margin_px - pixels_per_square) * metres_per_px;
    drawn.board_from_pixel << metres_per_px, 0.0, offset, 0.0, metres_per_px, offset;
    return drawn;
  }
  Charuco(board)->draw(size, drawn.image, margin_px, 1);
  // OpenCV lays the board out itself: find its corners in the drawing and fit the map.
  DetectOptions options;
  options.detect_max_side = std::max(640, std::max(size.width, size.height));
  const BoardDetection d = DetectBoard(drawn.image, board, options);
  const std::vector<cv::Point3f> object = board.ObjectPoints();
  CAROUSEL_THROW_IF(static_cast<int>(d.ids.size()) != board.CornersX() * board.CornersY(), Error,
                    "the drawn ChArUco board does not show all its corners");
  Eigen::MatrixXd a(static_cast<Eigen::Index>(d.ids.size()), 3);
  Eigen::MatrixXd b(static_cast<Eigen::Index>(d.ids.size()), 2);
  for (std::size_t i = 0; i < d.ids.size(); ++i) {
    const auto row = static_cast<Eigen::Index>(i);
    a.row(row) << d.corners[i].x, d.corners[i].y, 1.0;
    const cv::Point3f& p = object[static_cast<std::size_t>(d.ids[i])];
    b.row(row) << p.x, p.y;
  }
  const Eigen::MatrixXd solution = a.colPivHouseholderQr().solve(b);  // 3 x 2
  const Eigen::Matrix<double, 2, 3> fitted = solution.transpose();
  // The fit (to corners refined to a few tenths of a pixel) tells which way OpenCV lays the
  // board out; the exact map follows from the layout: a scale of square / pixels-per-square
  // along each image axis, the board spanning [0, squares * square] between the margins.
  const double extent_px[2] = {static_cast<double>(squares_x * pixels_per_square),
                               static_cast<double>(squares_y * pixels_per_square)};
  drawn.board_from_pixel.setZero();
  for (int axis = 0; axis < 2; ++axis) {
    // Which image axis this board axis follows, and its direction.
    const int image_axis = std::abs(fitted(axis, 0)) > std::abs(fitted(axis, 1)) ? 0 : 1;
    const double sign = fitted(axis, image_axis) > 0 ? 1.0 : -1.0;
    const double along = image_axis == 0 ? extent_px[0] : extent_px[1];
    drawn.board_from_pixel(axis, image_axis) = sign * metres_per_px;
    // Board 0 at the margin's edge (pixel edge = position + 0.5), or at the far edge.
    const double zero_edge = sign > 0 ? margin_px : margin_px + along;
    drawn.board_from_pixel(axis, 2) = -sign * metres_per_px * (zero_edge - 0.5);
  }
  const double residual_m =
      (a * drawn.board_from_pixel.transpose() - b).rowwise().norm().maxCoeff();
  CAROUSEL_THROW_IF(residual_m > 0.5 * metres_per_px, Error,
                    "the drawn ChArUco board's corners are not where its layout puts them ("
                        << residual_m / metres_per_px << " px off)");
  return drawn;
}

}  // namespace carousel::calib
