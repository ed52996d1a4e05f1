// The capture loop of a session: turntable stops x cameras through the rig's backends
// (rig_factory.h), into <session>/images/ with every photo's SHA-256 in session.json.
//   - each photo is downloaded atomically under its planned name (cam<C>_stop<SS>.jpg), then
//     its checksum goes into the manifest, which is rewritten atomically only after the photo
//     is on disk;
//   - a photo the manifest records and whose checksum matches is kept; a complete photo on disk
//     but not recorded (a kill between download and manifest) is adopted; a damaged one is
//     moved aside (damaged/<name>.N, never deleted) and retaken.
// Each stop: move, settle, every camera fires at once (triggered through libgphoto2 or
// released by the controller's shutter outputs); with mask shots (plan "backlit") the backlight
// goes on, every camera fires again into cam<C>_stop<SS>_backlit.jpg and the backlight goes off;
// then the table turns to the next stop while the photos download. Resume, adoption and
// checksums cover both photos of a stop: a view whose mask shot is missing or damaged gets
// only that shot again.
#pragma once

#include <filesystem>

#include "carousel/core/progress.h"
#include "carousel/studio/rig_factory.h"
#include "carousel/studio/session.h"

namespace carousel::studio {

struct CaptureResult {
  int photos_taken = 0;              // this run
  int photos_kept = 0;               // verified from an earlier run
  int photos_adopted = 0;            // complete on disk but not yet recorded
  int photos_retaken = 0;            // damaged or missing: moved aside and taken again
  double max_trigger_skew_ms = 0.0;  // largest spread of the cameras' triggers at a stop
  double seconds = 0.0;
};

// Takes every photo of the plan (rig.plan.stops x `placements` turns x cameras) that `session`
// does not hold verified yet, updating `session` and its manifest in `folder` as each arrives.
// A capture that changed anything makes the later stages stale. \throw DeviceError (the first
// device failure, after every camera of the stop has finished), IoError, Cancelled; every
// photo recorded before is kept.
CaptureResult CaptureSession(const std::filesystem::path& folder, Session& session,
                             RigBackends& rig, int placements, Progress& progress);

// The relative path of the backlit mask shot camera `camera` takes at stop `stop` (of pass
// `pass`).
std::string MaskShotPath(int camera, int stop, int pass = 0);

// Removes the temporary files atomic writes leave behind when a process is killed.
void RemoveStaleTemporaries(const std::filesystem::path& folder);

}  // namespace carousel::studio
