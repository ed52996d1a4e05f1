#include "carousel/recon/mesh_optimization.h"

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <queue>
#include <utility>
#include <vector>

#include <OpenMesh/Tools/Decimater/DecimaterT.hh>
#include <OpenMesh/Tools/Decimater/ModAspectRatioT.hh>
#include <OpenMesh/Tools/Decimater/ModNormalFlippingT.hh>
#include <OpenMesh/Tools/Decimater/ModQuadricT.hh>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/mesh_query.h"
#include "carousel/core/timer.h"
#include "quadric_decimation.h"

namespace carousel::recon {
namespace {

using Point = Mesh::Point;

Point FaceNormalWith(const Point& a, const Point& b, const Point& c) {
  return OpenMesh::cross(b - a, c - a);
}

// Would collapsing halfedge h (its from-vertex moves onto its to-vertex) flip or crush a face
// that survives? Compares each surviving face's normal before and after.
bool CollapseKeepsOrientation(const Mesh& mesh, Mesh::HalfedgeHandle h) {
  const auto v0 = mesh.from_vertex_handle(h);
  const auto v1 = mesh.to_vertex_handle(h);
  const Point& target = mesh.point(v1);
  for (const auto face : mesh.vf_range(v0)) {
    Point p[3];
    bool has_v1 = false;
    int k = 0;
    for (const auto v : mesh.fv_range(face)) {
      if (v == v1) has_v1 = true;
      p[k++] = mesh.point(v);
    }
    if (has_v1) continue;  // removed by the collapse
    const Point before = FaceNormalWith(p[0], p[1], p[2]);
    k = 0;
    for (const auto v : mesh.fv_range(face)) {
      if (v == v0) p[k] = target;
      ++k;
    }
    const Point after = FaceNormalWith(p[0], p[1], p[2]);
    const double nb = before.norm();
    const double na = after.norm();
    if (!(na > 0.0) || !(nb > 0.0)) return false;
    if (OpenMesh::dot(before, after) < 0.5 * na * nb) return false;  // > 60 degrees
  }
  return true;
}

// Longest edge first (Rivara bisection): splitting arbitrary long edges can cascade without
// end around the needle fans decimation leaves on flat regions; longest-first terminates.
void SplitLongEdges(Mesh* mesh, double high) {
  const double high_sq = high * high;
  auto length_sq = [&](Mesh::EdgeHandle e) {
    const auto h = mesh->halfedge_handle(e, 0);
    return (mesh->point(mesh->to_vertex_handle(h)) - mesh->point(mesh->from_vertex_handle(h)))
        .sqrnorm();
  };
  std::priority_queue<std::pair<double, int>> queue;
  for (const auto e : mesh->edges())
    if (const double l = length_sq(e); l > high_sq) queue.emplace(l, e.idx());
  while (!queue.empty()) {
    const auto [l, index] = queue.top();
    queue.pop();
    const Mesh::EdgeHandle e(index);
    if (mesh->status(e).deleted() || length_sq(e) != l) continue;  // changed since queued
    const auto h = mesh->halfedge_handle(e, 0);
    const Point middle =
        0.5 * (mesh->point(mesh->from_vertex_handle(h)) + mesh->point(mesh->to_vertex_handle(h)));
    const auto v = mesh->add_vertex(middle);
    mesh->split(e, v);
    for (const auto edge : mesh->ve_range(v))
      if (const double le = length_sq(edge); le > high_sq) queue.emplace(le, edge.idx());
  }
}

void CollapseShortEdges(Mesh* mesh, double low, double high) {
  const double low_sq = low * low;
  const double high_sq = high * high;
  for (std::size_t i = 0; i < mesh->n_edges(); ++i) {
    const Mesh::EdgeHandle e(static_cast<int>(i));
    if (mesh->status(e).deleted()) continue;
    const auto h0 = mesh->halfedge_handle(e, 0);
    const auto v0 = mesh->from_vertex_handle(h0);
    const auto v1 = mesh->to_vertex_handle(h0);
    if ((mesh->point(v1) - mesh->point(v0)).sqrnorm() >= low_sq) continue;
    for (const auto h : {h0, mesh->halfedge_handle(e, 1)}) {
      const auto from = mesh->from_vertex_handle(h);
      const auto to = mesh->to_vertex_handle(h);
      bool too_long = false;
      for (const auto n : mesh->vv_range(from))
        too_long = too_long || (mesh->point(n) - mesh->point(to)).sqrnorm() > high_sq;
      if (too_long || !mesh->is_collapse_ok(h) || !CollapseKeepsOrientation(*mesh, h)) continue;
      mesh->collapse(h);
      break;
    }
  }
  mesh->garbage_collection();
}

int Valence(const Mesh& mesh, Mesh::VertexHandle v) { return static_cast<int>(mesh.valence(v)); }

void EqualizeValences(Mesh* mesh) {
  for (const auto e : mesh->edges()) {
    if (!mesh->is_flip_ok(e)) continue;
    const auto h0 = mesh->halfedge_handle(e, 0);
    const auto h1 = mesh->halfedge_handle(e, 1);
    const auto a = mesh->to_vertex_handle(h0);
    const auto b = mesh->to_vertex_handle(h1);
    const auto c = mesh->to_vertex_handle(mesh->next_halfedge_handle(h0));
    const auto d = mesh->to_vertex_handle(mesh->next_halfedge_handle(h1));
    const int before = std::abs(Valence(*mesh, a) - 6) + std::abs(Valence(*mesh, b) - 6) +
                       std::abs(Valence(*mesh, c) - 6) + std::abs(Valence(*mesh, d) - 6);
    const int after = std::abs(Valence(*mesh, a) - 7) + std::abs(Valence(*mesh, b) - 7) +
                      std::abs(Valence(*mesh, c) - 5) + std::abs(Valence(*mesh, d) - 5);
    if (after >= before) continue;
    // Geometry: the two new triangles (c, d, ...) must face the way the old ones did.
    const Point pa = mesh->point(a), pb = mesh->point(b), pc = mesh->point(c), pd = mesh->point(d);
    // Old faces: (b, a, c)... use the face normals of the two adjacent faces.
    const Point n_old = FaceNormalWith(pb, pa, pc) + FaceNormalWith(pa, pb, pd);
    const Point n1 = FaceNormalWith(pc, pd, pa);
    const Point n2 = FaceNormalWith(pd, pc, pb);
    if (OpenMesh::dot(n1, n_old) <= 0.0 || OpenMesh::dot(n2, n_old) <= 0.0 ||
        OpenMesh::dot(n1, n2) <= 0.0)
      continue;
    mesh->flip(e);
  }
}

void TangentialRelaxation(Mesh* mesh) {
  mesh->update_face_normals();
  mesh->update_vertex_normals();
  std::vector<Point> moved(mesh->n_vertices());
  for (const auto v : mesh->vertices()) {
    Point centroid(0.0, 0.0, 0.0);
    int n = 0;
    for (const auto w : mesh->vv_range(v)) {
      centroid += mesh->point(w);
      ++n;
    }
    const Point p = mesh->point(v);
    if (n == 0) {
      moved[v.idx()] = p;
      continue;
    }
    centroid /= n;
    const Point normal = mesh->normal(v);
    moved[v.idx()] = centroid + normal * OpenMesh::dot(normal, p - centroid);
  }
  for (const auto v : mesh->vertices()) mesh->set_point(v, moved[v.idx()]);
}

void RequireClosedManifold(const Mesh& mesh, const char* what) {
  const MeshTopology topology = AnalyzeTopology(mesh);
  CAROUSEL_THROW_IF(topology.faces == 0, InvalidArgument, what << " has no faces");
  CAROUSEL_THROW_IF(!topology.closed(), InvalidArgument,
                    what << " is not closed (" << topology.boundary_edges << " boundary edges)");
  CAROUSEL_THROW_IF(
      !topology.manifold(), InvalidArgument,
      what << " is not manifold (" << topology.non_manifold_vertices << " non-manifold vertices)");
}

// Collapses edges far shorter than the mean (coincident vertices, zero-area triangles): the
// quadric and normal computations need triangles with an area.
void CollapseDegenerateEdges(Mesh* mesh) {
  double total = 0.0;
  std::size_t n = 0;
  for (const auto e : mesh->edges()) {
    total += mesh->calc_edge_length(e);
    ++n;
  }
  if (n == 0) return;
  const double tiny = 1e-4 * total / static_cast<double>(n);
  std::size_t collapsed = 0;
  for (const auto e : mesh->edges()) {
    if (mesh->status(e).deleted() || mesh->calc_edge_length(e) >= tiny) continue;
    for (const auto h : {mesh->halfedge_handle(e, 0), mesh->halfedge_handle(e, 1)}) {
      if (!mesh->is_collapse_ok(h)) continue;
      mesh->collapse(h);
      ++collapsed;
      break;
    }
  }
  if (collapsed > 0) mesh->garbage_collection();
}

}  // namespace

const OptionTable<MeshOptimizationOptions>& MeshOptimizationOptions::Fields() {
  using O = MeshOptimizationOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::target_faces,
          {.name = "faces", .help = "faces of the optimized mesh", .unit = "faces", .min = 100});
    t.Add(&O::smoothing_iterations, {.name = "smoothing-iterations",
                                     .help = "Taubin smoothing passes on the hull (0: none)",
                                     .min = 0,
                                     .max = 200,
                                     .advanced = true});
    t.Add(&O::taubin_lambda, {.name = "taubin-lambda",
                              .help = "Taubin smoothing's shrinking step",
                              .min = 0,
                              .max = 1,
                              .min_exclusive = true,
                              .max_exclusive = true,
                              .advanced = true});
    t.Add(&O::taubin_mu, {.name = "taubin-mu",
                          .help = "Taubin smoothing's inflating step (below -lambda)",
                          .min = -1,
                          .max = 0,
                          .min_exclusive = true,
                          .max_exclusive = true,
                          .advanced = true});
    t.Add(&O::remesh,
          {.name = "remesh", .help = "isotropic remeshing before the final decimation"});
    t.Add(&O::remesh_iterations, {.name = "remesh-iterations",
                                  .help = "isotropic remeshing passes",
                                  .min = 1,
                                  .max = 20,
                                  .advanced = true});
    t.Add(&O::remesh_face_factor, {.name = "remesh-face-factor",
                                   .help = "remesh to about this many times --faces",
                                   .min = 1,
                                   .max = 10,
                                   .advanced = true});
    t.Add(&O::max_normal_deviation_deg,
          {.name = "max-normal-deviation",
           .help = "largest change of a face normal by one edge collapse",
           .unit = "deg",
           .min = 0,
           .max = 180,
           .min_exclusive = true,
           .advanced = true});
    t.Add(&O::max_aspect_ratio,
          {.name = "max-aspect-ratio",
           .help = "largest triangle aspect ratio (longest edge / height) a collapse may create",
           .min = 1,
           .min_exclusive = true,
           .advanced = true});
    t.Add(&O::target_volume_m3, {.name = "target-volume",
                                 .help = "volume the result is offset to",
                                 .unit = "m^3",
                                 .min = 0,
                                 .special = 0,
                                 .special_meaning = "the input's",
                                 .advanced = true});
    return t;
  }();
  return table;
}

