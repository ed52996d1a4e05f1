#include "carousel/texture/atlas.h"

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <numbers>

#include <Eigen/Geometry>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/raster.h"
#include "carousel/core/timer.h"
#include "face_graph.h"

namespace carousel::texture {
namespace {

using Corners2 = std::array<Eigen::Vector2d, 3>;
using Corners3 = std::array<Eigen::Vector3d, 3>;

double SignedArea(const Corners2& t) {
  return 0.5 * ((t[1] - t[0]).x() * (t[2] - t[0]).y() - (t[1] - t[0]).y() * (t[2] - t[0]).x());
}

double AngleAt(const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d u = b - a;
  const Eigen::Vector3d w = c - a;
  return std::atan2(u.cross(w).norm(), u.dot(w));
}

// The face's UVs and positions, corner k at the halfedge pointing to vertex k.
void FaceCorners(const Mesh& mesh, Mesh::FaceHandle face, Corners2* uv, Corners3* p) {
  int k = 0;
  for (const auto h : mesh.fh_range(face)) {
    if (k == 3) break;
    const auto q = mesh.uv(h);
    (*uv)[k] = Eigen::Vector2d(q[0], q[1]);
    const auto& x = mesh.point(mesh.to_vertex_handle(h));
    (*p)[k] = Eigen::Vector3d(x[0], x[1], x[2]);
    ++k;
  }
}

}  // namespace

const OptionTable<AtlasOptions>& AtlasOptions::Fields() {
  static const OptionTable<AtlasOptions> table =
      OptionTable<AtlasOptions>()
          .Include(&AtlasOptions::charts, ChartOptions::Fields())
          .Include(&AtlasOptions::parameterization, ParameterizationOptions::Fields())
          .Include(&AtlasOptions::packing, PackingOptions::Fields())
          .Include(&AtlasOptions::size, AtlasSizeOptions::Fields());
  return table;
}

void AtlasOptions::Validate() const {
  charts.Validate();
  parameterization.Validate();
  packing.Validate();
  size.Validate();
}

AtlasQuality MeasureAtlas(const Mesh& mesh, int atlas_size, int gutter_texels) {
  CAROUSEL_THROW_IF(!mesh.has_uvs(), InvalidArgument, "MeasureAtlas: the mesh has no UVs");
  CAROUSEL_THROW_IF(atlas_size < 16 || atlas_size > 32768 || gutter_texels < 0, InvalidArgument,
                    "MeasureAtlas: atlas size " << atlas_size << ", gutter " << gutter_texels);
  AtlasQuality q;
  int charts = 0;
  for (const auto f : mesh.faces()) charts = std::max(charts, mesh.chart_id(f) + 1);
  q.charts = charts;
  double area_3d = 0.0;
  double area_uv = 0.0;
  double stretch_sq = 0.0;
  double angle_error = 0.0;
  std::vector<double> face_stretch_sq(mesh.n_faces(), -1.0);
  std::vector<double> face_area_3d(mesh.n_faces(), 0.0);
  for (const auto f : mesh.faces()) {
    Corners2 t;
    Corners3 p;
    FaceCorners(mesh, f, &t, &p);
    bool finite = true;
    for (const auto& c : t) {
      finite = finite && c.allFinite();
      if (c.x() < 0.0 || c.x() > 1.0 || c.y() < 0.0 || c.y() > 1.0) ++q.uvs_outside;
    }
    if (!finite || mesh.chart_id(f) < 0) {
      ++q.faces_without_uvs;
      continue;
    }
    const double a_uv = SignedArea(t);
    const double a_3d = 0.5 * (p[1] - p[0]).cross(p[2] - p[0]).norm();
    if (!(a_uv > 0.0)) {
      ++q.flipped_faces;
      continue;
    }
    area_3d += a_3d;
    area_uv += a_uv;
    face_area_3d[f.idx()] = a_3d;
    const double l2_sq = internal::L2StretchSquared(p[0], p[1], p[2], t[0], t[1], t[2], a_uv);
    face_stretch_sq[f.idx()] = l2_sq;
    stretch_sq += l2_sq * a_3d;
    const Eigen::Vector3d t3d[3] = {Eigen::Vector3d(t[0].x(), t[0].y(), 0),
                                    Eigen::Vector3d(t[1].x(), t[1].y(), 0),
                                    Eigen::Vector3d(t[2].x(), t[2].y(), 0)};
    for (int k = 0; k < 3; ++k) {
      const double a2 = AngleAt(t3d[k], t3d[(k + 1) % 3], t3d[(k + 2) % 3]);
      const double a3 = AngleAt(p[k], p[(k + 1) % 3], p[(k + 2) % 3]);
      angle_error += std::abs(a2 - a3) * a_3d / 3.0;
    }
  }
  if (area_3d > 0.0 && area_uv > 0.0) {
    // Normalised so that the UV area equals the surface area.
    const double scale_sq = area_uv / area_3d;
    q.l2_stretch = std::sqrt(stretch_sq / area_3d * scale_sq);
    for (std::size_t f = 0; f < face_stretch_sq.size(); ++f)
      if (face_stretch_sq[f] >= 0.0 && face_area_3d[f] > 1e-12 * area_3d)
        q.max_face_stretch = std::max(q.max_face_stretch, std::sqrt(face_stretch_sq[f] * scale_sq));
    q.angle_distortion_deg = angle_error / area_3d * 180.0 / std::numbers::pi;
  }
  q.utilization = area_uv;

  // Texels: owner chart per texel (pixel-centre coverage), then each chart's footprint grown
  // by half the gutter must stay clear of the others'.
  cv::Mat owner(atlas_size, atlas_size, CV_32SC1, cv::Scalar(-1));
  std::vector<cv::Rect> bounds(charts);
  for (const auto f : mesh.faces()) {
    const int chart = mesh.chart_id(f);
    if (chart < 0) continue;
    Corners2 t;
    Corners3 p;
    FaceCorners(mesh, f, &t, &p);
    // Texel (x, y) (y down) has its centre at (x + 0.5, y + 0.5).
    for (auto& c : t)
      c = Eigen::Vector2d(c.x() * atlas_size - 0.5, (1.0 - c.y()) * atlas_size - 0.5);
    ForEachPixelCentreIn(t, atlas_size, atlas_size, [&](int x, int y) {
      int& o = owner.at<int>(y, x);
      if (o >= 0 && o != chart) ++q.overlapping_texels;
      o = chart;
      bounds[chart] |= cv::Rect(x, y, 1, 1);
    });
  }
  const int grow = std::max(0, (gutter_texels - 1) / 2);
  if (grow > 0) {
    cv::Mat claimed(atlas_size, atlas_size, CV_32SC1, cv::Scalar(-1));
    const cv::Mat kernel =
        cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * grow + 1, 2 * grow + 1));
    for (int chart = 0; chart < charts; ++chart) {
      if (bounds[chart].area() == 0) continue;
      const cv::Rect roi = (bounds[chart] + cv::Size(2 * grow, 2 * grow) - cv::Point(grow, grow)) &
                           cv::Rect(0, 0, atlas_size, atlas_size);
      cv::Mat mine = owner(roi) == chart;
      cv::dilate(mine, mine, kernel);
      for (int y = 0; y < roi.height; ++y) {
        const auto* m = mine.ptr<std::uint8_t>(y);
        auto* c = claimed.ptr<int>(y + roi.y) + roi.x;
        for (int x = 0; x < roi.width; ++x) {
          if (!m[x]) continue;
          if (c[x] >= 0 && c[x] != chart) ++q.gutter_violations;
          c[x] = chart;
        }
      }
    }
  }
  std::vector<int> chart_of_face(mesh.n_faces(), 0);
  for (const auto f : mesh.faces()) chart_of_face[f.idx()] = std::max(0, mesh.chart_id(f));
  const std::vector<int> loops = CountChartBoundaryLoops(mesh, chart_of_face, charts);
  for (const int l : loops) q.charts_not_disks += l == 1 ? 0 : 1;
  return q;
}

