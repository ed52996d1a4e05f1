// `carousel self-check`: verifies that this build and machine can do the pipeline's basic
// work, with real data through the real libraries: the camera model against OpenCV, image and
// mesh files written and read back, and the shared test data.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"

namespace carousel::studio {

struct SelfCheckOptions {
  // Folder for scratch files; created and removed by the check. Empty: a folder under the
  // system's temporary directory.
  std::filesystem::path scratch_dir;
  // Third-party test data (shared/data). Empty: skip the data checks (reported as skipped).
  std::filesystem::path data_dir;
  // Random points per camera-model check (>= 1).
  int points = 2000;
  // The description of the fields a person sets (core/options.h).
  static const OptionTable<SelfCheckOptions>& Fields();
  void Validate() const;
};

struct SelfCheckItem {
  std::string name;
  enum class Status { kPassed, kFailed, kSkipped } status = Status::kFailed;
  std::string detail;  // figures measured, or the reason for a failure or skip
};

struct SelfCheckResult {
  std::vector<SelfCheckItem> items;
  bool AllPassed() const;  // no item failed (skipped items do not fail the check)
};

SelfCheckResult RunSelfCheck(const SelfCheckOptions& options, Progress& progress);

}  // namespace carousel::studio
