#include "carousel/publish/viewer_page.h"

#include <algorithm>
#include <cstdlib>
#include <sstream>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"

namespace carousel::publish {
namespace {

constexpr const char* kModelViewerFile = kModelViewerScript;
constexpr const char* kDecoderFile = kMeshoptDecoderScript;

}  // namespace

bool WriteIfDifferent(const std::filesystem::path& path, std::span<const std::uint8_t> bytes) {
  std::error_code ec;
  if (std::filesystem::is_regular_file(path, ec) &&
      std::filesystem::file_size(path, ec) == bytes.size()) {
    const std::vector<std::uint8_t> old = ReadFileBytes(path);
    if (std::equal(old.begin(), old.end(), bytes.begin(), bytes.end())) return false;
  }
  WriteFileAtomic(path, bytes);
  return true;
}

bool WriteIfDifferent(const std::filesystem::path& path, const std::string& text) {
  return WriteIfDifferent(
      path, std::span<const std::uint8_t>(reinterpret_cast<const std::uint8_t*>(text.data()),
                                          text.size()));
}

bool CopyIfDifferent(const std::filesystem::path& from, const std::filesystem::path& to) {
  const std::vector<std::uint8_t> bytes = ReadFileBytes(from);
  return WriteIfDifferent(to, std::span<const std::uint8_t>(bytes.data(), bytes.size()));
}

WebRuntime FindWebRuntime() {
  const char* env = std::getenv("CAROUSEL_WEB_MODULES");
  const std::filesystem::path modules = env != nullptr && *env != '\0'
                                            ? std::filesystem::path(env)
                                            : std::filesystem::path(CAROUSEL_DEFAULT_WEB_MODULES);
  WebRuntime runtime;
  runtime.model_viewer = modules / "@google/model-viewer/dist" / kModelViewerFile;
  // The UMD build: a classic script that sets self.MeshoptDecoder, as model-viewer loads it.
  runtime.meshopt_decoder = modules / "meshoptimizer" / "meshopt_decoder.cjs";
  for (const auto& file : {runtime.model_viewer, runtime.meshopt_decoder}) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec))
      throw IoError(file,
                    "missing web package file (install the web packages: scripts/install-deps, "
                    "or set CAROUSEL_WEB_MODULES to a node_modules folder that has them)");
  }
  return runtime;
}

std::string EscapeHtml(const std::string& text) {
  std::string out;
  for (const char c : text) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&#39;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string HtmlPageOpening(const std::string& title) {
  return R"(<!doctype html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="Carousel">
<title>)" +
         EscapeHtml(title) + "</title>\n";
}

std::string ViewerPageHtml(const ViewerPageOptions& options) {
  const std::string name = options.title.empty() ? "3D model" : options.title;
  const std::string title = EscapeHtml(name);
  std::ostringstream html;
  html << HtmlPageOpening(name) << R"(<style>
  html, body { margin: 0; height: 100%; background: #fff; font-family: system-ui, sans-serif; }
  body { display: flex; flex-direction: column; }
  h1 { font-size: 1.1rem; font-weight: 600; margin: 0.6rem 1rem; color: #222; }
  model-viewer { flex: 1; width: 100%; min-height: 320px; background-color: #fff;
                 --poster-color: #fff; }
  nav { margin: 0 1rem 0.5rem; font-size: 0.9rem; }
  nav a { margin-right: 1rem; }
</style>
<!-- The web GLB's geometry is meshopt-compressed: model-viewer decodes it only once a decoder
     location is set (it has no default); the decoder ships beside the page, for offline use. -->
<script>
  self.ModelViewerElement = self.ModelViewerElement || {};
  self.ModelViewerElement.meshoptDecoderLocation = ')"
       << EscapeHtml(options.script_dir) << kDecoderFile << R"(';
</script>
<script type="module" src=")"
       << EscapeHtml(options.script_dir) << kModelViewerFile << R"("></script>
</head>
<body>
<h1>)" << title
       << "</h1>\n";
  if (!options.links.empty()) {
    html << "<nav>";
    for (const auto& [label, href] : options.links)
      html << "<a href=\"" << EscapeHtml(href) << "\">" << EscapeHtml(label) << "</a>";
    html << "</nav>\n";
  }
  html << R"(<model-viewer src=")" << EscapeHtml(options.glb) << '"';
  if (!options.poster.empty()) html << " poster=\"" << EscapeHtml(options.poster) << '"';
  html << " alt=\"" << title << "\"";
  html << R"( camera-controls touch-action="pan-y")";
  if (options.auto_rotate) html << " auto-rotate";
  // The material is unlit (the photos' light): no tone mapping, so the page shows the
  // texture's colours as they are.
  html << R"( shadow-intensity="0" exposure="1" tone-mapping="none")"
       << R"( ar ar-modes="webxr scene-viewer" ar-scale="fixed">
</model-viewer>
</body>
</html>
)";
  return html.str();
}

void WriteViewerPage(const std::filesystem::path& folder, const ViewerPageOptions& options,
                     const WebRuntime& runtime) {
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  if (ec) throw IoError(folder, "cannot create the folder: " + ec.message());
  if (options.script_dir.empty()) {
    CopyIfDifferent(runtime.model_viewer, folder / kModelViewerFile);
    CopyIfDifferent(runtime.meshopt_decoder, folder / kDecoderFile);
  }
  WriteIfDifferent(folder / "index.html", ViewerPageHtml(options));
}

}  // namespace carousel::publish