void MeshOptimizationOptions::Validate() const {
  Fields().Check(*this);
  CAROUSEL_THROW_IF(
      !(taubin_mu < -taubin_lambda), InvalidArgument,
      "--taubin-mu must be below -(--taubin-lambda) (" << -taubin_lambda << "), got " << taubin_mu);
}

void TaubinSmooth(Mesh* mesh, int iterations, double lambda, double mu) {
  std::vector<Point> laplacian(mesh->n_vertices());
  auto step = [&](double factor) {
    for (const auto v : mesh->vertices()) {
      Point sum(0.0, 0.0, 0.0);
      int n = 0;
      for (const auto w : mesh->vv_range(v)) {
        sum += mesh->point(w);
        ++n;
      }
      laplacian[v.idx()] = n > 0 ? sum / n - mesh->point(v) : Point(0.0, 0.0, 0.0);
    }
    for (const auto v : mesh->vertices())
      mesh->set_point(v, mesh->point(v) + factor * laplacian[v.idx()]);
  };
  for (int i = 0; i < iterations; ++i) {
    step(lambda);
    step(mu);
  }
}

std::size_t DecimateQuadric(Mesh* mesh, std::size_t target_faces, double max_normal_deviation_deg,
                            double max_aspect_ratio) {
  if (mesh->n_faces() <= target_faces) return mesh->n_faces();
  mesh->update_face_normals();
  {
    OpenMesh::Decimater::DecimaterT<Mesh> decimater(*mesh);
    OpenMesh::Decimater::ModQuadricT<Mesh>::Handle quadric;
    OpenMesh::Decimater::ModNormalFlippingT<Mesh>::Handle flipping;
    OpenMesh::Decimater::ModAspectRatioT<Mesh>::Handle aspect;
    decimater.add(quadric);
    decimater.module(quadric).unset_max_err();
    decimater.add(flipping);
    decimater.module(flipping).set_max_normal_deviation(max_normal_deviation_deg);
    decimater.add(aspect);
    decimater.module(aspect).set_aspect_ratio(static_cast<float>(max_aspect_ratio));
    decimater.module(aspect).set_binary(true);
    CAROUSEL_CHECK(decimater.initialize(), "OpenMesh decimater did not initialise");
    decimater.decimate_to_faces(0, target_faces);
  }
  mesh->garbage_collection();
  return mesh->n_faces();
}

