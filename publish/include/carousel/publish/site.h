// A static catalog site (`carousel publish SESSION... --out SITE/`): one folder per product with
// its viewer page, web GLB, report and catalog images, the page scripts once in SITE/assets/,
// and SITE/index.html linking every product the site holds. Works from any static host and
// offline.
//
//   SITE/index.html            the catalog: one card per product (poster, name), by name
//   SITE/assets/               model-viewer.min.js, meshopt_decoder.js (shared)
//   SITE/<slug>/               what the product's model/publish.json lists, its own
//                              index.html (scripts from ../assets/), product.json
//
// Publishing is idempotent: a file already holding the same bytes is not rewritten, and the
// files of a product folder that its publish.json no longer lists are removed (only in folders
// with a product.json, which the site wrote).
#pragma once

#include <filesystem>
#include <string>
#include <vector>

#include "carousel/publish/viewer_page.h"

namespace carousel::publish {

// A folder name from a product name or session folder name: [A-Za-z0-9._-], others '-',
// never empty, never "." / ".." / "assets".
std::string SiteSlug(const std::string& name);

struct SiteProductResult {
  std::filesystem::path folder;  // SITE/<slug>
  int files_written = 0;         // new or changed
  int files_unchanged = 0;
  int files_removed = 0;
};

// Copies a published model folder (a session's model/ with publish.json) into SITE/<slug>/.
// \throw IoError naming the file (no publish.json: publish the session first; a listed file
// missing) or the site folder when it cannot be created or written; FormatError for a damaged
// publish.json.
SiteProductResult PublishToSite(const std::filesystem::path& model_folder, const std::string& slug,
                                const std::filesystem::path& site, const WebRuntime& runtime);

// Rewrites SITE/index.html from the product.json of each product folder. Returns the products
// listed. \throw IoError/FormatError naming the file.
int WriteSiteIndex(const std::filesystem::path& site, const std::string& title = "Catalog");

}  // namespace carousel::publish
