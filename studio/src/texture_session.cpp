#include "carousel/studio/texture_session.h"

#include <algorithm>

#include "carousel/core/error.h"
#include "carousel/core/image_io.h"
#include "carousel/core/mesh_io.h"
#include "carousel/core/timer.h"
#include "carousel/studio/session.h"
#include "carousel/texture/held_out.h"
#include "carousel/texture/quality_report.h"
#include "carousel/texture/textured_model.h"

#include "held_out_reference.h"

namespace carousel::studio {

const OptionTable<TextureSessionOptions>& TextureSessionOptions::Fields() {
  static const OptionTable<TextureSessionOptions> table =
      OptionTable<TextureSessionOptions>()
          .Include(&TextureSessionOptions::atlas, texture::AtlasOptions::Fields())
          .Include(&TextureSessionOptions::grouping, texture::GroupingOptions::Fields())
          .Include(&TextureSessionOptions::transfer, texture::TransferOptions::Fields())
          .Include(&TextureSessionOptions::output, texture::ExportOptions::Fields());
  return table;
}

void TextureSessionOptions::Validate() const {
  atlas.Validate();
  grouping.Validate();
  transfer.Validate();
  output.Validate();
}

TextureSessionResult TextureSession(const std::filesystem::path& session_folder,
                                    const TextureSessionOptions& options, Progress& progress) {
  Session session = ReadSession(session_folder);
  return TextureSession(session_folder, session, options, progress);
}

TextureSessionResult TextureSession(const std::filesystem::path& session_folder, Session& session,
                                    const TextureSessionOptions& options, Progress& progress) {
  options.Validate();
  Stopwatch total;
  const std::filesystem::path mesh_path = session_folder / "recon" / "mesh.ply";
  if (!std::filesystem::exists(mesh_path))
    throw IoError(mesh_path, "no reconstructed mesh (run `carousel reconstruct` first)");
  std::vector<View> views = SessionViews(session_folder, session);
  TextureSessionResult result;
  // The missing-colour correction needs each photo's own silhouette: the mesh's projection
  // would agree with the mesh everywhere and correct nothing. Without masks (a dataset
  // imported with its mesh) it is skipped, and the run says so.
  bool correction = options.grouping.correction;
  // Over the views the model is made from (those of a later pass left out come after them).
  const auto no_mask = [](const SessionView& v) { return v.mask.empty(); };
  const auto used_end = session.views.begin() + static_cast<std::ptrdiff_t>(views.size());
  const auto unmasked = std::count_if(session.views.begin(), used_end, no_mask);
  if (correction && unmasked > 0) {
    correction = false;
    result.warnings.push_back(
        std::to_string(unmasked) + " of " + std::to_string(views.size()) +
        " views have no mask (the first: " +
        std::find_if(session.views.begin(), used_end, no_mask)->image +
        "): the missing-colour correction is skipped (masks come from `carousel reconstruct` "
        "or `carousel import --masks`)");
  }
  texture::GroupingOptions grouping = options.grouping;
  grouping.correction = correction;
  grouping.view_pass.clear();
  for (std::size_t i = 0; i < views.size(); ++i)
    grouping.view_pass.push_back(session.views[i].pass);
  Mesh mesh = ReadMesh(mesh_path, {.read_uvs = false});
  result.views = static_cast<int>(views.size());
  result.faces = mesh.n_faces();

  Stopwatch watch;
  result.grouping = texture::GroupFaces(mesh, views, grouping, progress);
  result.seconds_grouping = watch.ElapsedSeconds();

  watch = Stopwatch();
  texture::AtlasBuilder builder(mesh);
  builder.Layout(options.atlas, progress);
  result.charts = builder.charts().charts;
  // The atlas side, decided once (automatic: from the faces' front photos).
  result.size = builder
                    .DecideSizeAndPack(options.atlas.packing, options.atlas.size, views,
                                       result.grouping.front_view, &mesh, progress)
                    .size;
  result.seconds_atlas = watch.ElapsedSeconds();

  watch = Stopwatch();
  texture::TransferOptions transfer = options.transfer;
  transfer.correction = correction;
  const texture::TextureMap map =
      texture::TransferTexture(mesh, views, result.grouping, result.size, transfer, progress);
  result.filled_faces = map.filled_faces;
  result.blended_texels = map.blended_texels;
  result.corrected_texels = map.corrected_texels;
  result.occluded_texels = map.occluded_texels;
  result.inpainted_texels = map.inpainted_texels;
  result.seconds_transfer = watch.ElapsedSeconds();

  // Report figures.
  texture::QualityReport report = texture::SummarizeTexture(result.grouping, map);
  result.histogram_edges = report.histogram.edges;
  result.histogram_counts = report.histogram.counts;
  result.dense_fraction = report.dense_fraction;

  watch = Stopwatch();
  const std::filesystem::path model = session_folder / "model";
  result.files = texture::ExportTexturedModel(mesh, map.texture, model, options.output);
  result.seconds_export = watch.ElapsedSeconds();
  // Held-out views: the model as a viewer shows it (read back from the GLB; from memory when
  // no GLB is written), against the photos.
  watch = Stopwatch();
  if (!options.grouping.exclude_views.empty()) {
    const texture::TexturedModel viewed = !result.files.glb.empty()
                                              ? texture::ReadTexturedModel(result.files.glb)
                                              : texture::TexturedModelFromMesh(mesh, map.texture);
    for (const int v : options.grouping.exclude_views) {
      const cv::Mat reference = HeldOutReferenceMask(session_folder, session, views, v);
      result.held_out.push_back(texture::ScoreHeldOutView(viewed, views[v], v, reference));
    }
    result.mean_psnr_db = texture::MeanPsnrDb(result.held_out);
    result.mean_ssim = texture::MeanSsim(result.held_out);
  }
  result.seconds_evaluation = watch.ElapsedSeconds();
  result.seconds_total = total.ElapsedSeconds();

  report.faces = result.faces;
  report.views = result.views;
  report.excluded_views = options.grouping.exclude_views;
  report.warnings = result.warnings;
  report.charts = result.charts;
  report.atlas_size = result.size;
  report.blend = options.transfer.blend;
  report.correction = correction;
  report.gain = options.transfer.gain;
  report.packing = texture::PackingModeName(options.atlas.packing.mode);
  report.held_out = result.held_out;
  report.seconds = {.grouping = result.seconds_grouping,
                    .atlas = result.seconds_atlas,
                    .transfer = result.seconds_transfer,
                    .export_model = result.seconds_export,
                    .evaluation = result.seconds_evaluation,
                    .png = result.files.seconds_png,
                    .glb = result.files.seconds_glb,
                    .total = result.seconds_total};
  texture::WriteQualityReport(report, model);
  // The manifest last, once every file is on disk.
  session.stages["texture"] = "done";
  WriteSessionManifest(session_folder, session);
  return result;
}

}  // namespace carousel::studio
