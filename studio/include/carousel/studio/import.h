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
// Imported sessions use the dataset's world frame (manifest frame "dataset").
#pragma once

#include <filesystem>
#include <string>

#include "carousel/core/progress.h"

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
  std::string product;     // empty = the dataset's folder name
  bool overwrite = false;  // replace an existing session folder
  void Validate() const;
};

struct ImportResult {
  std::filesystem::path session;
  int views = 0;
};

// \throw IoError (missing file or photo, target exists), FormatError (malformed line, naming
//        the file and line), InvalidArgument; nothing is left at the target on failure.
ImportResult ImportDataset(const ImportOptions& options,
                           const std::filesystem::path& session_folder, Progress& progress);

}  // namespace carousel::studio