AtlasBuilder::AtlasBuilder(const Mesh& mesh) : mesh_(mesh) {
  CAROUSEL_THROW_IF(mesh.n_faces() == 0, InvalidArgument, "atlas: the mesh has no faces");
  for (const auto v : mesh.vertices()) {
    const auto& p = mesh.point(v);
    CAROUSEL_THROW_IF(!std::isfinite(p[0]) || !std::isfinite(p[1]) || !std::isfinite(p[2]),
                      InvalidArgument,
                      "atlas: vertex " << v.idx() << " has a non-finite coordinate");
  }
}

const ChartsResult& AtlasBuilder::ComputeCharts(const ChartOptions& options, Progress& progress) {
  charts_ = texture::ComputeCharts(mesh_, options, progress);
  flat_.reset();
  packed_.reset();
  return *charts_;
}

const ParameterizationResult& AtlasBuilder::Parameterize(const ParameterizationOptions& options,
                                                         Progress& progress) {
  CAROUSEL_THROW_IF(!charts_, InvalidArgument, "atlas: compute the charts before flattening");
  flat_ = ParameterizeCharts(mesh_, charts_->chart_of_face, charts_->charts, options, progress);
  packed_.reset();
  return *flat_;
}

int AtlasBuilder::Layout(const AtlasOptions& options, Progress& progress) {
  options.Validate();
  const int layouts = mesh_.n_faces() <= static_cast<std::size_t>(options.charts.layout_faces)
                          ? options.charts.layouts
                          : 1;
  const int side = options.size.size > 0 ? options.size.size
                                         : std::min(kProvisionalAtlasSize, options.size.max_size);
  std::optional<ChartsResult> best_charts;
  std::optional<ParameterizationResult> best_flat;
  double best_utilization = -1.0;
  double worst_utilization = 2.0;
  int best_layout = 0;
  double seconds_charts = 0.0;
  double seconds_flat = 0.0;
  for (int layout = 0; layout < layouts; ++layout) {
    ChartOptions charts = options.charts;
    charts.random_seed += static_cast<std::uint64_t>(layout);
    seconds_charts += ComputeCharts(charts, progress).seconds;
    seconds_flat += Parameterize(options.parameterization, progress).seconds;
    if (layouts == 1) return 1;
    const double utilization = Pack(options.packing, side, progress).utilization;
    worst_utilization = std::min(worst_utilization, utilization);
    if (utilization > best_utilization) {
      best_utilization = utilization;
      best_layout = layout;
      best_charts = charts_;
      best_flat = flat_;
    }
  }
  CAROUSEL_LOG_INFO("atlas: " << layouts << " chart layouts tried, utilization " << std::fixed
                              << std::setprecision(1) << 100.0 * worst_utilization << " .. "
                              << 100.0 * best_utilization << " %; kept the one from random seed "
                              << options.charts.random_seed + best_layout);
  charts_ = std::move(best_charts);
  flat_ = std::move(best_flat);
  charts_->seconds = seconds_charts;  // all layouts'
  flat_->seconds = seconds_flat;
  packed_.reset();
  return layouts;
}

