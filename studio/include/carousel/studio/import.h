// `carousel import`: turns a calibrated real dataset into a session folder (session.h), so the
// pipeline runs on real photos. The photos are copied (or linked) into images/, never
// modified; the session appears atomically like a simulated one.
//
// Formats:
//   Middlebury multi-view (`*_par.txt`): first line N, then per image
//     `name k11 k12 k13 k21 k22 k23 k31 k32 k33 r11 ... r33 t1 t2 t3` with x ~ K (R X + t);
//     pixel coordinates taken as given (integer = pixel centre), no distortion.
//   COLMAP sparse text model (cameras.txt, images.txt): SIMPLE_PINHOLE, PINHOLE,
//     SIMPLE_RADIAL, RADIAL, OPENCV and FULL_OPENCV (rational terms zero). COLMAP puts the
//     centre of the top-left pixel at (0.5, 0.5); the import shifts the principal point by
//     -0.5 px to OpenCV's convention.
// Imported sessions are not on our turntable (manifest frame "dataset": no plate, no floor), but
// the import stands them upright in our convention: +Z along the capture's up axis, the origin
// where the cameras look (UprightFrame below), so that renders, the hero shot, the spin and the
// Y-up OBJ/GLB show the object standing. The transform is kept in session.json
// ("world_from_dataset") to map points of the dataset's own frame; --keep-frame keeps the
// dataset's axes as they are.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "carousel/core/camera_model.h"
#include "carousel/core/progress.h"
#include "carousel/core/rigid3.h"

namespace carousel::studio {

struct ImportOptions {
  enum class Format { kMiddlebury, kColmap } format = Format::kMiddlebury;
  // Middlebury: the *_par.txt file. COLMAP: the folder with cameras.txt and images.txt.
  std::filesystem::path source;
  // Folder of the photos; empty = the par file's folder (Middlebury). Required for COLMAP.
  std::filesystem::path images_dir;
  // How photos enter the session: copied (default), hard-linked (falls back to a copy across
  // file systems) or symbolically linked.
  enum class Transfer { kCopy, kHardLink, kSymlink } transfer = Transfer::kCopy;
  std::string product;      // empty = the dataset's folder name
  bool overwrite = false;   // replace an existing session folder
  bool keep_frame = false;  // keep the dataset's world frame instead of standing it upright
  // Folder of the silhouettes that come with the dataset (8-bit, object bright; 0/1 masks are
  // scaled), one per photo named like it (<stem>.png, .pgm, .pbm, .bmp, .tif, .jpg, or the
  // photo's full name + .png): they become the views' given masks (masks/given/), which the
  // reconstruction starts from and checks against the other views. Empty = none.
  std::filesystem::path masks_dir;
  void Validate() const;
};

struct ImportResult {
  std::filesystem::path session;
  int views = 0;
  std::string frame;  // how the world frame was chosen (UprightFrameResult::basis, or "kept")
};

struct UprightFrameResult {
  Rigid3d world_from_dataset;  // maps the dataset's points into the upright frame
  std::string basis;           // in words: which evidence fixed the up axis and its sign
  // A ring of cameras: its radius and how far the centres stray from the fitted circle (RMS),
  // in the dataset's units; 0 when the cameras form no ring.
  double ring_radius = 0.0;
  double ring_rms = 0.0;
};

// The upright frame of a capture, from its cameras alone. Up is the axis of the ring the camera
// centres lie on (the normal of their best-fit plane; with the centres spread in 3D, as on a
// dome, the mean of the cameras' image-up directions instead). Its sign makes the cameras look
// down on the object, as studio cameras do; a ring looking straight across takes the sign the
// photos' up direction agrees with (cameras may be rolled, so that comes second). The origin is
// on the ring's axis (the centre of the circle fitted to the camera centres in the ring's
// plane: a turntable's axis, wherever the cameras aim), at the height of the point nearest every
// optical axis; without a ring, that point itself. std::nullopt when the cameras fix no axis
// (fewer than 3, or all on a line, or looking every way).
std::optional<UprightFrameResult> UprightFrame(const std::vector<CameraModel>& cameras);

// \throw IoError (missing file or photo, target exists), FormatError (malformed line, naming
//        the file and line), InvalidArgument; nothing is left at the target on failure.
ImportResult ImportDataset(const ImportOptions& options,
                           const std::filesystem::path& session_folder, Progress& progress);

}  // namespace carousel::studio
