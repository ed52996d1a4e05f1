// The publish stage of a session (DESIGN.md's model/ folder), after texture:
//   model/model.web.glb   the compact GLB a shop's page downloads (publish/web_glb.h)
//   model/poster.jpg      the hero shot, shown while the page loads
//   model/index.html      the viewer page, with model-viewer and the meshopt decoder beside it
//   model/publish.json    sizes of both GLBs and the held-out scores of the web GLB next to
//                         the lossless one's (report.json's views), so the cost of the
//                         compression is a measured figure
// The lossless model.glb is only read.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/publish/web_glb.h"
#include "carousel/studio/session.h"
#include "carousel/texture/held_out.h"

namespace carousel::studio {

struct PublishSessionOptions {
  publish::WebGlbOptions web;
  int poster_size = 800;  // pixels per side, 64..4096
  static const OptionTable<PublishSessionOptions>& Fields();
  void Validate() const;
};

struct PublishSessionResult {
  publish::WebGlbResult web;
  std::size_t lossless_bytes = 0;
  std::vector<texture::HeldOutScore> held_out_lossless, held_out_web;
  double mean_psnr_lossless_db = 0.0, mean_psnr_web_db = 0.0;
  double seconds = 0.0;
};

// \throw IoError/FormatError naming the file at fault (no model: run texture first; the web
// packages missing), InvalidArgument.
PublishSessionResult PublishSession(const std::filesystem::path& session_folder,
                                    const Session& session, const PublishSessionOptions& options,
                                    Progress& progress);

}  // namespace carousel::studio
