#include "carousel/publish/site.h"

#include <algorithm>
#include <set>
#include <sstream>
#include <utility>

#include <nlohmann/json.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/json.h"

namespace carousel::publish {

namespace {

constexpr const char* kProductFile = "product.json";
constexpr const char* kAssets = "assets";

void RequireWritableFolder(const std::filesystem::path& folder) {
  std::error_code ec;
  std::filesystem::create_directories(folder, ec);
  if (ec) throw IoError(folder, "cannot create the site folder: " + ec.message());
  if (!std::filesystem::is_directory(folder, ec))
    throw IoError(folder, "the site folder is not a folder");
  // A probe: a folder that cannot take a new file fails here, before anything is copied.
  const std::filesystem::path probe = TemporarySibling(folder / ".write-probe");
  try {
    WriteFileAtomic(probe, std::string("probe"), {.overwrite = true, .sync = false});
  } catch (const IoError&) {
    throw IoError(folder, "the site folder is not writable");
  }
  std::filesystem::remove(probe, ec);
}

}  // namespace

std::string SiteSlug(const std::string& name) {
  std::string slug;
  for (const char c : name) {
    const bool keep = (c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') ||
                      c == '.' || c == '_' || c == '-';
    slug += keep ? c : '-';
  }
  if (slug.empty() || slug == "." || slug == ".." || slug == kAssets) slug = "product-" + slug;
  return slug;
}

SiteProductResult PublishToSite(const std::filesystem::path& model_folder, const std::string& slug,
                                const std::filesystem::path& site, const WebRuntime& runtime) {
  CAROUSEL_THROW_IF(slug != SiteSlug(slug), InvalidArgument,
                    "site: '" << slug << "' is not a folder name a site uses");
  const std::filesystem::path manifest_path = model_folder / "publish.json";
  std::error_code ec;
  if (!std::filesystem::is_regular_file(manifest_path, ec))
    throw IoError(manifest_path, "no published model (run `carousel publish SESSION` first)");
  const nlohmann::json manifest = ParseJsonFile(manifest_path);
  const JsonReader read(manifest, manifest_path);
  const std::string name = read.String("name");
  const JsonReader page = read.Object("page");
  std::vector<std::string> files;
  for (const JsonReader& f : read.Array("files")) files.push_back(f.AsRelativePath("model folder"));
  ViewerPageOptions options;
  options.title = name;
  options.glb = page.RelativePath("glb", "model folder");
  options.poster = page.OptionalRelativePath("poster", "model folder").value_or("");
  options.script_dir = std::string("../") + kAssets + "/";
  for (const JsonReader& link : page.Array("links")) {
    const std::vector<JsonReader> pair = link.AsArray();
    if (pair.size() != 2) link.Fail("a link must be [label, href]");
    options.links.emplace_back(pair[0].AsString(), pair[1].AsRelativePath("model folder"));
  }
  // Every listed file must be there before the site changes.
  for (const std::string& f : files) RequireReadableFile(model_folder / f);

  RequireWritableFolder(site);
  SiteProductResult result;
  result.folder = site / slug;
  std::filesystem::create_directories(site / kAssets, ec);
  if (ec) throw IoError(site / kAssets, "cannot create the folder: " + ec.message());
  CopyIfDifferent(runtime.model_viewer, site / kAssets / kModelViewerScript);
  CopyIfDifferent(runtime.meshopt_decoder, site / kAssets / kMeshoptDecoderScript);

  std::set<std::filesystem::path> wanted = {"index.html", kProductFile};
  auto count = [&result](bool written) {
    ++(written ? result.files_written : result.files_unchanged);
  };
  for (const std::string& f : files) {
    if (f == "index.html" || f == kModelViewerScript || f == kMeshoptDecoderScript) continue;
    const std::filesystem::path to = result.folder / f;
    std::filesystem::create_directories(to.parent_path(), ec);
    if (ec) throw IoError(to.parent_path(), "cannot create the folder: " + ec.message());
    count(CopyIfDifferent(model_folder / f, to));
    wanted.insert(std::filesystem::path(f).lexically_normal());
  }
  count(WriteIfDifferent(result.folder / "index.html", ViewerPageHtml(options)));
  nlohmann::ordered_json product = {{"format", "carousel-site-product"},
                                    {"name", name},
                                    {"slug", slug},
                                    {"page", "index.html"},
                                    {"poster", options.poster}};
  count(WriteIfDifferent(result.folder / kProductFile, product.dump(2) + "\n"));

  // What an earlier publish left that this one no longer lists.
  std::vector<std::filesystem::path> stale;
  for (auto it = std::filesystem::recursive_directory_iterator(result.folder, ec);
       !ec && it != std::filesystem::recursive_directory_iterator(); it.increment(ec)) {
    if (!it->is_regular_file()) continue;
    const std::filesystem::path relative =
        std::filesystem::relative(it->path(), result.folder).lexically_normal();
    if (!wanted.count(relative)) stale.push_back(it->path());
  }
  for (const std::filesystem::path& p : stale)
    if (std::filesystem::remove(p, ec)) ++result.files_removed;
  return result;
}

int WriteSiteIndex(const std::filesystem::path& site, const std::string& title) {
  struct Card {
    std::string name, slug, poster;
  };
  std::vector<Card> cards;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(site, ec)) {
    const std::filesystem::path product = entry.path() / kProductFile;
    if (!entry.is_directory() || !std::filesystem::is_regular_file(product)) continue;
    const nlohmann::json json = ParseJsonFile(product);
    const JsonReader read(json, product);
    if (read.String("format") != "carousel-site-product")
      read.Fail("not a Carousel site product (format is not 'carousel-site-product')");
    Card card{read.String("name"), entry.path().filename().string(),
              read.OptionalString("poster").value_or("")};
    cards.push_back(std::move(card));
  }
  if (ec) throw IoError(site, "cannot list the site folder: " + ec.message());
  std::sort(cards.begin(), cards.end(), [](const Card& a, const Card& b) {
    return std::tie(a.name, a.slug) < std::tie(b.name, b.slug);
  });
  std::ostringstream html;
  html << HtmlPageOpening(title) << R"(<style>
  body { font-family: system-ui, sans-serif; margin: 1rem 1.5rem; color: #222; }
  h1 { font-size: 1.3rem; }
  ul { list-style: none; padding: 0; display: grid; gap: 1rem;
       grid-template-columns: repeat(auto-fill, minmax(220px, 1fr)); }
  li a { display: block; text-decoration: none; color: inherit; border: 1px solid #ddd;
         border-radius: 6px; padding: 0.5rem; }
  li img { width: 100%; height: auto; display: block; }
  li span { display: block; margin-top: 0.4rem; font-size: 0.95rem; }
</style>
</head>
<body>
<h1>)" << EscapeHtml(title)
       << "</h1>\n<p>" << cards.size() << (cards.size() == 1 ? " product" : " products")
       << "</p>\n<ul id=\"products\">\n";
  for (const Card& c : cards) {
    const std::string href = EscapeHtml(c.slug + "/index.html");
    html << "<li><a href=\"" << href << "\">";
    if (!c.poster.empty())
      html << "<img src=\"" << EscapeHtml(c.slug + "/" + c.poster) << "\" alt=\""
           << EscapeHtml(c.name) << "\" loading=\"lazy\">";
    html << "<span>" << EscapeHtml(c.name) << "</span></a></li>\n";
  }
  html << "</ul>\n</body>\n</html>\n";
  WriteIfDifferent(site / "index.html", html.str());
  return static_cast<int>(cards.size());
}

}  // namespace carousel::publish
