// The viewer page of a product, model/index.html: Google's <model-viewer> showing the web GLB
// (orbit, zoom, auto-rotate, the poster while it loads, AR on phones that offer it), with the
// scripts it needs copied beside it from the web packages (web/package.json: the model-viewer
// bundle with three.js inside, and meshoptimizer's decoder, which model-viewer would otherwise
// fetch from a CDN). The folder works offline from any static host.
#pragma once

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <utility>
#include <vector>

namespace carousel::publish {

// The installed web packages' files a page ships with.
struct WebRuntime {
  std::filesystem::path model_viewer;     // model-viewer.min.js
  std::filesystem::path meshopt_decoder;  // the decoder as a classic script (sets MeshoptDecoder)
};

// From $CAROUSEL_WEB_MODULES, else the node_modules folder scripts/install-deps fills.
// \throw IoError naming the missing file and how to install it.
WebRuntime FindWebRuntime();

struct ViewerPageOptions {
  std::string title;                  // the product's name (escaped for HTML)
  std::string glb = "model.web.glb";  // relative to the page
  std::string poster;                 // relative image shown while loading; empty: none
  bool auto_rotate = true;
  // Where the scripts are, relative to the page ("" = beside it; a catalog shares one copy:
  // "../assets/"); WriteViewerPage copies them beside the page only when this is empty.
  std::string script_dir;
  // Links shown under the title (label, relative href): the report, the spin, the 360 set.
  std::vector<std::pair<std::string, std::string>> links;
};

// The file names of the runtime's scripts where a page looks for them.
inline constexpr const char* kModelViewerScript = "model-viewer.min.js";
inline constexpr const char* kMeshoptDecoderScript = "meshopt_decoder.js";

// The page's HTML.
std::string ViewerPageHtml(const ViewerPageOptions& options);

// Writes `bytes` to `path` atomically unless the file already holds exactly them (its time
// stamp then stays: publishing twice changes nothing). Returns whether it wrote.
// \throw IoError naming the file.
bool WriteIfDifferent(const std::filesystem::path& path, std::span<const std::uint8_t> bytes);
bool WriteIfDifferent(const std::filesystem::path& path, const std::string& text);
// The same with the bytes of the file `from`. \throw IoError naming the file at fault.
bool CopyIfDifferent(const std::filesystem::path& from, const std::filesystem::path& to);

// Writes `folder`/index.html and copies the runtime's scripts beside it (each file atomically;
// a script already there with the same bytes is left alone). \throw IoError naming the file.
void WriteViewerPage(const std::filesystem::path& folder, const ViewerPageOptions& options,
                     const WebRuntime& runtime);

// `text` with &, <, >, " and ' escaped for HTML text and attribute values.
std::string EscapeHtml(const std::string& text);

// The opening of each of our pages up to and including its <title> (the doctype, <html lang>,
// <head>, charset, viewport and generator): the caller goes on with the <style> and closes the
// head. `title` is plain text, escaped here.
std::string HtmlPageOpening(const std::string& title);

}  // namespace carousel::publish
