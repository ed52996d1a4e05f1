#include "carousel/studio/texture_session.h"

#include <algorithm>

#include <nlohmann/json.hpp>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/file_util.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/timer.h"
#include "carousel/sim/renderer.h"
#include "carousel/sim/scene.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

// The histogram as a bar chart (BGR).
cv::Mat PlotHistogram(const std::vector<int>& edges, const std::vector<int>& counts, int size) {
  const int width = 900, height = 420, left = 70, bottom = 70, top = 50;
  cv::Mat plot(height, width, CV_8UC3, cv::Scalar(255, 255, 255));
  const int peak = std::max(1, *std::max_element(counts.begin(), counts.end()));
  const int bars = static_cast<int>(counts.size());
  const double bar_width = static_cast<double>(width - left - 20) / bars;
  cv::putText(plot, "faces by texels per face (" + std::to_string(size) + "^2 atlas)", {left, 30},
              cv::FONT_HERSHEY_SIMPLEX, 0.6, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  for (int i = 0; i < bars; ++i) {
    const int h = static_cast<int>((height - top - bottom) * static_cast<double>(counts[i]) / peak);
    const int x0 = left + static_cast<int>(i * bar_width) + 2;
    const int x1 = left + static_cast<int>((i + 1) * bar_width) - 2;
    cv::rectangle(plot, {x0, height - bottom - h}, {x1, height - bottom}, cv::Scalar(180, 110, 40),
                  cv::FILLED);
    cv::putText(plot, std::to_string(counts[i]), {x0, height - bottom - h - 5},
                cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
    const std::string label =
        i + 1 < static_cast<int>(edges.size())
            ? std::to_string(edges[i]) + "-" + std::to_string(edges[i + 1] - 1)
            : ">=" + std::to_string(edges[i]);
    cv::putText(plot, label, {x0, height - bottom + 18}, cv::FONT_HERSHEY_SIMPLEX, 0.35,
                cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  }
  cv::line(plot, {left, height - bottom}, {width - 10, height - bottom}, cv::Scalar(0, 0, 0));
  cv::putText(plot, "texels per face", {width / 2 - 60, height - 20}, cv::FONT_HERSHEY_SIMPLEX, 0.5,
              cv::Scalar(0, 0, 0), 1, cv::LINE_AA);
  return plot;
}

// Mean SSIM (Gaussian 11x11, sigma 1.5, the usual constants) of two BGR images over `mask`.
double MaskedSsim(const cv::Mat& a, const cv::Mat& b, const cv::Mat& mask) {
  const cv::Scalar c1 = cv::Scalar::all(6.5025),
                   c2 = cv::Scalar::all(58.5225);  // (0.01, 0.03 x 255)^2
  cv::Mat fa, fb;
  a.convertTo(fa, CV_32F);
  b.convertTo(fb, CV_32F);
  auto blur = [](const cv::Mat& m) {
    cv::Mat out;
    cv::GaussianBlur(m, out, cv::Size(11, 11), 1.5);
    return out;
  };
  const cv::Mat mu_a = blur(fa), mu_b = blur(fb);
  const cv::Mat mu_aa = mu_a.mul(mu_a), mu_bb = mu_b.mul(mu_b), mu_ab = mu_a.mul(mu_b);
  const cv::Mat s_aa = blur(fa.mul(fa)) - mu_aa, s_bb = blur(fb.mul(fb)) - mu_bb,
                s_ab = blur(fa.mul(fb)) - mu_ab;
  cv::Mat t1, t2, t3, t4;
  cv::add(2 * mu_ab, c1, t1);
  cv::add(2 * s_ab, c2, t2);
  cv::add(mu_aa + mu_bb, c1, t3);
  cv::add(s_aa + s_bb, c2, t4);
  cv::Mat map;
  cv::divide(t1.mul(t2), t3.mul(t4), map);
  const cv::Scalar mean = cv::mean(map, mask);
  return (mean[0] + mean[1] + mean[2]) / 3.0;
}

HeldOutScore ScoreView(const sim::Scene& model, const View& view, int index,
                       const cv::Mat& reference_mask) {
  sim::RenderOptions render;
  render.lit = false;
  render.plate_radius_m = 0.0;
  render.noise_sigma = 0.0;
  const sim::RenderResult r = sim::Render(model, view.camera(), view.table_angle_rad(), render);
  const cv::Mat photo = view.Image();
  HeldOutScore score;
  score.view = index;
  cv::Mat mask = reference_mask >= 128;
  cv::Mat diff;
  cv::absdiff(r.image, photo, diff);
  diff.convertTo(diff, CV_64F);
  const cv::Scalar mse = cv::mean(diff.mul(diff), mask);
  const double m = (mse[0] + mse[1] + mse[2]) / 3.0;
  score.psnr_db = m > 0.0 ? 10.0 * std::log10(255.0 * 255.0 / m) : 99.0;
  score.ssim = MaskedSsim(r.image, photo, mask);
  const cv::Mat rendered = r.mask >= 128;
  const double both = cv::countNonZero(rendered & mask), either = cv::countNonZero(rendered | mask);
  score.mask_agreement = either > 0 ? both / either : 0.0;
  return score;
}

}  // namespace

void TextureSessionOptions::Validate() const {
  atlas.Validate();
  grouping.Validate();
  output.Validate();
  CAROUSEL_THROW_IF(size != 0 && (size < 64 || size > 16384), InvalidArgument,
                    "TextureSessionOptions.size must be 0 (automatic) or in [64, 16384]");
  CAROUSEL_THROW_IF(max_size < 512 || max_size > 16384, InvalidArgument,
                    "TextureSessionOptions.max_size must be in [512, 16384]");
  CAROUSEL_THROW_IF(!(density_coverage > 0.0 && density_coverage <= 1.0), InvalidArgument,
                    "TextureSessionOptions.density_coverage must be in (0, 1]");
}

TextureSessionResult TextureSession(const std::filesystem::path& session_folder,
                                    const TextureSessionOptions& options, Progress& progress) {
  options.Validate();
  Stopwatch total;
  Session session = ReadSession(session_folder);
  const std::filesystem::path mesh_path = session_folder / "recon" / "mesh.ply";
  if (!std::filesystem::exists(mesh_path))
    throw IoError(mesh_path, "no reconstructed mesh (run `carousel reconstruct` first)");
  std::vector<View> views = SessionViews(session_folder, session);
  if (options.grouping.correction)
    for (std::size_t i = 0; i < views.size(); ++i)
      if (session.views[i].mask.empty())
        throw FormatError(
            session_folder / kManifestName,
            "view " + std::to_string(i) + " (" + session.views[i].image +
                ") has no mask (run `carousel reconstruct` first, or --no-correction)");
  Mesh mesh = ReadMesh(mesh_path, {.read_uvs = false});
  TextureSessionResult result;
  result.views = static_cast<int>(views.size());
  result.faces = mesh.n_faces();

  Stopwatch watch;
  result.grouping = texture::GroupFaces(mesh, views, options.grouping, progress);
  result.seconds_grouping = watch.ElapsedSeconds();

  watch = Stopwatch();
  texture::AtlasBuilder builder(mesh);
  result.charts = builder.ComputeCharts(options.atlas.charts, progress).charts;
  builder.Parameterize(options.atlas.parameterization, progress);
  texture::PackingOptions packing = options.atlas.packing;
  packing.size = options.size > 0 ? options.size : std::min(4096, options.max_size);
  builder.Pack(packing, progress);
  builder.Apply(&mesh);
  if (options.size == 0) {
    const int chosen = texture::ChooseTextureSize(mesh, views, result.grouping.front_view,
                                                  options.density_coverage, options.max_size);
    if (chosen != packing.size) {
      packing.size = chosen;
      builder.Pack(packing, progress);
      builder.Apply(&mesh);
    }
  }
  result.size = packing.size;
  result.seconds_atlas = watch.ElapsedSeconds();

  watch = Stopwatch();
  texture::TransferOptions transfer = options.transfer;
  transfer.size = result.size;
  transfer.correction = options.grouping.correction;
  const texture::TextureMap map =
      texture::TransferTexture(mesh, views, result.grouping, transfer, progress);
  result.filled_faces = map.filled_faces;
  result.blended_texels = map.blended_texels;
  result.corrected_texels = map.corrected_texels;
  result.inpainted_texels = map.inpainted_texels;
  result.seconds_transfer = watch.ElapsedSeconds();

  // Report figures.
  result.histogram_edges = {0, 1, 11, 51, 101, 501, 1001, 5001};
  result.histogram_counts.assign(result.histogram_edges.size(), 0);
  int dense = 0, seen = 0;
  for (std::size_t f = 0; f < map.texels_per_face.size(); ++f) {
    const int t = map.texels_per_face[f];
    const auto bin =
        std::upper_bound(result.histogram_edges.begin(), result.histogram_edges.end(), t) -
        result.histogram_edges.begin() - 1;
    ++result.histogram_counts[std::max<std::ptrdiff_t>(bin, 0)];
    if (result.grouping.front_view[f] >= 0) {
      ++seen;
      if (map.density_ratio[f] >= 1.0) ++dense;
    }
  }
  result.dense_fraction = seen > 0 ? static_cast<double>(dense) / seen : 0.0;

  watch = Stopwatch();
  const std::filesystem::path model = session_folder / "model";
  result.files = texture::ExportTexturedModel(mesh, map.texture, model, options.output);
  nlohmann::json report;
  report["faces"] = result.faces;
  report["views"] = result.views;
  report["excluded_views"] = options.grouping.exclude_views;
  report["charts"] = result.charts;
  report["atlas_size"] = result.size;
  report["grouping"] = {{"unseen_faces", result.grouping.unseen_faces},
                        {"corrected_faces", result.grouping.corrected_faces},
                        {"uncorrectable_faces", result.grouping.uncorrectable_faces},
                        {"island_faces_switched", result.grouping.island_faces_switched}};
  report["filled_faces"] = result.filled_faces;
  report["blended_texels"] = result.blended_texels;
  report["corrected_texels"] = map.corrected_texels;
  report["inpainted_texels"] = map.inpainted_texels;
  report["texel_density"] = {
      {"faces_with_at_least_one_texel_per_photo_pixel", result.dense_fraction},
      {"per_face", map.density_ratio}};
  report["histogram"] = {{"texels_per_face_bin_starts", result.histogram_edges},
                         {"faces", result.histogram_counts}};
  std::vector<std::array<double, 3>> gains;
  for (const auto& g : map.gains) gains.push_back({g[0], g[1], g[2]});
  report["view_gains_bgr"] = gains;
  report["options"] = {{"blend", options.transfer.blend},
                       {"correction", options.grouping.correction},
                       {"gain", options.transfer.gain},
                       {"packing", texture::PackingModeName(options.atlas.packing.mode)}};
  WriteImage(model / "report.png",
             PlotHistogram(result.histogram_edges, result.histogram_counts, result.size));
  result.seconds_export = watch.ElapsedSeconds();
  // Held-out views: the model as a viewer shows it (the GLB), against the photos.
  watch = Stopwatch();
  if (!options.grouping.exclude_views.empty() && !result.files.glb.empty()) {
    const sim::Scene scene = sim::LoadScene(result.files.glb);
    for (const int v : options.grouping.exclude_views) {
      const std::string& truth = static_cast<std::size_t>(v) < session.ground_truth.masks.size()
                                     ? session.ground_truth.masks[v]
                                     : std::string();
      const cv::Mat reference = !truth.empty() ? ReadMask(session_folder / truth) : views[v].Mask();
      result.held_out.push_back(ScoreView(scene, views[v], v, reference));
    }
    for (const HeldOutScore& h : result.held_out) {
      result.mean_psnr_db += h.psnr_db / static_cast<double>(result.held_out.size());
      result.mean_ssim += h.ssim / static_cast<double>(result.held_out.size());
    }
    nlohmann::json scores = nlohmann::json::array();
    for (const HeldOutScore& h : result.held_out)
      scores.push_back({{"view", h.view},
                        {"psnr_db", h.psnr_db},
                        {"ssim", h.ssim},
                        {"silhouette_iou", h.mask_agreement}});
    report["held_out"] = {
        {"views", scores}, {"mean_psnr_db", result.mean_psnr_db}, {"mean_ssim", result.mean_ssim}};
  }
  result.seconds_evaluation = watch.ElapsedSeconds();
  result.seconds_total = total.ElapsedSeconds();
  report["seconds"] = {{"grouping", result.seconds_grouping},     {"atlas", result.seconds_atlas},
                       {"transfer", result.seconds_transfer},     {"export", result.seconds_export},
                       {"evaluation", result.seconds_evaluation}, {"png", result.files.seconds_png},
                       {"glb", result.files.seconds_glb},         {"total", result.seconds_total}};
  WriteFileAtomic(model / "report.json", report.dump(2));
  // The manifest last, once every file is on disk.
  session = ReadSession(session_folder);
  session.stages["texture"] = "done";
  WriteSessionManifest(session_folder, session);
  return result;
}

}  // namespace carousel::studio
