// The processing part of a session (after capture): reconstruct (silhouettes -> masks/, visual
// hull, optimized mesh -> recon/) and texture (atlas, texture map, export -> model/), each
// stage skipped when its outputs are current. `carousel process SESSION...` and the one-button
// `carousel run` both go through ProcessSession.
//
// Current means: the manifest says the stage is done, every output file exists, and the
// stage's input fingerprint (recorded in session.json's "stage_inputs" when the stage
// finished) equals the fingerprint of what it would read now:
//   reconstruct: every photo's SHA-256, camera model and table angle, the session frame and
//                every reconstruct option;
//   texture:     the reconstruct fingerprint, the SHA-256 of recon/mesh.ply and every
//                texture option;
//   publish:     the texture fingerprint, the SHA-256 of model/model.glb and every publish
//                option (publish_session.h; off with publish_model = false).
// A photo retaken, a camera recalibrated, a mesh edited or an option changed therefore reruns
// exactly the stages that depend on it. The fingerprint is recorded only after the stage's own
// manifest update, so a stage killed half-way is never taken for current.
#pragma once

#include <filesystem>
#include <optional>
#include <string>

#include "carousel/core/progress.h"
#include "carousel/studio/publish_session.h"
#include "carousel/studio/reconstruct.h"
#include "carousel/studio/texture_session.h"

namespace carousel::studio {

struct ProcessOptions {
  ReconstructOptions reconstruct;
  TextureSessionOptions texture;
  PublishSessionOptions publish;
  bool publish_model = true;  // the publish stage (web GLB, viewer page) after texture
  bool force = false;         // run every stage even when current
  void Validate() const;
};

struct ProcessResult {
  std::optional<ReconstructResult> reconstruct;  // set when the stage ran
  std::optional<TextureSessionResult> texture;   // set when the stage ran
  std::optional<PublishSessionResult> publish;   // set when the stage ran
  std::string reconstruct_reason;                // why it ran (or "current")
  std::string texture_reason, publish_reason;
  double seconds_reconstruct = 0.0, seconds_texture = 0.0, seconds_publish = 0.0;
};

// \throw what ReconstructSession and TextureSession throw (IoError/FormatError naming the
// session file at fault, InvalidArgument, Cancelled).
ProcessResult ProcessSession(const std::filesystem::path& session_folder,
                             const ProcessOptions& options, Progress& progress);
// The same on a session already read (one run reads session.json once); `session` is kept
// up to date with what the stages record.
ProcessResult ProcessSession(const std::filesystem::path& session_folder, Session& session,
                             const ProcessOptions& options, Progress& progress);

// The fingerprints ProcessSession compares (lowercase hex SHA-256). \throw IoError/FormatError.
std::string ReconstructFingerprint(const std::filesystem::path& session_folder,
                                   const ReconstructOptions& options);
std::string ReconstructFingerprint(const std::filesystem::path& session_folder,
                                   const Session& session, const ReconstructOptions& options);
std::string TextureFingerprint(const std::filesystem::path& session_folder,
                               const std::string& reconstruct_fingerprint,
                               const TextureSessionOptions& options);

}  // namespace carousel::studio
