#include "carousel/studio/publish_session.h"

#include <opencv2/imgcodecs.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/json.h"
#include "carousel/core/timer.h"
#include "carousel/publish/renders.h"
#include "carousel/publish/viewer_page.h"

#include "held_out_reference.h"

namespace carousel::studio {

const OptionTable<PublishSessionOptions>& PublishSessionOptions::Fields() {
  using O = PublishSessionOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Include(&O::web, publish::WebGlbOptions::Fields());
    t.Add(&O::poster_size, {.name = "poster-size",
                            .help = "side of the viewer page's poster (the hero shot)",
                            .unit = "px",
                            .min = 64,
                            .max = 4096,
                            .advanced = true});
    return t;
  }();
  return table;
}

void PublishSessionOptions::Validate() const {
  Fields().Check(*this);
  web.Validate();
}

PublishSessionResult PublishSession(const std::filesystem::path& session_folder,
                                    const Session& session, const PublishSessionOptions& options,
                                    Progress& progress) {
  options.Validate();
  Stopwatch total;
  const std::filesystem::path model_folder = session_folder / "model";
  const std::filesystem::path lossless = model_folder / "model.glb";
  std::error_code ec;
  if (!std::filesystem::is_regular_file(lossless, ec))
    throw IoError(lossless, "no textured model to publish (run `carousel texture` first)");
  const publish::WebRuntime runtime = publish::FindWebRuntime();
  PublishSessionResult result;
  result.lossless_bytes = std::filesystem::file_size(lossless);
  const texture::TexturedModel model = texture::ReadTexturedModel(lossless);
  progress.Report(0.1);

  const std::filesystem::path web_path = model_folder / "model.web.glb";
  result.web = publish::WriteWebGlb(model, web_path, options.web);
  progress.Report(0.3);

  // The held-out views of the texture stage (report.json), scored for both files.
  const std::filesystem::path report_path = model_folder / "report.json";
  std::vector<int> excluded;
  if (std::filesystem::is_regular_file(report_path, ec)) {
    const nlohmann::json report = ParseJsonFile(report_path);
    const JsonReader reader(report, report_path);
    if (reader.Has("excluded_views")) excluded = reader.Member("excluded_views").AsInts();
  }
  if (!excluded.empty()) {
    const texture::TexturedModel web = publish::ReadWebGlb(web_path);
    const std::vector<View> views = SessionViews(session_folder, session);
    for (const int v : excluded) {
      if (v < 0 || static_cast<std::size_t>(v) >= views.size())
        throw FormatError(report_path,
                          "excluded view " + std::to_string(v) + " is not a view of the session");
      const cv::Mat reference = HeldOutReferenceMask(session_folder, session, views, v);
      result.held_out_lossless.push_back(texture::ScoreHeldOutView(model, views[v], v, reference));
      result.held_out_web.push_back(texture::ScoreHeldOutView(web, views[v], v, reference));
      progress.CheckCancelled();
    }
    result.mean_psnr_lossless_db = texture::MeanPsnrDb(result.held_out_lossless);
    result.mean_psnr_web_db = texture::MeanPsnrDb(result.held_out_web);
  }
  progress.Report(0.7);

  publish::OrbitShot hero;
  hero.width = hero.height = options.poster_size;
  std::vector<std::uint8_t> poster;
  if (!cv::imencode(".jpg", publish::RenderShot(model, hero), poster,
                    {cv::IMWRITE_JPEG_QUALITY, 88}))
    throw IoError(model_folder / "poster.jpg", "JPEG encoding failed");
  WriteFileAtomic(model_folder / "poster.jpg",
                  std::span<const std::uint8_t>(poster.data(), poster.size()));
  publish::WriteViewerPage(
      model_folder, {.title = session.product, .glb = "model.web.glb", .poster = "poster.jpg"},
      runtime);
  progress.Report(0.9);

  nlohmann::ordered_json summary;
  summary["lossless_glb"] = {{"file", "model.glb"}, {"bytes", result.lossless_bytes}};
  summary["web_glb"] = {{"file", "model.web.glb"},
                        {"bytes", result.web.bytes},
                        {"texture_bytes", result.web.texture_bytes},
                        {"texture_size", result.web.texture_size},
                        {"geometry_bytes", result.web.geometry_bytes},
                        {"geometry_raw_bytes", result.web.geometry_raw_bytes},
                        {"vertices", result.web.vertices},
                        {"triangles", result.web.triangles},
                        {"jpeg_quality", options.web.jpeg_quality},
                        {"unlit", options.web.unlit},
                        {"meshopt", options.web.compress}};
  if (!excluded.empty()) {
    nlohmann::ordered_json views = nlohmann::ordered_json::array();
    for (std::size_t i = 0; i < excluded.size(); ++i)
      views.push_back({{"view", excluded[i]},
                       {"psnr_db_lossless", result.held_out_lossless[i].psnr_db},
                       {"psnr_db_web", result.held_out_web[i].psnr_db},
                       {"ssim_lossless", result.held_out_lossless[i].ssim},
                       {"ssim_web", result.held_out_web[i].ssim}});
    summary["held_out"] = {{"views", views},
                           {"mean_psnr_db_lossless", result.mean_psnr_lossless_db},
                           {"mean_psnr_db_web", result.mean_psnr_web_db}};
  }
  summary["files"] = {"index.html", "model.web.glb", "poster.jpg", "model-viewer.min.js",
                      "meshopt_decoder.js"};
  WriteFileAtomic(model_folder / "publish.json", summary.dump(2) + "\n");
  result.seconds = total.ElapsedSeconds();
  progress.Report(1.0);
  return result;
}

}  // namespace carousel::studio
