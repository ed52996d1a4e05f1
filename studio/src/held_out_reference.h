// What a held-out view's rendering is scored over (texture and publish stages): the view's
// ground-truth mask when the session has one (simulated sessions), else its silhouette, else
// (a dataset imported without masks) nothing: the rendering's own coverage.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "carousel/core/image_io.h"
#include "carousel/core/view.h"
#include "carousel/studio/session.h"

namespace carousel::studio {

// \throw IoError/FormatError naming the mask.
inline cv::Mat HeldOutReferenceMask(const std::filesystem::path& folder, const Session& session,
                                    const std::vector<View>& views, int index) {
  const auto i = static_cast<std::size_t>(index);
  const std::string truth =
      i < session.ground_truth.masks.size() ? session.ground_truth.masks[i] : std::string();
  if (!truth.empty()) return ReadMask(folder / truth);
  return views.at(i).HasMask() ? views.at(i).Mask() : cv::Mat();
}

}  // namespace carousel::studio
