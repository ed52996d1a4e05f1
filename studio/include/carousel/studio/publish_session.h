// The publish stage of a session (DESIGN.md's model/ folder), after texture:
//   model/model.web.glb   the compact GLB a shop's page downloads (publish/web_glb.h)
//   model/poster.jpg      the hero shot, shown while the page loads
//   model/index.html      the viewer page, with model-viewer and the meshopt decoder beside it
//   model/hero.jpg        the hero shot (the poster is it, smaller)
//   model/cutouts/        every photo with its background removed through its mask (white
//                         JPEG or transparent PNG), cropped square and centred
//   model/360.zip         the 360° set: spin_frames images at equal steps from one elevation,
//                         "<product>_01.jpg"...; from the photos when one camera took exactly
//                         that many equally spaced stops, rendered from the model otherwise
//   model/spin.webp       the same frames as an animated WebP
//   model/report.html     the report page (publish/report_page.h) with its images in report/
//   model/publish.json    sizes of both GLBs, the held-out scores of the web GLB next to the
//                         lossless one's (report.json's views), so the cost of the compression
//                         is a measured figure, and the files a site copies (publish/site.h)
// The lossless model.glb is only read; cutouts/ and report/ hold only what this stage wrote
// last (older files there are removed).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "carousel/core/options.h"
#include "carousel/core/progress.h"
#include "carousel/publish/catalog_images.h"
#include "carousel/publish/site.h"
#include "carousel/publish/web_glb.h"
#include "carousel/studio/session.h"
#include "carousel/texture/held_out.h"

namespace carousel::studio {

struct PublishSessionOptions {
  publish::WebGlbOptions web;
  int poster_size = 800;                                               // pixels per side, 64..4096
  int hero_size = 1600;                                                // pixels per side, 64..8192
  bool cutouts = true;                                                 // model/cutouts/
  publish::CutoutBackdrop backdrop = publish::CutoutBackdrop::kWhite;  // cut-outs and 360° set
  int cutout_size = 1600;  // pixels per side, 0 = as cropped
  double cutout_margin = 0.06;
  int spin_frames = 24;  // 24, 48 or 72; 0 = no 360° set and no spin
  int spin_size = 720;   // pixels per side
  int spin_frame_ms = 125;
  int webp_quality = 80;
  int jpeg_quality = 90;  // the catalog images
  bool report = true;     // model/report.html
  static const OptionTable<PublishSessionOptions>& Fields();
  void Validate() const;
};

struct PublishSessionResult {
  publish::WebGlbResult web;
  std::size_t lossless_bytes = 0;
  std::vector<texture::HeldOutScore> held_out_lossless, held_out_web;
  double mean_psnr_lossless_db = 0.0, mean_psnr_web_db = 0.0;
  int cutouts = 0;         // photos cut out
  int cutouts_turned = 0;  // of them, turned by quarter turns to stand upright (rolled cameras)
  int spin_frames = 0;     // frames of the 360° set and the spin
  bool spin_from_photos = false;
  int spin_camera = -1;             // the camera whose photos made it (from photos)
  double spin_elevation_deg = 0.0;  // of the rendered frames
  std::vector<std::string> files;   // everything written, relative to model/
  double seconds = 0.0;
};

// \throw IoError/FormatError naming the file at fault (no model: run texture first; the web
// packages missing), InvalidArgument.
PublishSessionResult PublishSession(const std::filesystem::path& session_folder,
                                    const Session& session, const PublishSessionOptions& options,
                                    Progress& progress);

// Copies a published session (its model/publish.json) into the static catalog `site`
// (publish/site.h) as SITE/<the session folder's name>/ and rewrites SITE/index.html, titled
// `title`. \throw IoError naming the file or the site folder at fault, FormatError.
struct SiteResult {
  publish::SiteProductResult product;
  int products = 0;  // listed in SITE/index.html
};
SiteResult AddToSite(const std::filesystem::path& session_folder, const std::filesystem::path& site,
                     const std::string& title = "Catalog");

}  // namespace carousel::studio