namespace {

// Taubin smoothing that never makes the surface intersect itself (a thin part's two sides
// pulled through each other): where faces come to intersect, their vertices and those
// around them go back to where they were, until no faces intersect.
void SmoothWithoutIntersections(Mesh* mesh, const MeshOptimizationOptions& options) {
  std::vector<Mesh::Point> before(mesh->n_vertices());
  for (const auto v : mesh->vertices()) before[v.idx()] = mesh->point(v);
  TaubinSmooth(mesh, options.smoothing_iterations, options.taubin_lambda, options.taubin_mu);
  constexpr int kRounds = 20;
  for (int round = 0; round < kRounds; ++round) {
    const auto pairs = FindSelfIntersections(*mesh, 100000);
    if (pairs.empty()) return;
    std::vector<Mesh::VertexHandle> revert;
    for (const auto& [f, g] : pairs)
      for (const int face : {f, g})
        for (const auto v : mesh->fv_range(Mesh::FaceHandle(face))) {
          revert.push_back(v);
          for (const auto w : mesh->vv_range(v)) revert.push_back(w);
        }
    for (const auto v : revert) mesh->set_point(v, before[v.idx()]);
    if (round == 0)
      CAROUSEL_LOG_INFO("mesh: smoothing folded a thin part (" << pairs.size()
                                                               << " pairs of faces); undone there");
  }
  for (const auto v : mesh->vertices()) mesh->set_point(v, before[v.idx()]);
  CAROUSEL_LOG_WARN("mesh: smoothing undone: it made the surface intersect itself");
}

// Moves the vertices of intersecting faces, and `rings` of their neighbours, back to
// `positions`, growing the neighbourhood each round until no faces intersect (or 8 rounds).
// Returns the pairs still intersecting.
std::vector<std::pair<int, int>> UndoAroundIntersections(Mesh* mesh,
                                                         const std::vector<Mesh::Point>& positions,
                                                         std::vector<std::pair<int, int>> pairs) {
  constexpr int kRounds = 8;
  for (int round = 0; round < kRounds && !pairs.empty(); ++round) {
    std::vector<char> marked(mesh->n_vertices(), 0);
    std::vector<Mesh::VertexHandle> undo;
    auto mark = [&](Mesh::VertexHandle v) {
      if (!marked[v.idx()]) undo.push_back(v);
      marked[v.idx()] = 1;
    };
    for (const auto& [f, g] : pairs)
      for (const int face : {f, g})
        for (const auto v : mesh->fv_range(Mesh::FaceHandle(face))) mark(v);
    for (int ring = 0; ring <= round; ++ring) {
      const std::size_t n = undo.size();
      for (std::size_t k = 0; k < n; ++k)
        for (const auto w : mesh->vv_range(undo[k])) mark(w);
    }
    for (const auto v : undo) mesh->set_point(v, positions[v.idx()]);
    pairs = FindSelfIntersections(*mesh, 1000);
  }
  return pairs;
}

}  // namespace

