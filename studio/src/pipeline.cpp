#include "carousel/studio/pipeline.h"

#include <iomanip>
#include <sstream>

#include <nlohmann/json.hpp>

#include "carousel/core/error.h"
#include "carousel/core/json.h"
#include "carousel/core/logging.h"
#include "carousel/core/timer.h"
#include "carousel/studio/checksum.h"
#include "carousel/studio/session.h"

namespace carousel::studio {
namespace {

constexpr const char* kReconstruct = "reconstruct";
constexpr const char* kTexture = "texture";
constexpr const char* kPublish = "publish";

// Writes "name=value;" with doubles at full precision, so any change of a value shows.
class Describer {
 public:
  template <typename T>
  Describer& operator()(const char* name, const T& value) {
    out_ << name << '=' << value << ';';
    return *this;
  }
  Describer& operator()(const char* name, double value) {
    out_ << name << '=' << std::setprecision(17) << value << ';';
    return *this;
  }
  Describer& operator()(const char* name, bool value) {
    out_ << name << '=' << (value ? 1 : 0) << ';';
    return *this;
  }
  std::string str() const { return out_.str(); }

 private:
  std::ostringstream out_;
};

// Every option that changes what the stage produces (thread counts do not).
std::string Describe(const ReconstructOptions& o) {
  const recon::SilhouetteOptions& s = o.silhouettes;
  const recon::VisualHullOptions& h = o.hull;
  const recon::MeshOptimizationOptions& m = o.mesh;
  const recon::RegistrationOptions& r = o.registration;
  return Describer()("method", static_cast<int>(s.method))("noise", s.noise_threshold)(
             "chroma", s.chroma_threshold)("shadow", s.min_shadow_brightness)(
             "highlight", s.max_highlight_brightness)("plate", s.plate_radius_m)(
             "rim_m", s.plate_rim_m)("rim_px", s.plate_rim_px)("refine", s.refine_boundary)(
             "segmentation", 2)("border", s.check_border)("multi_view", s.multi_view)(
             "component", s.min_component_fraction)("hole", s.max_hole_fraction)(
             "voxel", h.voxel_size_m)("resolution", h.resolution)("voxel_px", h.voxel_px)(
             "max_resolution", h.max_resolution)("floor", h.use_floor)("floor_z", h.floor_z_m)(
             "consistency", h.min_view_consistency)("cells", h.max_surface_cells)(
             "proxy", h.proxy_max_faces)("faces", m.target_faces)("smooth", m.smoothing_iterations)(
             "lambda", m.taubin_lambda)("mu", m.taubin_mu)("remesh", m.remesh)(
             "remesh_iterations", m.remesh_iterations)("remesh_factor", m.remesh_face_factor)(
             "normal", m.max_normal_deviation_deg)("aspect", m.max_aspect_ratio)(
             "volume", m.target_volume_m3)("max_deviation", o.max_outline_deviation_px)(
             "rotations", r.rotations)("candidates", r.candidates)("distinct", r.distinct_deg)(
             "ambiguity", r.ambiguity_ratio)("inconsistent", r.max_inconsistent)(
             "points", r.points)("registration_side", r.max_side_px)("by_colour", r.colour)
      .str();
}

std::string Describe(const TextureSessionOptions& o) {
  const texture::ChartOptions& c = o.atlas.charts;
  const texture::ParameterizationOptions& p = o.atlas.parameterization;
  const texture::PackingOptions& k = o.atlas.packing;
  const texture::GroupingOptions& g = o.grouping;
  const texture::TransferOptions& t = o.transfer;
  const texture::ExportOptions& e = o.output;
  std::ostringstream excluded;
  for (const int v : g.exclude_views) excluded << v << ',';
  return Describer()("seeds", c.seeds)("faces_per_seed", c.faces_per_seed)(
             "normal", c.max_normal_deviation_deg)("compactness", c.compactness)(
             "chart_iterations", c.max_iterations)("random", c.random_seed)(
             "abf_iterations", p.max_abf_iterations)("abf_tolerance", p.abf_tolerance)(
             "split", p.max_split_depth)("stretch", p.max_chart_stretch)(
             "packing", static_cast<int>(k.mode))("atlas_size", 4096)("gutter", k.gutter_texels)(
             "exclude", excluded.str())("correction", g.correction)("island", g.max_island_faces)(
             "zbuffer", g.zbuffer_max_side)("transfer_size", 4096)("blend", t.blend)(
             "gain", t.gain)("transfer_correction", t.correction)("dilation", t.dilation_texels)(
             "name", e.name)("glb", e.glb)("jpeg", e.jpeg_in_glb)("jpeg_quality", e.jpeg_quality)(
             "png", e.png_compression)("size", o.atlas.size.size)(
             "max_size", o.atlas.size.max_size)("coverage", o.atlas.size.density_coverage)
      .str();
}

std::string Describe(const PublishSessionOptions& o) {
  return Describer()("web_size", o.web.max_texture_size)("web_quality", o.web.jpeg_quality)(
             "unlit", o.web.unlit)("meshopt", o.web.compress)("poster", o.poster_size)
      .str();
}

bool AllExist(const std::filesystem::path& folder, const std::vector<std::string>& files) {
  for (const std::string& f : files) {
    if (!std::filesystem::is_regular_file(folder / f)) return false;
  }
  return true;
}

// Why `stage` must run ("" = it is current).
std::string Staleness(const Session& session, const char* stage, const std::string& fingerprint,
                      bool outputs_present) {
  const auto done = session.stages.find(stage);
  if (done == session.stages.end() || done->second != "done") return "not done yet";
  if (!outputs_present) return "outputs missing";
  const auto recorded = session.stage_inputs.find(stage);
  if (recorded == session.stage_inputs.end()) return "inputs not recorded";
  if (recorded->second != fingerprint) return "inputs or options changed";
  return "";
}

// The reconstruction's fingerprint: every photo as it is on disk now (read again, never the
// checksum recorded at capture, so that a photo damaged or replaced since makes the stage stale),
// its pose and the options. The photos whose file no longer matches their recorded checksum are
// added to *changed (when given).
std::string ReconstructInputs(const std::filesystem::path& folder, const Session& session,
                              const ReconstructOptions& options,
                              std::vector<std::string>* changed) {
  std::ostringstream inputs;
  inputs << "frame=" << session.frame << '\n';
  for (const SessionView& view : session.views) {
    const std::string sha = FileSha256(folder / view.image);
    if (changed != nullptr && !view.sha256.empty() && view.sha256 != sha)
      changed->push_back(view.image);
    inputs << view.image << ' ' << sha << ' ' << std::setprecision(17) << view.table_angle_deg
           << ' ' << CameraModelToJson(view.camera_model).dump() << '\n';
    // The silhouettes' own sources: the mask shot, a given mask.
    for (const auto& [file, recorded] : {std::pair{view.mask_shot, view.mask_shot_sha256},
                                         std::pair{view.given_mask, view.given_mask_sha256}}) {
      if (file.empty()) continue;
      const std::string file_sha = FileSha256(folder / file);
      if (changed != nullptr && !recorded.empty() && recorded != file_sha) changed->push_back(file);
      inputs << file << ' ' << file_sha << '\n';
    }
  }
  // The operator's choices of pose (the option itself only records them in the session).
  for (std::size_t pass = 1; pass < session.passes.size(); ++pass)
    if (session.passes[pass].chosen_pose > 0)
      inputs << "pass " << pass << " pose " << session.passes[pass].chosen_pose << '\n';
  inputs << Describe(options);
  return Sha256(inputs.str());
}

void RecordInputs(const std::filesystem::path& folder, Session& session, const char* stage,
                  const std::string& fingerprint, double seconds) {
  session.stage_inputs[stage] = fingerprint;
  session.stage_seconds[stage] = seconds;
  WriteSessionManifest(folder, session);
}

}  // namespace

void ProcessOptions::Validate() const {
  reconstruct.Validate();
  texture.Validate();
  publish.Validate();
}

std::string ReconstructFingerprint(const std::filesystem::path& folder,
                                   const ReconstructOptions& options) {
  return ReconstructFingerprint(folder, ReadSession(folder), options);
}

std::string ReconstructFingerprint(const std::filesystem::path& folder, const Session& session,
                                   const ReconstructOptions& options) {
  return ReconstructInputs(folder, session, options, nullptr);
}

std::string TextureFingerprint(const std::filesystem::path& folder,
                               const std::string& reconstruct_fingerprint,
                               const TextureSessionOptions& options) {
  return Sha256(reconstruct_fingerprint + '\n' + FileSha256(folder / "recon" / "mesh.ply") + '\n' +
                Describe(options));
}

ProcessResult ProcessSession(const std::filesystem::path& folder, const ProcessOptions& options,
                             Progress& progress) {
  Session session = ReadSession(folder);
  return ProcessSession(folder, session, options, progress);
}

ProcessResult ProcessSession(const std::filesystem::path& folder, Session& session,
                             const ProcessOptions& options, Progress& progress) {
  options.Validate();
  ProcessResult result;
  // A mask edited by hand since the reconstruction is taken as given from now on.
  const std::vector<std::string> edited_masks = AdoptEditedMasks(folder, session);
  ApplyPoseChoices(session, options.reconstruct.choose_pose);
  std::vector<std::string> changed_photos;
  const std::string recon_inputs =
      ReconstructInputs(folder, session, options.reconstruct, &changed_photos);
  // The views the model is made from (a later pass left out by the last reconstruction has
  // no masks and needs none).
  bool masks_present = true;
  const std::size_t used = SessionViews(folder, session).size();
  for (std::size_t i = 0; i < used; ++i) {
    const SessionView& view = session.views[i];
    masks_present =
        masks_present && !view.mask.empty() && std::filesystem::is_regular_file(folder / view.mask);
  }
  result.reconstruct_reason =
      options.force
          ? "forced"
          : Staleness(session, kReconstruct, recon_inputs,
                      masks_present && AllExist(folder, {"recon/hull.ply", "recon/mesh.ply"}));
  if (result.reconstruct_reason == "inputs or options changed" && !changed_photos.empty()) {
    result.reconstruct_reason =
        "photo " + changed_photos.front() +
        (changed_photos.size() > 1 ? " and " + std::to_string(changed_photos.size() - 1) + " more"
                                   : std::string()) +
        " changed since capture (checksum differs from session.json)";
  }
  if (!options.force && !edited_masks.empty()) {
    result.reconstruct_reason =
        "mask " + edited_masks.front() +
        (edited_masks.size() > 1 ? " and " + std::to_string(edited_masks.size() - 1) + " more"
                                 : std::string()) +
        " edited since the reconstruction (kept under masks/given/ and checked against the other "
        "views)";
  }
  if (!result.reconstruct_reason.empty()) {
    CAROUSEL_LOG_INFO(folder.string()
                      << ": reconstruct runs (" << result.reconstruct_reason << ")");
    Stopwatch watch;
    result.reconstruct = ReconstructSession(folder, session, options.reconstruct, progress);
    result.seconds_reconstruct = watch.ElapsedSeconds();
    RecordInputs(folder, session, kReconstruct, recon_inputs, result.seconds_reconstruct);
  } else {
    result.reconstruct_reason = "current";
  }

  const std::string texture_inputs = TextureFingerprint(folder, recon_inputs, options.texture);
  const std::string stem = "model/" + options.texture.output.name;
  std::vector<std::string> outputs = {stem + ".obj", stem + ".mtl", stem + ".png"};
  if (options.texture.output.glb) outputs.push_back(stem + ".glb");
  result.texture_reason =
      (options.force || result.reconstruct)
          ? (options.force ? "forced" : "the reconstruction ran")
          : Staleness(session, kTexture, texture_inputs, AllExist(folder, outputs));
  if (!result.texture_reason.empty()) {
    CAROUSEL_LOG_INFO(folder.string() << ": texture runs (" << result.texture_reason << ")");
    Stopwatch watch;
    result.texture = TextureSession(folder, session, options.texture, progress);
    result.seconds_texture = watch.ElapsedSeconds();
    RecordInputs(folder, session, kTexture, texture_inputs, result.seconds_texture);
  } else {
    result.texture_reason = "current";
  }
  if (!options.publish_model || !options.texture.output.glb ||
      options.texture.output.name != "model")
    return result;
  const std::string publish_inputs =
      Sha256(texture_inputs + '\n' + FileSha256(folder / (stem + ".glb")) + '\n' +
             Describe(options.publish));
  result.publish_reason =
      (options.force || result.texture)
          ? (options.force ? "forced" : "the texture ran")
          : Staleness(
                session, kPublish, publish_inputs,
                AllExist(folder, {"model/model.web.glb", "model/index.html", "model/poster.jpg",
                                  "model/hero.jpg", "model/publish.json"}));
  if (!result.publish_reason.empty()) {
    CAROUSEL_LOG_INFO(folder.string() << ": publish runs (" << result.publish_reason << ")");
    Stopwatch watch;
    progress.BeginStage("publish");
    result.publish = PublishSession(folder, session, options.publish, progress);
    progress.EndStage();
    session.stages[kPublish] = "done";
    result.seconds_publish = watch.ElapsedSeconds();
    RecordInputs(folder, session, kPublish, publish_inputs, result.seconds_publish);
  } else {
    result.publish_reason = "current";
  }
  return result;
}

}  // namespace carousel::studio
