// `carousel run`: the one-button session. Capture (capture.h: turntable stops x cameras, on the
// rig that rig_factory.h opens), then reconstruct, texture and export, into <out>/<product>/
// (DESIGN.md's session folder). Crash-safe and resumable:
//   - run.json (written first, atomically) records how to rebuild the rig and the plan;
//   - photos are recorded in session.json only once on disk (capture.h);
//   - `carousel run --resume SESSION` keeps every photo whose checksum matches, adopts a
//     complete photo that was on disk but not yet recorded, moves a damaged one aside and
//     retakes it, removes stale temporary files, and runs each stage whose outputs are not
//     current.
// Backends: the simulated rig (a product model on the simulated turntable), or the hardware of
// a rig file (the serial turntable controller and libgphoto2 cameras; rig_config.h).
#pragma once

#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "carousel/core/progress.h"
#include "carousel/studio/calibrate_session.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/publish_session.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/rig_config.h"
#include "carousel/studio/sim_capture.h"
#include "carousel/studio/texture_session.h"

namespace carousel::studio {

struct RunOptions {
  std::string product;                     // SKU; the session folder's name is derived from it
  std::filesystem::path out = "sessions";  // parent folder
  SimCaptureOptions sim;                   // scene, rig, stops, renderer (the simulated backend)
  std::optional<RigConfig> hardware;       // set: capture with this rig's devices instead
  // Set: a calibration session: the table turns with the board on it, once per placement
  // (the simulated rig places its board itself; on hardware `place_board` asks the operator),
  // and the photos are calibrated into <session>/calibration/rig_calibration.json instead of
  // reconstructed. The simulated rig is framed as for `sim.scene`.
  std::optional<CalibrationPlan> calibration;
  // Hardware calibration sessions: called before the table turns for placement `index`
  // (0-based) once the board must stand there; it returns when it does.
  std::function<void(int index, int placements)> place_board;
  // Hardware product sessions of more than one orientation (rig.json capture.orientations):
  // called before the first photo of pass `pass` (1-based passes after the first: 1, 2, ...)
  // once the product must lie another way; it returns when it does.
  std::function<void(int pass, int passes)> turn_product;
  // A rig calibration file (calib/rig_calibration.h) whose cameras the photos get instead of
  // the rig's own (the simulator's ground truth, or rig.json's); copied into the session.
  std::filesystem::path calibration_file;
  ReconstructOptions reconstruct;
  TextureSessionOptions texture;
  PublishSessionOptions publish;  // recorded in run.json: a resume publishes the same way
  bool publish_model = true;      // the publish stage after texture
  bool force = false;             // replace an existing session of that name
  void Validate() const;
};

struct RunResult {
  std::filesystem::path session;
  int photos_taken = 0;              // this run
  int photos_kept = 0;               // verified from an earlier run
  int photos_adopted = 0;            // complete on disk but not yet recorded
  int photos_retaken = 0;            // damaged or missing: moved aside and taken again
  double max_trigger_skew_ms = 0.0;  // largest spread of the cameras' triggers at a stop
  bool reconstructed = false, textured = false;  // stages run (not skipped) this time
  std::optional<ReconstructResult> reconstruct;  // the reconstruction, when it ran
  TextureSessionResult texture;
  std::optional<PublishSessionResult> publish;        // the publish stage, when it ran
  std::optional<CalibrateSessionResult> calibration;  // calibration sessions, when it ran
  double seconds_capture = 0.0, seconds_reconstruct = 0.0, seconds_texture = 0.0;
};

// A session folder name for a product SKU: letters, digits, '-', '_' and '.' kept, anything
// else '_', no leading dot, at most 100 characters. \throw InvalidArgument if nothing is left.
std::string SessionNameForProduct(const std::string& product);

// A new session. \throw IoError when it exists (without force), InvalidArgument, and what the
// stages throw.
RunResult RunSession(const RunOptions& options, Progress& progress);

// Continues a session started by RunSession. On hardware, `turn_product` (as
// RunOptions::turn_product) asks the operator to lay the product as the pass the first
// missing photo belongs to needs. \throw IoError/FormatError naming run.json or session.json,
// and what the stages throw.
RunResult ResumeSession(const std::filesystem::path& session, Progress& progress,
                        std::function<void(int pass, int passes)> turn_product = {});

// The publish options a session goes on with: those it last published with
// (model/publish.json's "options"), else those its `carousel run` was given (run.json), else the
// defaults. \throw FormatError naming the file whose record is malformed.
PublishSessionOptions RecordedPublishOptions(const std::filesystem::path& session);
// The views a session's texture held out: those its last texture held out
// (model/report.json's "excluded_views"), else those its `carousel run` was given (run.json),
// else none. \throw FormatError naming the file whose record is malformed.
std::vector<int> RecordedExcludedViews(const std::filesystem::path& session);

}  // namespace carousel::studio