void RemeshIsotropic(Mesh* mesh, double edge_length, int iterations) {
  const double high = 4.0 / 3.0 * edge_length;
  const double low = 4.0 / 5.0 * edge_length;
  for (int i = 0; i < iterations; ++i) {
    SplitLongEdges(mesh, high);
    CollapseShortEdges(mesh, low, high);
    EqualizeValences(mesh);
    TangentialRelaxation(mesh);
  }
}

MeshOptimizationResult OptimizeMesh(const Mesh& hull, const MeshOptimizationOptions& options,
                                    Progress& progress) {
  options.Validate();
  RequireClosedManifold(hull, "the input mesh");
  MeshOptimizationResult result;
  result.input_faces = hull.n_faces();
  result.input_volume_m3 = SignedVolume(hull);
  const double target_volume =
      options.target_volume_m3 > 0.0 ? options.target_volume_m3 : result.input_volume_m3;
  Mesh mesh = hull;
  const auto target = static_cast<std::size_t>(options.target_faces);
  Stopwatch stopwatch;

  progress.BeginStage("mesh: smoothing");
  CollapseDegenerateEdges(&mesh);
  SmoothWithoutIntersections(&mesh, options);
  progress.EndStage();
  result.seconds_smooth = stopwatch.ElapsedSeconds();

  if (options.remesh) {
    const Mesh smoothed = mesh;
    progress.BeginStage("mesh: remeshing");
    stopwatch.Restart();
    const auto intermediate =
        static_cast<std::size_t>(4.0 * options.remesh_face_factor * options.target_faces);
    if (mesh.n_faces() > intermediate) {
      internal::IndexedMesh indexed = internal::ToIndexed(mesh);
      internal::DecimateIndexed(&indexed, intermediate, options.max_normal_deviation_deg,
                                options.max_aspect_ratio);
      mesh = internal::FromIndexed(indexed);
    }
    result.seconds_decimate += stopwatch.ElapsedSeconds();
    progress.Report(0.3);
    stopwatch.Restart();
    // Equilateral triangles of edge L have area sqrt(3)/4 L^2.
    const double faces = options.remesh_face_factor * options.target_faces;
    const double edge = std::sqrt(4.0 * mesh.SurfaceArea() / (std::sqrt(3.0) * faces));
    // Every step below starts from a mesh whose faces do not intersect.
    if (!FindSelfIntersections(mesh, 1).empty()) {
      CAROUSEL_LOG_INFO(
          "mesh: the intermediate decimation folded a thin part; decimating the "
          "smoothed hull directly");
      mesh = smoothed;
    } else {
      Mesh decimated = mesh;
      RemeshIsotropic(&mesh, edge, options.remesh_iterations);
      if (!FindSelfIntersections(mesh, 1).empty()) {
        CAROUSEL_LOG_INFO("mesh: remeshing folded a thin part; decimating without it");
        mesh = std::move(decimated);
      }
    }
    result.seconds_remesh = stopwatch.ElapsedSeconds();
    progress.EndStage();
  }

  progress.BeginStage("mesh: decimation");
  stopwatch.Restart();
  // A collapse may fold a thin part (a 2 mm heel tab) through its other side. Such places are
  // found after the decimation, and the decimation is redone with the vertices around them
  // locked at the finer (remeshed) resolution, until no two faces intersect.
  const Mesh base = mesh;
  std::vector<std::pair<Eigen::Vector3d, double>> locked;  // balls: centre, radius
  constexpr int kMaxRepairRounds = 6;
  for (int round = 0;; ++round) {
    if (round > 0) {
      mesh = base;
      mesh.request_vertex_status();
      for (const auto v : mesh.vertices()) {
        const auto& p = mesh.point(v);
        const Eigen::Vector3d x(p[0], p[1], p[2]);
        for (const auto& [centre, radius] : locked)
          if ((x - centre).squaredNorm() <= radius * radius) mesh.status(v).set_locked(true);
      }
    }
    std::size_t faces =
        DecimateQuadric(&mesh, target, options.max_normal_deviation_deg, options.max_aspect_ratio);
    if (faces > target + target / 100) {
      // The guards blocked the last collapses: relax the aspect guard, then the normal guard.
      CAROUSEL_LOG_INFO("mesh: decimation stopped at " << faces << " faces; relaxing the guards");
      DecimateQuadric(&mesh, target, std::min(90.0, 1.5 * options.max_normal_deviation_deg),
                      4.0 * options.max_aspect_ratio);
    }
    if (round > 0) mesh.release_vertex_status();
    // Smoothing and decimation shrink curved parts slightly: offset the surface along its
    // normals by the uniform distance that restores the target volume (dV = area * d).
    std::vector<Mesh::Point> decimated(mesh.n_vertices());
    for (const auto v : mesh.vertices()) decimated[v.idx()] = mesh.point(v);
    const bool folded_before_offset = !FindSelfIntersections(mesh, 1).empty();
    for (int iteration = 0; iteration < 3; ++iteration) {
      mesh.RecomputeNormals();
      const double area = mesh.SurfaceArea();
      const double offset = (target_volume - SignedVolume(mesh)) / area;
      if (!(area > 0.0) || !std::isfinite(offset)) break;
      for (const auto v : mesh.vertices())
        mesh.set_point(v, mesh.point(v) + offset * mesh.normal(v));
    }
    auto pairs = FindSelfIntersections(mesh, 1000);
    // In a crevice narrower than twice the offset (a beak's parted lips) the offset carries
    // either side through the other: undo it there, a ring wider each round.
    if (!folded_before_offset && !pairs.empty())
      pairs = UndoAroundIntersections(&mesh, decimated, pairs);
    result.self_intersections = pairs.size();
    result.repair_rounds = round;
    if (pairs.empty()) break;
    if (round == kMaxRepairRounds) {
      CAROUSEL_LOG_WARN("mesh: " << pairs.size() << " pairs of faces still intersect after "
                                 << round << " repair rounds");
      break;
    }
    for (const auto& [f, g] : pairs) {
      for (const int face : {f, g}) {
        Eigen::Vector3d centre = Eigen::Vector3d::Zero();
        std::vector<Eigen::Vector3d> corners;
        for (const auto v : mesh.fv_range(Mesh::FaceHandle(face))) {
          const auto& p = mesh.point(v);
          corners.emplace_back(p[0], p[1], p[2]);
          centre += corners.back();
        }
        centre /= static_cast<double>(corners.size());
        double radius = 0.0;
        for (const auto& c : corners) radius = std::max(radius, (c - centre).norm());
        locked.emplace_back(centre, 1.5 * radius);
      }
    }
    CAROUSEL_LOG_INFO("mesh: " << pairs.size()
                               << " pairs of faces intersect; decimating again with "
                                  "their surroundings locked");
  }
  result.seconds_decimate += stopwatch.ElapsedSeconds();
  progress.EndStage();
  mesh.RecomputeNormals();
  RequireClosedManifold(mesh, "the optimized mesh");
  result.volume_m3 = SignedVolume(mesh);
  CAROUSEL_CHECK(result.volume_m3 > 0.0, "optimized mesh is inside out");
  result.mesh = std::move(mesh);
  return result;
}

}  // namespace carousel::recon