const ChartsResult& AtlasBuilder::charts() const {
  CAROUSEL_THROW_IF(!charts_, InvalidArgument, "atlas: no charts computed yet");
  return *charts_;
}

const ParameterizationResult& AtlasBuilder::flattening() const {
  CAROUSEL_THROW_IF(!flat_, InvalidArgument, "atlas: no charts flattened yet");
  return *flat_;
}

const PackingResult& AtlasBuilder::Pack(const PackingOptions& options, int size,
                                        Progress& progress) {
  CAROUSEL_THROW_IF(!flat_, InvalidArgument, "atlas: flatten the charts before packing");
  packed_ = PackCharts(flat_->uv, flat_->chart_of_face, flat_->charts, size, options, progress);
  return *packed_;
}

void AtlasBuilder::Apply(Mesh* mesh) const {
  CAROUSEL_THROW_IF(!packed_, InvalidArgument, "atlas: pack the charts before applying them");
  CAROUSEL_THROW_IF(
      mesh->n_faces() != mesh_.n_faces(), InvalidArgument,
      "atlas: the mesh has " << mesh->n_faces() << " faces, the atlas " << mesh_.n_faces());
  for (const auto f : mesh->faces()) {
    mesh->set_chart_id(f, flat_->chart_of_face[f.idx()]);
    // Corner k of the atlas stages is the start of the face's k-th halfedge (from its first
    // halfedge); a halfedge carries the UV of the corner it points to, corner k + 1.
    auto h = mesh->halfedge_handle(f);
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d& uv = packed_->uv[f.idx()][(k + 1) % 3];
      mesh->set_uv(h, OpenMesh::Vec2d(uv.x(), uv.y()));
      h = mesh->next_halfedge_handle(h);
    }
  }
  mesh->set_has_uvs(true);
}

