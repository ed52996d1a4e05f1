// The session folder (DESIGN.md) and its manifest, session.json.
//
//   <session>/session.json   this manifest, rewritten atomically (write, fsync, rename)
//   <session>/images/        photos, never rewritten
//   <session>/backgrounds/   cam<C>.jpg: camera C's photo of the empty turntable (optional)
//   <session>/masks/ recon/ model/   later stages
//   <session>/ground_truth/  simulated sessions only: exact masks, depth and scene mesh, kept
//                            apart from what the pipeline reads
//
// Every path in the manifest is relative to the session folder. Each view carries the exact
// camera used: intrinsics, distortion, image size and cam_from_world, plus the table angle.
// World frame: the turntable frame ("turntable"), or for imported datasets whose object does not
// sit on our turntable "dataset": +Z up as the import found it, with world_from_dataset mapping
// the dataset's own frame into it (import.h).
// Format version 1; readers refuse newer major versions.
#pragma once

#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "carousel/core/camera_model.h"
// The camera as session.json stores it: CameraModelToJson/FromJson (core/json.h). Included
// here until tests/studio/hardware_run_test.cpp includes core/json.h itself.
#include "carousel/core/json.h"
#include "carousel/core/view.h"

namespace carousel::studio {

inline constexpr int kSessionFormatVersion = 1;
inline constexpr const char* kManifestName = "session.json";

struct SessionView {
  std::string image;        // relative path of the photo
  std::string mask;         // relative path of its silhouette, empty until made
  std::string mask_sha256;  // of the silhouette as the reconstruct stage wrote it
  // The backlit mask shot of the same camera and stop (the backlight on; capture plan
  // "mask_shots": "backlit"): what the silhouette is taken from, while the texture comes from
  // `image`. Empty when the plan took none.
  std::string mask_shot;
  std::string mask_shot_sha256;  // of the mask shot as downloaded
  // A silhouette given rather than found (a dataset's own masks, `carousel import --masks`, or
  // a mask edited by hand after reconstruct, kept under masks/given/): the reconstruct stage
  // starts from it instead of segmenting the photo, and checks it against the other views.
  std::string given_mask;
  std::string given_mask_sha256;
  int camera = 0;  // index of the camera in the rig
  int stop = 0;    // index of the turntable stop
  // The pass it belongs to (Session::passes): 0 = the first, whose turntable frame is the
  // object's frame.
  int pass = 0;
  double table_angle_deg = 0.0;  // table angle at capture
  // Exact calibration, cam_from_world at this angle, in its pass's own turntable frame (the
  // object frame for pass 0; SessionViews maps later passes through their registration).
  CameraModel camera_model;
  std::string sha256;  // of the photo as downloaded (empty: not recorded)
  // When the shutter was triggered, milliseconds after the first camera's trigger at this
  // stop (the trigger skew between cameras); < 0 when unknown.
  double trigger_offset_ms = -1.0;
};

// A photo the simulator took for evaluation only, never used by the pipeline: e.g. from below
// the product, where no pass's camera looks (ground_truth "eval_views").
struct EvalView {
  std::string image;
  std::string mask;          // exact silhouette
  CameraModel camera_model;  // in the object frame
  std::string name;          // what it shows ("below")
};

struct GroundTruth {
  std::string mesh;                // relative path of the scene surface (object frame)
  std::vector<std::string> masks;  // per view, exact silhouettes
  std::vector<std::string> depth;  // per view, 16-bit PNG, units of depth_unit_m, 0 = none
  double depth_unit_m = 1e-4;
  // Per pass (Session::passes), where the simulator laid the product: the pass's turntable
  // frame from the object frame (identity for pass 0). Empty for one pass.
  std::vector<Rigid3d> table_from_object;
  std::vector<EvalView> eval_views;
  bool empty() const { return mesh.empty() && masks.empty() && depth.empty(); }
};

// One pass of the turntable with the product in one orientation (capture plan
// "orientations"): pass 0 stands it as the photographer put it first, and its turntable frame
// is the object frame; later passes lay it down another way and are registered to pass 0 by
// the reconstruct stage (recon/registration.h).
struct SessionPass {
  std::string orientation;  // how it lies, as the plan or the operator named it ("upright")
  // Passes >= 1: "" (not registered yet), "registered", "ambiguous" or "failed". Only a
  // registered pass's views reach the model.
  std::string registration;
  std::string registration_note;  // the residual, or why it was not registered, for people
  std::optional<Rigid3d> table_from_object;  // set when "registered"
  // Set when it was found "ambiguous": the poses the silhouettes fit alike, the likeliest first
  // (their pictures: recon/pass<N>_pose<K>.jpg), for the operator to choose among.
  std::vector<Rigid3d> pose_choices;
  // The operator's choice among pose_choices, 1-based (0: none): the pass is registered from
  // that pose, and pose_choices stay.
  int chosen_pose = 0;
};

struct Session {
  int version = kSessionFormatVersion;
  std::string product;      // the product's SKU or name
  std::string created_utc;  // ISO 8601
  std::string source;       // "sim:<scene>", "import:middlebury", "capture", ...
  std::string frame = "turntable";
  // Imported sessions: how the import stood the dataset upright (points of the dataset's own
  // frame map into the session's world through it); unset when the frame is the dataset's own.
  std::optional<Rigid3d> world_from_dataset;
  std::vector<SessionView> views;
  // Empty, or one entry per pass (views name theirs); views of later passes follow pass 0's.
  std::vector<SessionPass> passes;
  GroundTruth ground_truth;
  std::map<std::string, std::string> stages;  // stage name -> state ("done", ...)
  // stage name -> fingerprint of the inputs it ran on (pipeline.h), recorded after it finished
  std::map<std::string, std::string> stage_inputs;
  // stage name -> seconds its last run took (the report page's stage times)
  std::map<std::string, double> stage_seconds;
};

// Reads <folder>/session.json. \throw IoError (missing) or FormatError (malformed JSON, missing
// or wrong-typed field, unsupported version, absolute or escaping path) naming the file.
Session ReadSession(const std::filesystem::path& folder);

// Writes <folder>/session.json atomically. \throw IoError.
void WriteSessionManifest(const std::filesystem::path& folder, const Session& session);

// The session's photos as Views (absolute paths, cameras, angles, masks when present), the
// cameras in the object frame. A later pass's views are left out until it is registered; they
// follow pass 0's, so a view's index is the same here and in session.views for every view
// returned.
std::vector<View> SessionViews(const std::filesystem::path& folder, const Session& session);
// Every photo, each camera in its own pass's turntable frame (what the silhouettes and the
// registration work in).
std::vector<View> SessionTableViews(const std::filesystem::path& folder, const Session& session);
// Whether the session has views of more than one pass.
bool HasSeveralPasses(const Session& session);

// The file stem of the photo camera `camera` takes at turntable stop `stop`: "cam0_stop03";
// its backlit mask shot's is ViewStem + kMaskShotSuffix ("cam0_stop03_backlit"). Passes after
// the first prefix theirs: "pass1_cam0_stop03".
std::string ViewStem(int camera, int stop, int pass = 0);
inline constexpr const char* kMaskShotSuffix = "_backlit";

// The session's backlit mask shots as Views (the photos' cameras), one per view; empty unless
// every view has one.
std::vector<View> SessionMaskShotViews(const std::filesystem::path& folder, const Session& session);

// The current UTC time as ISO 8601 ("2026-11-22T01:44:27Z").
std::string NowUtc();

// Creates a new session folder atomically: files go into a hidden staging folder beside the
// target; Commit() renames it into place (replacing an old session only when `overwrite`, and
// only once the new one is complete). Destroyed without Commit(), it removes the staging folder
// and leaves the target untouched.
class StagedSessionFolder {
 public:
  // \throw IoError if the target exists (and not `overwrite`) or its parent is missing.
  StagedSessionFolder(const std::filesystem::path& target, bool overwrite);
  ~StagedSessionFolder();
  StagedSessionFolder(const StagedSessionFolder&) = delete;
  StagedSessionFolder& operator=(const StagedSessionFolder&) = delete;
  // Where to write now.
  const std::filesystem::path& staging() const { return staging_; }
  const std::filesystem::path& target() const { return target_; }
  // Creates a sub-folder of the staging folder. \throw IoError.
  void CreateFolder(const std::filesystem::path& relative) const;
  // Moves the finished session into place. \throw IoError (the target is then unchanged).
  void Commit();

 private:
  std::filesystem::path target_;
  std::filesystem::path staging_;
  bool overwrite_;
  bool committed_ = false;
};

}  // namespace carousel::studio
