// `carousel reconstruct`: the reconstruction stage of a session folder (DESIGN.md):
//   masks/<photo>.png   silhouettes, 8-bit, 255 = object (one per photo, same name)
//   recon/hull.ply      the visual hull
//   recon/mesh.ply      the optimized mesh
// and session.json records the masks and the stage ("reconstruct": "done"). The photos are
// only read. Each output is written atomically; the manifest last, once they are all on disk.
// Sessions in the turntable frame stand on the floor z = 0 and have the plate removed; imported
// datasets ("dataset" frame) have neither.
// Background plates for the difference method: <session>/backgrounds/cam<C>.jpg (or .png), a
// photo of the empty turntable by camera C.
#pragma once

#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/recon/recon.h"
#include "carousel/studio/session.h"

namespace carousel::studio {

struct ReconstructOptions {
  recon::SilhouetteOptions silhouettes;
  recon::VisualHullOptions hull;
  recon::MeshOptimizationOptions mesh;
  // Later passes (the product laid down another way) registered to the first.
  recon::RegistrationOptions registration;
  // A mesh whose outline deviates further than this from the silhouettes on average (pixels)
  // is made again with twice the faces, up to 8 x mesh.target_faces; 0 = never.
  double max_outline_deviation_px = 1.0;
  // The operator's choice for ambiguous passes, "PASS:POSE[,PASS:POSE...]" (2:3 = pass 2 takes
  // pose 3 of those recon/pass2_pose<K>.jpg show); recorded in the session (ApplyPoseChoices),
  // so later runs keep it. Empty: none.
  std::string choose_pose;
  // The silhouette, hull and mesh tables together (flag names are unique across them).
  static const OptionTable<ReconstructOptions>& Fields();
  void Validate() const;
};

// What became of a later pass (Session::passes).
struct PassOutcome {
  int pass = 0;
  std::string orientation;
  std::string status;  // "registered", "ambiguous", "failed"
  std::string note;    // the residual, or what is wrong, naming the pass
  int views = 0;
  std::optional<recon::RegistrationResult> registration;  // when it ran
};

struct ReconstructResult {
  int views = 0;                    // photos segmented (every pass)
  int model_views = 0;              // of them, those the hull and the mesh were made from
  std::vector<PassOutcome> passes;  // passes after the first
  std::string method;               // the silhouette method used ("backlit", "key", ...)
  int given_masks = 0;              // views whose mask was given (a dataset's, or edited by hand)
  int redecided = 0;                // views the multi-view step segmented again or repaired
  double min_mask_fraction = 0.0;   // smallest object fraction of a photo
  std::size_t hull_faces = 0;
  double voxel_size_m = 0.0;
  std::size_t mesh_faces = 0;
  // The optimized mesh against each view's silhouette (pixels).
  std::vector<recon::SilhouetteAgreement> agreement;
  double seconds_silhouettes = 0.0;
  double seconds_registration = 0.0;
  double seconds_hull = 0.0;
  double seconds_mesh = 0.0;
  double seconds_agreement = 0.0;
};

// Masks edited by hand since the reconstruction wrote them (their file differs from the
// recorded checksum): each is copied to masks/given/ (the edit is never lost) and recorded as the
// view's given mask, which the next reconstruction starts from and checks against the other
// views (a deliberate fix that agrees with them stays; a damaged mask is repaired). Returns the
// edited masks' paths; `session` and its manifest are updated. \throw IoError.
std::vector<std::string> AdoptEditedMasks(const std::filesystem::path& session_folder,
                                          Session& session);

// Records the operator's choices (ReconstructOptions::choose_pose) in `session`: each named
// pass must have been found ambiguous (it lists pose_choices) and the pose must be one of them.
// Returns whether anything changed. \throw InvalidArgument naming the pass and what is wrong.
bool ApplyPoseChoices(Session& session, const std::string& choices);

// Silhouettes come from the given masks (session views' given_mask), else from the backlit mask
// shots when every view has one (method auto), else from the photos; masks/ receives the
// consistent result and session.json each mask's checksum.
// \throw IoError/FormatError naming the session file at fault, InvalidArgument, Cancelled.
ReconstructResult ReconstructSession(const std::filesystem::path& session_folder,
                                     const ReconstructOptions& options, Progress& progress);
// The same on a session already read (one run reads session.json once): `session` is updated
// (masks, stage) and written back.
ReconstructResult ReconstructSession(const std::filesystem::path& session_folder, Session& session,
                                     const ReconstructOptions& options, Progress& progress);

}  // namespace carousel::studio
