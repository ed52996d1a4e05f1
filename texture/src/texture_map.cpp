// TransferTexture (texture_map.h): its steps in order (texture_map_steps.h names the file of
// each), and the face data every step reads.
#include "carousel/texture/texture_map.h"

#include <cmath>

#include "carousel/core/error.h"
#include "carousel/core/timer.h"
#include "texture_map_steps.h"

namespace carousel::texture {
namespace internal {

std::vector<FaceData> ReadFaces(const Mesh& mesh) {
  std::vector<FaceData> faces(mesh.n_faces());
  for (const auto f : mesh.faces()) {
    FaceData& d = faces[f.idx()];
    std::array<Mesh::HalfedgeHandle, 3> h;
    int k = 0;
    for (const auto he : mesh.fh_range(f)) {
      if (k == 3) break;
      h[k++] = he;
    }
    CAROUSEL_THROW_IF(k != 3, InvalidArgument, "texture: face " << f.idx() << " is not a triangle");
    for (int i = 0; i < 3; ++i) {
      const auto& q = mesh.point(mesh.to_vertex_handle(h[i]));
      d.p[i] = Eigen::Vector3d(q[0], q[1], q[2]);
      const auto& t = mesh.uv(h[i]);
      d.uv[i] = Eigen::Vector2d(t[0], t[1]);
      // Edge (i, i + 1) is the halfedge from corner i to corner i + 1: h[i + 1].
      const auto across = mesh.opposite_face_handle(h[(i + 1) % 3]);
      d.across[i] = across.is_valid() ? across.idx() : -1;
    }
    const Eigen::Vector3d n = (d.p[1] - d.p[0]).cross(d.p[2] - d.p[0]);
    d.normal = n.norm() > 0.0 ? Eigen::Vector3d(n.normalized()) : Eigen::Vector3d::Zero();
    d.chart = mesh.chart_id(f);
  }
  return faces;
}

double ProjectedArea(const FaceData& f, const CameraModel& camera) {
  std::array<Eigen::Vector2d, 3> px;
  for (int i = 0; i < 3; ++i) {
    const auto p = camera.Project(f.p[i]);
    if (!p) return 0.0;
    px[i] = *p;
  }
  return 0.5 * std::abs((px[1] - px[0]).x() * (px[2] - px[0]).y() -
                        (px[1] - px[0]).y() * (px[2] - px[0]).x());
}

double UvArea(const FaceData& f) {
  return 0.5 * std::abs((f.uv[1] - f.uv[0]).x() * (f.uv[2] - f.uv[0]).y() -
                        (f.uv[1] - f.uv[0]).y() * (f.uv[2] - f.uv[0]).x());
}

void CheckViews(const std::vector<View>& views) {
  CAROUSEL_THROW_IF(views.empty(), InvalidArgument, "texture: no views");
  for (const View& v : views) v.camera().Validate();
}

}  // namespace internal

const OptionTable<TransferOptions>& TransferOptions::Fields() {
  using O = TransferOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::blend, {.name = "blend", .help = "seam blending between photos (the paper's Eq. 8)"});
    t.Add(&O::gain, {.name = "gain", .help = "per-photo colour gains (even out exposure)"});
    t.Add(&O::dilation_texels, {.name = "dilation",
                                .help = "texels the charts are grown by into the gutter",
                                .unit = "texels",
                                .min = 0,
                                .max = 64,
                                .advanced = true});
    t.Add(&O::zbuffer_max_side,
          {.name = "texel-zbuffer-max-side",
           .help = "per-texel occlusion test: longest side of the per-view depth buffers",
           .unit = "px",
           .min = 64,
           .max = 8192,
           .special = 0,
           .special_meaning = "off",
           .advanced = true});
    return t;
  }();
  return table;
}

void TransferOptions::Validate() const { Fields().Check(*this); }

TextureMap TransferTexture(const Mesh& mesh, const std::vector<View>& views,
                           const GroupingResult& grouping, int atlas_size,
                           const TransferOptions& options, Progress& progress) {
  options.Validate();
  CheckAtlasSize(atlas_size);
  internal::CheckViews(views);
  CAROUSEL_THROW_IF(!mesh.has_uvs(), InvalidArgument,
                    "texture: the mesh has no UVs (build its atlas first)");
  const int nv = static_cast<int>(views.size());
  CAROUSEL_THROW_IF(grouping.front_view.size() != mesh.n_faces() || grouping.views != nv ||
                        grouping.usable.size() != mesh.n_faces() * views.size() ||
                        grouping.seen.size() != grouping.usable.size(),
                    InvalidArgument, "texture: the grouping belongs to another mesh or view set");
  Stopwatch stopwatch;
  progress.BeginStage("texture: transfer");
  const std::vector<internal::FaceData> faces = internal::ReadFaces(mesh);
  internal::ViewSampler sampler(faces, views, grouping, options);
  if (options.gain) sampler.SetGains(internal::EstimateGains(faces, grouping, sampler));
  TextureMap result;
  result.gains = sampler.gains();
  const int size = atlas_size;
  result.texture = cv::Mat(size, size, CV_8UC3, cv::Scalar(0, 0, 0));
  result.coverage = cv::Mat(size, size, CV_8UC1, cv::Scalar(0));
  result.texels_per_face.assign(faces.size(), 0);
  result.density_ratio.assign(faces.size(), 0.0);
  const internal::TransferredTexels texels =
      internal::TransferCharts(faces, views, grouping, sampler, options, size, progress, &result);
  result.inpainted_texels = internal::InpaintHoles(texels.holes, &result);
  result.filled_faces = internal::FillUnseenFaces(faces, grouping.front_view, texels, &result);
  internal::DilateGutter(options.dilation_texels, &result);
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

}  // namespace carousel::texture