const PackingResult& AtlasBuilder::DecideSizeAndPack(const PackingOptions& packing,
                                                     const AtlasSizeOptions& size,
                                                     const std::vector<View>& views,
                                                     const std::vector<int>& front_view, Mesh* mesh,
                                                     Progress& progress) {
  size.Validate();
  const int first = size.size > 0 ? size.size : std::min(kProvisionalAtlasSize, size.max_size);
  Pack(packing, first, progress);
  Apply(mesh);
  if (size.size == 0 && !views.empty()) {
    const int chosen =
        ChooseTextureSize(*mesh, views, front_view, size.density_coverage, size.max_size);
    if (chosen != first) {
      Pack(packing, chosen, progress);
      Apply(mesh);
    }
  }
  return *packed_;
}

AtlasResult BuildAtlas(Mesh* mesh, const AtlasOptions& options, Progress& progress) {
  options.Validate();
  AtlasBuilder builder(*mesh);
  AtlasResult result;
  result.layouts = builder.Layout(options, progress);
  const ChartsResult& charts = builder.charts();
  result.seeds_grown_into = charts.charts;
  result.chart_iterations = charts.iterations;
  result.seconds_charts = charts.seconds;
  const ParameterizationResult& flat = builder.flattening();
  result.charts_split = flat.charts_split;
  result.seconds_parameterization = flat.seconds;
  const PackingResult& packed =
      builder.DecideSizeAndPack(options.packing, options.size, {}, {}, mesh, progress);
  result.size = packed.size;
  result.seconds_packing = packed.seconds;
  Stopwatch stopwatch;
  result.quality = MeasureAtlas(*mesh, packed.size, options.packing.gutter_texels);
  result.quality.texels_per_metre = packed.texels_per_metre;
  result.seconds_quality = stopwatch.ElapsedSeconds();
  return result;
}

cv::Mat DrawCharts(const Mesh& mesh, int size) {
  CAROUSEL_THROW_IF(size < 16 || size > 32768, InvalidArgument, "DrawCharts: size " << size);
  cv::Mat image(size, size, CV_8UC3, cv::Scalar(0, 0, 0));
  for (const auto f : mesh.faces()) {
    const int chart = mesh.chart_id(f);
    if (chart < 0) continue;
    // A colour per chart from a hash of its id, never too dark.
    const auto h = static_cast<std::uint32_t>(chart) * 2654435761u;
    const cv::Scalar colour(64 + (h & 0xbf), 64 + ((h >> 8) & 0xbf), 64 + ((h >> 16) & 0xbf));
    Corners2 t;
    Corners3 p;
    FaceCorners(mesh, f, &t, &p);
    constexpr int kShift = 4;
    std::array<cv::Point, 3> points;
    for (int k = 0; k < 3; ++k)
      points[k] = cv::Point(cvRound(t[k].x() * size * (1 << kShift)),
                            cvRound((1.0 - t[k].y()) * size * (1 << kShift)));
    cv::fillConvexPoly(image, points.data(), 3, colour, cv::LINE_8, kShift);
  }
  return image;
}

}  // namespace carousel::texture
