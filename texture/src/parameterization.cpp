#include "carousel/texture/parameterization.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>
#include <numeric>
#include <unordered_map>

#include <Eigen/Geometry>
#include <Eigen/SparseCholesky>
#include <Eigen/SparseCore>
#include <Eigen/SparseLU>
#include <opencv2/imgproc.hpp>

#include "carousel/core/error.h"
#include "carousel/core/logging.h"
#include "carousel/core/parallel.h"
#include "carousel/core/timer.h"
#include "chart_growth.h"
#include "face_graph.h"

namespace carousel::texture {
namespace {

using internal::FaceGraph;
using SparseMatrix = Eigen::SparseMatrix<double>;
using Triplet = Eigen::Triplet<double>;

constexpr double kPi = std::numbers::pi;
constexpr double kMinAngle = 0.0175;      // radians (1 degree): slivers are clamped to this
constexpr int kRectifySteps = 4;          // rectification steps at most
constexpr double kUnbendBelowFill = 0.6;  // charts filling less of their box: unbending tried
// Charts filling less of their box after all, of kSplitMinFaces faces or more, are tried split;
// kept split when the parts' boxes together are under kSplitGain of the chart's (the parts'
// gutters cost room too).
constexpr double kSplitBelowFill = 0.6;
constexpr std::size_t kSplitMinFaces = 16;
constexpr double kSplitGain = 0.85;

// One chart in local indices.
struct Chart {
  std::vector<int> faces;                   // global face ids
  std::vector<int> vertices;                // global vertex ids
  std::vector<std::array<int, 3>> corners;  // per face, local vertex ids
  std::vector<char> interior;               // per local vertex
};

Chart MakeChart(const FaceGraph& g, const std::vector<int>& faces,
                const std::vector<int>& chart_of_face) {
  Chart chart;
  chart.faces = faces;
  std::unordered_map<int, int> local;
  local.reserve(faces.size() * 2);
  chart.corners.resize(faces.size());
  for (std::size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const int v = g.faces[faces[i]][k];
      const auto [it, added] = local.emplace(v, static_cast<int>(chart.vertices.size()));
      if (added) chart.vertices.push_back(v);
      chart.corners[i][k] = it->second;
    }
  }
  const int chart_id = chart_of_face[faces.front()];
  chart.interior.resize(chart.vertices.size());
  for (std::size_t i = 0; i < chart.vertices.size(); ++i) {
    const int v = chart.vertices[i];
    bool interior = !g.boundary_vertex[v];
    for (int j = g.fan_start[v]; interior && j < g.fan_start[v + 1]; ++j)
      interior = chart_of_face[g.fan[j]] == chart_id;
    chart.interior[i] = interior ? 1 : 0;
  }
  return chart;
}

// The 3D corner angles of a face, clamped away from 0 and pi, summing to pi.
std::array<double, 3> CornerAngles(const FaceGraph& g, int face) {
  std::array<double, 3> angle{};
  const auto& t = g.faces[face];
  bool degenerate = false;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector3d u = g.positions[t[(k + 1) % 3]] - g.positions[t[k]];
    const Eigen::Vector3d w = g.positions[t[(k + 2) % 3]] - g.positions[t[k]];
    const double cross = u.cross(w).norm();
    const double dot = u.dot(w);
    if (!(cross > 0.0 || dot != 0.0) || !std::isfinite(cross) || !std::isfinite(dot))
      degenerate = true;
    angle[k] = std::atan2(cross, dot);
  }
  if (degenerate) return {kPi / 3, kPi / 3, kPi / 3};
  for (int pass = 0; pass < 2; ++pass) {
    double sum = 0.0;
    for (double& a : angle) {
      a = std::clamp(a, kMinAngle, kPi - 2 * kMinAngle);
      sum += a;
    }
    for (double& a : angle) a *= kPi / sum;
  }
  return angle;
}

// ABF++: the 2D angles per corner (3 per face, in face order). Returns false when the
// constraints did not reach the tolerance (the angles are still usable).
bool SolveAbf(const FaceGraph& g, const Chart& chart, const ParameterizationOptions& options,
              std::vector<double>* alpha) {
  const int nf = static_cast<int>(chart.faces.size());
  const int n = 3 * nf;
  std::vector<double> beta(n);
  for (int i = 0; i < nf; ++i) {
    const auto a = CornerAngles(g, chart.faces[i]);
    for (int k = 0; k < 3; ++k) beta[3 * i + k] = a[k];
  }
  // Interior vertices: their own row pair; the 3D angles around them scaled to 2 pi.
  std::vector<int> row_of(chart.vertices.size(), -1);
  int interior = 0;
  for (std::size_t v = 0; v < chart.vertices.size(); ++v)
    if (chart.interior[v]) row_of[v] = interior++;
  std::vector<double> angle_sum(interior, 0.0);
  for (int i = 0; i < nf; ++i)
    for (int k = 0; k < 3; ++k)
      if (row_of[chart.corners[i][k]] >= 0)
        angle_sum[row_of[chart.corners[i][k]]] += beta[3 * i + k];
  for (int i = 0; i < nf; ++i)
    for (int k = 0; k < 3; ++k)
      if (row_of[chart.corners[i][k]] >= 0)
        beta[3 * i + k] *= 2 * kPi / angle_sum[row_of[chart.corners[i][k]]];
  // Boundary vertices: ABF leaves their angle sums free, and one whose surface angles sum to
  // more than 2 pi (a saddle on a bumpy surface) would fold the boundary over itself. Their
  // targets are scaled down to at most kMaxBoundaryAngle.
  {
    constexpr double kMaxBoundaryAngle = 1.8 * kPi;
    std::vector<double> boundary_sum(chart.vertices.size(), 0.0);
    for (int i = 0; i < nf; ++i)
      for (int k = 0; k < 3; ++k)
        if (row_of[chart.corners[i][k]] < 0) boundary_sum[chart.corners[i][k]] += beta[3 * i + k];
    for (int i = 0; i < nf; ++i)
      for (int k = 0; k < 3; ++k) {
        const double sum = boundary_sum[chart.corners[i][k]];
        if (row_of[chart.corners[i][k]] < 0 && sum > kMaxBoundaryAngle)
          beta[3 * i + k] *= kMaxBoundaryAngle / sum;
      }
  }
  *alpha = beta;
  if (options.max_abf_iterations == 0) return true;
  // D = (2 W)^-1 with W = diag(1 / beta^2).
  Eigen::VectorXd d(n);
  for (int i = 0; i < n; ++i) d[i] = 0.5 * beta[i] * beta[i];
  Eigen::VectorXd d1(nf);  // J1 D J1^T, diagonal
  for (int i = 0; i < nf; ++i) d1[i] = d[3 * i] + d[3 * i + 1] + d[3 * i + 2];
  const Eigen::VectorXd inv_d1 = d1.cwiseInverse();

  // J2's rows touch a face's own 3 columns only: per face, the rows of its corners' vertices
  // (k: the angle sum around corner k's vertex; 3 + k: its sine condition; -1 on the boundary).
  // The Schur complement S = J2 D J2^T - B D1^-1 B^T (B = J2 D J1^T) is then a sum of one
  // small dense block per face, assembled straight into S's lower triangle, whose pattern,
  // ordering and symbolic factorization are computed once.
  std::vector<std::array<int, 6>> rows(nf);
  for (int i = 0; i < nf; ++i)
    for (int k = 0; k < 3; ++k) {
      const int row = row_of[chart.corners[i][k]];
      rows[i][k] = row;
      rows[i][3 + k] = row < 0 ? -1 : interior + row;
    }
  SparseMatrix s;
  std::vector<int> slot;  // per face and row pair (lower triangle), S's value index
  Eigen::SimplicialLDLT<SparseMatrix> solver;
  if (interior > 0) {
    std::vector<Triplet> pattern;
    pattern.reserve(static_cast<std::size_t>(21) * nf);
    for (int i = 0; i < nf; ++i)
      for (int p = 0; p < 6; ++p)
        for (int q = 0; q < 6; ++q)
          if (rows[i][p] >= 0 && rows[i][q] >= 0 && rows[i][p] >= rows[i][q])
            pattern.emplace_back(rows[i][p], rows[i][q], 0.0);
    s.resize(2 * interior, 2 * interior);
    s.setFromTriplets(pattern.begin(), pattern.end());
    s.makeCompressed();
    slot.reserve(pattern.size());
    for (const Triplet& t : pattern) {
      const int* begin = s.innerIndexPtr() + s.outerIndexPtr()[t.col()];
      const int* end = s.innerIndexPtr() + s.outerIndexPtr()[t.col() + 1];
      slot.push_back(static_cast<int>(std::lower_bound(begin, end, t.row()) - s.innerIndexPtr()));
    }
    solver.analyzePattern(s);
  }
  std::vector<std::array<double, 18>> jacobian(nf);  // per face, J2's 6 x 3 block, row-major
  std::vector<std::array<double, 6>> jd(nf);         // per face, J2's block times D

  for (int iteration = 0; iteration < options.max_abf_iterations; ++iteration) {
    std::vector<double>& a = *alpha;
    // Constraint values and J2's blocks.
    Eigen::VectorXd c1(nf);
    for (int i = 0; i < nf; ++i) c1[i] = a[3 * i] + a[3 * i + 1] + a[3 * i + 2] - kPi;
    Eigen::VectorXd c2 = Eigen::VectorXd::Zero(2 * interior);
    for (int i = 0; i < nf; ++i) {
      std::array<double, 18>& j = jacobian[i];
      j.fill(0.0);
      for (int k = 0; k < 3; ++k) {
        const int row = rows[i][k];
        if (row < 0) continue;
        const int next = (k + 1) % 3;
        const int prev = (k + 2) % 3;
        c2[row] += a[3 * i + k];
        j[3 * k + k] = 1.0;
        c2[rows[i][3 + k]] +=
            std::log(std::sin(a[3 * i + next])) - std::log(std::sin(a[3 * i + prev]));
        j[3 * (3 + k) + next] = 1.0 / std::tan(a[3 * i + next]);
        j[3 * (3 + k) + prev] = -1.0 / std::tan(a[3 * i + prev]);
      }
    }
    for (int row = 0; row < interior; ++row) c2[row] -= 2 * kPi;
    const double worst =
        std::max(c1.cwiseAbs().maxCoeff(), interior > 0 ? c2.cwiseAbs().maxCoeff() : 0.0);
    if (!std::isfinite(worst)) return false;
    if (worst < options.abf_tolerance) return true;

    // r = C - J (alpha - beta).
    Eigen::VectorXd offset(n);
    for (int i = 0; i < n; ++i) offset[i] = a[i] - beta[i];
    Eigen::VectorXd r1(nf);
    for (int i = 0; i < nf; ++i)
      r1[i] = c1[i] - (offset[3 * i] + offset[3 * i + 1] + offset[3 * i + 2]);
    Eigen::VectorXd lambda1(nf);
    Eigen::VectorXd step(n);
    if (interior == 0) {
      lambda1 = r1.cwiseQuotient(d1);
      for (int i = 0; i < nf; ++i)
        for (int k = 0; k < 3; ++k)
          step[3 * i + k] = -offset[3 * i + k] - d[3 * i + k] * lambda1[i];
    } else {
      // S, and the right-hand side r2 - B D1^-1 r1 with r2 = C2 - J2 (alpha - beta).
      std::fill(s.valuePtr(), s.valuePtr() + s.nonZeros(), 0.0);
      Eigen::VectorXd rhs = c2;
      std::size_t next_slot = 0;
      for (int i = 0; i < nf; ++i) {
        const std::array<double, 18>& j = jacobian[i];
        for (int p = 0; p < 6; ++p) {
          jd[i][p] = 0.0;
          if (rows[i][p] < 0) continue;
          double moved = 0.0;
          for (int k = 0; k < 3; ++k) {
            jd[i][p] += j[3 * p + k] * d[3 * i + k];
            moved += j[3 * p + k] * offset[3 * i + k];
          }
          rhs[rows[i][p]] -= moved + jd[i][p] * inv_d1[i] * r1[i];
        }
        for (int p = 0; p < 6; ++p)
          for (int q = 0; q < 6; ++q) {
            if (rows[i][p] < 0 || rows[i][q] < 0 || rows[i][p] < rows[i][q]) continue;
            double value = -jd[i][p] * jd[i][q] * inv_d1[i];
            for (int k = 0; k < 3; ++k) value += j[3 * p + k] * d[3 * i + k] * j[3 * q + k];
            s.valuePtr()[slot[next_slot++]] += value;
          }
      }
      solver.factorize(s);
      if (solver.info() != Eigen::Success) return false;
      const Eigen::VectorXd lambda2 = solver.solve(rhs);
      if (solver.info() != Eigen::Success || !lambda2.allFinite()) return false;
      for (int i = 0; i < nf; ++i) {
        // lambda1 = D1^-1 (r1 - B^T lambda2); the step -offset - D (J1^T lambda1 + J2^T lambda2).
        double bt = 0.0;
        std::array<double, 3> j2t = {0.0, 0.0, 0.0};
        for (int p = 0; p < 6; ++p) {
          if (rows[i][p] < 0) continue;
          const double l = lambda2[rows[i][p]];
          bt += jd[i][p] * l;
          for (int k = 0; k < 3; ++k) j2t[k] += jacobian[i][3 * p + k] * l;
        }
        lambda1[i] = inv_d1[i] * (r1[i] - bt);
        for (int k = 0; k < 3; ++k) {
          const int c = 3 * i + k;
          step[c] = -offset[c] - d[c] * (lambda1[i] + j2t[k]);
        }
      }
    }
    if (!step.allFinite()) return false;
    // Only kept inside (0, pi), where log sin is defined; the energy keeps them near beta.
    for (int i = 0; i < n; ++i) a[i] = std::clamp(a[i] + step[i], 1e-6, kPi - 1e-6);
  }
  return false;
}

// Least-squares vertex positions from the angles (paper Eq. 4), two boundary vertices pinned.
// Returns positions per local vertex, or an empty vector when the solve fails.
std::vector<Eigen::Vector2d> Reconstruct(const FaceGraph& g, const Chart& chart,
                                         const std::vector<double>& alpha) {
  const int nv = static_cast<int>(chart.vertices.size());
  const int nf = static_cast<int>(chart.faces.size());
  std::vector<Eigen::Vector2d> uv(nv, Eigen::Vector2d::Zero());
  // Pins: two boundary vertices far apart (the farthest from a boundary vertex, then the
  // farthest from that one), at their 3D distance.
  int first = 0;
  for (int v = 0; v < nv; ++v)
    if (!chart.interior[v]) {
      first = v;
      break;
    }
  auto farthest = [&](int from) {
    int best = from;
    double best_d = -1.0;
    for (int v = 0; v < nv; ++v) {
      if (chart.interior[v]) continue;
      const double dist =
          (g.positions[chart.vertices[v]] - g.positions[chart.vertices[from]]).norm();
      if (dist > best_d) {
        best_d = dist;
        best = v;
      }
    }
    return best;
  };
  const int pin0 = farthest(first);
  const int pin1 = farthest(pin0);
  if (pin0 == pin1) return {};
  const double span =
      (g.positions[chart.vertices[pin1]] - g.positions[chart.vertices[pin0]]).norm();
  uv[pin0] = Eigen::Vector2d(0.0, 0.0);
  uv[pin1] = Eigen::Vector2d(span > 0.0 ? span : 1.0, 0.0);
  // Unknown index of each vertex's u (v follows), -1 for pins.
  std::vector<int> column(nv, -1);
  int unknowns = 0;
  for (int v = 0; v < nv; ++v)
    if (v != pin0 && v != pin1) column[v] = 2 * unknowns++;
  if (unknowns == 0) return uv;
  std::vector<Triplet> entries;
  entries.reserve(static_cast<std::size_t>(12) * nf);
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(2 * nf);
  for (int i = 0; i < nf; ++i) {
    const auto& t = chart.corners[i];
    const double s1 = std::sin(alpha[3 * i]);
    const double c1 = std::cos(alpha[3 * i]);
    const double s2 = std::sin(alpha[3 * i + 1]);
    const double s3 = std::sin(alpha[3 * i + 2]);
    const double scale = 1.0 / std::max({s2, s3, 1e-12});
    // Row x: x1 (-s3 + s2 c1) + x2 (-s2 c1) + x3 s3 + y1 (-s2 s1) + y2 (s2 s1) = 0
    // Row y: x1 (s2 s1) + x2 (-s2 s1) + y1 (-s3 + s2 c1) + y2 (-s2 c1) + y3 s3 = 0
    const std::array<std::array<double, 6>, 2> coeff = {{
        {-s3 + s2 * c1, -s2 * c1, s3, -s2 * s1, s2 * s1, 0.0},
        {s2 * s1, -s2 * s1, 0.0, -s3 + s2 * c1, -s2 * c1, s3},
    }};
    for (int row = 0; row < 2; ++row) {
      for (int k = 0; k < 6; ++k) {
        const double value = coeff[row][k] * scale;
        if (value == 0.0) continue;
        const int v = t[k % 3];
        const int axis = k / 3;
        if (column[v] < 0)
          rhs[2 * i + row] -= value * uv[v][axis];
        else
          entries.emplace_back(2 * i + row, column[v] + axis, value);
      }
    }
  }
  SparseMatrix a(2 * nf, 2 * unknowns);
  a.setFromTriplets(entries.begin(), entries.end());
  const SparseMatrix normal = SparseMatrix(a.transpose() * a);
  Eigen::SimplicialLDLT<SparseMatrix> solver(normal);
  if (solver.info() != Eigen::Success) return {};
  const Eigen::VectorXd x = solver.solve(a.transpose() * rhs);
  if (solver.info() != Eigen::Success || !x.allFinite()) return {};
  for (int v = 0; v < nv; ++v)
    if (column[v] >= 0) uv[v] = Eigen::Vector2d(x[column[v]], x[column[v] + 1]);
  return uv;
}

double Cross(const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return a.x() * b.y() - a.y() * b.x();
}

// Whether segments (p1, p2) and (q1, q2) cross or touch (shared endpoints excluded by the
// caller).
bool SegmentsIntersect(const Eigen::Vector2d& p1, const Eigen::Vector2d& p2,
                       const Eigen::Vector2d& q1, const Eigen::Vector2d& q2) {
  const double d1 = Cross(q2 - q1, p1 - q1);
  const double d2 = Cross(q2 - q1, p2 - q1);
  const double d3 = Cross(p2 - p1, q1 - p1);
  const double d4 = Cross(p2 - p1, q2 - p1);
  if (((d1 > 0 && d2 < 0) || (d1 < 0 && d2 > 0)) && ((d3 > 0 && d4 < 0) || (d3 < 0 && d4 > 0)))
    return true;
  auto on_segment = [](const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                       const Eigen::Vector2d& p) {
    return p.x() >= std::min(a.x(), b.x()) && p.x() <= std::max(a.x(), b.x()) &&
           p.y() >= std::min(a.y(), b.y()) && p.y() <= std::max(a.y(), b.y());
  };
  return (d1 == 0 && on_segment(q1, q2, p1)) || (d2 == 0 && on_segment(q1, q2, p2)) ||
         (d3 == 0 && on_segment(p1, p2, q1)) || (d4 == 0 && on_segment(p1, p2, q2));
}

// A flattening is valid when no triangle is flipped or degenerate and the boundary does not
// cross itself.
bool IsValid(const FaceGraph& g, const Chart& chart, const std::vector<int>& chart_of_face,
             const std::vector<Eigen::Vector2d>& uv) {
  double total = 0.0;
  for (const auto& t : chart.corners) total += Cross(uv[t[1]] - uv[t[0]], uv[t[2]] - uv[t[0]]);
  if (!(total > 0.0)) return false;
  const double min_area = 1e-12 * total / static_cast<double>(chart.corners.size());
  int flipped = 0;
  for (const auto& t : chart.corners)
    if (!(Cross(uv[t[1]] - uv[t[0]], uv[t[2]] - uv[t[0]]) > min_area)) ++flipped;
  if (flipped > 0) return false;
  // Boundary edges (local vertex pairs), bucketed in a grid over the chart's box.
  std::vector<std::pair<int, int>> edges;
  const int chart_id = chart_of_face[chart.faces.front()];
  for (std::size_t i = 0; i < chart.faces.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const int across = g.neighbours[chart.faces[i]][k];
      if (across < 0 || chart_of_face[across] != chart_id)
        edges.emplace_back(chart.corners[i][k], chart.corners[i][(k + 1) % 3]);
    }
  Eigen::AlignedBox2d box;
  for (const auto& p : uv) box.extend(p);
  const int cells = std::max(1, static_cast<int>(std::sqrt(static_cast<double>(edges.size()))));
  const Eigen::Vector2d size = box.sizes().cwiseMax(1e-30);
  auto cell_of = [&](const Eigen::Vector2d& p) {
    const Eigen::Vector2d r = (p - box.min()).cwiseQuotient(size) * cells;
    return Eigen::Vector2i(std::clamp(static_cast<int>(r.x()), 0, cells - 1),
                           std::clamp(static_cast<int>(r.y()), 0, cells - 1));
  };
  std::vector<std::vector<int>> grid(static_cast<std::size_t>(cells) * cells);
  for (std::size_t e = 0; e < edges.size(); ++e) {
    const Eigen::Vector2i a = cell_of(uv[edges[e].first]);
    const Eigen::Vector2i b = cell_of(uv[edges[e].second]);
    for (int y = std::min(a.y(), b.y()); y <= std::max(a.y(), b.y()); ++y)
      for (int x = std::min(a.x(), b.x()); x <= std::max(a.x(), b.x()); ++x)
        grid[static_cast<std::size_t>(y) * cells + x].push_back(static_cast<int>(e));
  }
  for (const auto& bucket : grid)
    for (std::size_t i = 0; i < bucket.size(); ++i)
      for (std::size_t j = i + 1; j < bucket.size(); ++j) {
        const auto& e = edges[bucket[i]];
        const auto& f = edges[bucket[j]];
        if (e.first == f.first || e.first == f.second || e.second == f.first ||
            e.second == f.second)
          continue;
        if (SegmentsIntersect(uv[e.first], uv[e.second], uv[f.first], uv[f.second])) return false;
      }
  return true;
}

// The chart's area-weighted L2 texture stretch (Sander et al. 2001), the UV area equal to the
// surface area. Angle-preserving maps shrink protrusions (a tip, a tab) exponentially: such a
// chart has faces with a hundredth of the texels of the others and a large stretch.
double ChartStretch(const FaceGraph& g, const Chart& chart,
                    const std::vector<Eigen::Vector2d>& uv) {
  double sum = 0.0;
  double area = 0.0;
  for (std::size_t i = 0; i < chart.faces.size(); ++i) {
    const auto& c = chart.corners[i];
    const double a_uv = 0.5 * Cross(uv[c[1]] - uv[c[0]], uv[c[2]] - uv[c[0]]);
    const double a_3d = g.areas[chart.faces[i]];
    if (!(a_uv > 0.0) || !(a_3d > 0.0)) continue;
    const auto& t = g.faces[chart.faces[i]];
    sum += internal::L2StretchSquared(g.positions[t[0]], g.positions[t[1]], g.positions[t[2]],
                                      uv[c[0]], uv[c[1]], uv[c[2]], a_uv) *
           a_3d;
    area += a_3d;
  }
  return area > 0.0 ? std::sqrt(sum / area) : 1.0;
}

// Scales `uv` so that its area equals the chart's surface area.
void ScaleToSurfaceArea(const FaceGraph& g, const Chart& chart, std::vector<Eigen::Vector2d>* uv) {
  double area_2d = 0.0;
  double area_3d = 0.0;
  for (std::size_t i = 0; i < chart.faces.size(); ++i) {
    const auto& t = chart.corners[i];
    area_2d += 0.5 * Cross((*uv)[t[1]] - (*uv)[t[0]], (*uv)[t[2]] - (*uv)[t[0]]);
    area_3d += g.areas[chart.faces[i]];
  }
  if (area_2d > 0.0 && area_3d > 0.0) {
    const double s = std::sqrt(area_3d / area_2d);
    for (auto& p : *uv) p *= s;
  }
}

// The chart's boundary loop (local vertex ids, counter-clockwise), or empty if it is not one
// simple loop.
std::vector<int> BoundaryLoop(const FaceGraph& g, const Chart& chart,
                              const std::vector<int>& chart_of_face) {
  const int chart_id = chart_of_face[chart.faces.front()];
  std::unordered_map<int, int> next;
  for (std::size_t i = 0; i < chart.faces.size(); ++i)
    for (int k = 0; k < 3; ++k) {
      const int across = g.neighbours[chart.faces[i]][k];
      if (across >= 0 && chart_of_face[across] == chart_id) continue;
      if (!next.emplace(chart.corners[i][k], chart.corners[i][(k + 1) % 3]).second) return {};
    }
  if (next.empty()) return {};
  std::vector<int> loop;
  // From its lowest vertex: the same loop whatever the map's order.
  int v = std::min_element(next.begin(), next.end())->first;
  do {
    loop.push_back(v);
    const auto it = next.find(v);
    if (it == next.end() || loop.size() > next.size()) return {};
    v = it->second;
  } while (v != loop.front());
  if (loop.size() != next.size()) return {};
  return loop;
}

// A harmonic solve's factorization, kept from one call to the next: the Laplacian's pattern
// depends on which vertices are unknown only, so its ordering and symbolic analysis are
// computed again only when they change.
struct HarmonicSolver {
  Eigen::SparseLU<SparseMatrix> lu;
  std::vector<int> unknown;  // of the pattern analysed; empty before the first
};

// The displacement of every vertex that takes the chart's boundary onto a rectangle: the loop
// vertices loop[at[c]] onto the rectangle's corners[c] (counter-clockwise, in the chart's
// frame), the ones between by arc length along its sides, ear tips excepted; the interior's
// and the ear tips' by mean-value harmonic interpolation. With a convex boundary and positive
// weights the map is one-to-one (Floater 2003), but for faces whose three corners go onto one
// side and ear tips whose offset from their neighbours does not turn with the side: with
// `keep_triangles` (a large deformation) the middle one of such three is excepted as well, and
// an excepted vertex between two pulled ones keeps its triangle with them (a similarity).
// Returns empty when the solve fails.
std::vector<Eigen::Vector2d> ShiftOntoRectangle(const Chart& chart, const std::vector<int>& loop,
                                                const std::vector<Eigen::Vector2d>& uv,
                                                const std::array<std::size_t, 4>& at,
                                                const std::array<Eigen::Vector2d, 4>& corners,
                                                bool keep_triangles, HarmonicSolver* solver) {
  const std::size_t m = loop.size();
  auto ahead = [&](std::size_t from, std::size_t to) { return (to + m - from) % m; };
  std::vector<Eigen::Vector2d> target(m);
  std::vector<int> side(m);      // the side each loop vertex goes onto (a corner: the next one)
  std::vector<double> along(m);  // and where along it, 0..1
  for (int c = 0; c < 4; ++c) {
    const std::size_t steps = ahead(at[c], at[(c + 1) % 4]);
    double length = 0.0;
    for (std::size_t s = 0; s < steps; ++s)
      length += (uv[loop[(at[c] + s + 1) % m]] - uv[loop[(at[c] + s) % m]]).norm();
    double run = 0.0;
    for (std::size_t s = 0; s < steps; ++s) {
      const std::size_t i = (at[c] + s) % m;
      const double t = length > 0.0 ? run / length : 0.0;
      target[i] = corners[c] + t * (corners[(c + 1) % 4] - corners[c]);
      side[i] = c;
      along[i] = t;
      run += (uv[loop[(i + 1) % m]] - uv[loop[i]]).norm();
    }
  }
  // Boundary displacements; the interior's by a harmonic solve.
  const std::size_t n = chart.vertices.size();
  std::vector<Eigen::Vector2d> shift(n, Eigen::Vector2d::Zero());
  std::vector<int> unknown(n, -1);
  int unknowns = 0;
  for (std::size_t v = 0; v < n; ++v)
    if (chart.interior[v]) unknown[v] = unknowns++;
  // An ear's tip (a boundary vertex of one face) is not pulled: on the line through its
  // neighbours its face would collapse. It moves with them.
  std::vector<int> faces_at(n, 0);
  for (const auto& t : chart.corners)
    for (const int v : t) ++faces_at[v];
  // Nor is the middle one of three corners of a face that would go onto one side: the face
  // would collapse onto it.
  std::vector<char> free(m, 0);
  for (std::size_t i = 0; i < m; ++i) free[i] = faces_at[loop[i]] < 2 ? 1 : 0;
  if (keep_triangles) {
    std::vector<int> in_loop(n, -1);
    for (std::size_t i = 0; i < m; ++i) in_loop[loop[i]] = static_cast<int>(i);
    // Loop vertex i on side c: its own side, or a corner ending side c.
    auto on_side = [&](int i, int c) {
      return side[i] == c || (side[i] == (c + 1) % 4 && along[i] == 0.0);
    };
    for (const auto& t : chart.corners) {
      const std::array<int, 3> i = {in_loop[t[0]], in_loop[t[1]], in_loop[t[2]]};
      if (i[0] < 0 || i[1] < 0 || i[2] < 0) continue;
      for (int c = 0; c < 4; ++c) {
        if (!on_side(i[0], c) || !on_side(i[1], c) || !on_side(i[2], c)) continue;
        auto at_side = [&](int k) { return side[i[k]] == c ? along[i[k]] : 1.0; };
        std::array<int, 3> by = {0, 1, 2};
        std::sort(by.begin(), by.end(), [&](int x, int y) { return at_side(x) < at_side(y); });
        free[i[by[1]]] = 1;
      }
    }
  }
  // An excepted vertex between two that are not keeps its triangle with them (a similarity:
  // its offset turns with the side); otherwise it moves with the interior.
  for (std::size_t i = 0; i < m && keep_triangles; ++i) {
    const std::size_t before = (i + m - 1) % m;
    const std::size_t after = (i + 1) % m;
    if (!free[i] || free[before] || free[after]) continue;
    const Eigen::Vector2d base = uv[loop[after]] - uv[loop[before]];
    const Eigen::Vector2d moved = target[after] - target[before];
    const double length = base.squaredNorm();
    if (!(length > 0.0)) continue;
    const Eigen::Vector2d offset = uv[loop[i]] - uv[loop[before]];
    const double a = offset.dot(base) / length;
    const double b = Cross(base, offset) / length;
    target[i] = target[before] + a * moved + b * Eigen::Vector2d(-moved.y(), moved.x());
    free[i] = 2;
  }
  for (std::size_t i = 0; i < m; ++i) {
    if (free[i] == 1) {
      unknown[loop[i]] = unknowns++;
      continue;
    }
    shift[loop[i]] = target[i] - uv[loop[i]];
    unknown[loop[i]] = -1;
  }
  if (unknowns > 0) {
    std::vector<Triplet> triplets;
    Eigen::MatrixX2d rhs = Eigen::MatrixX2d::Zero(unknowns, 2);
    for (const auto& t : chart.corners)
      for (int k = 0; k < 3; ++k) {
        // Mean value weights (Floater 2003), positive and exact for affine fields: the
        // corner at a, angle theta, gives edges (a, b) and (a, c) tan(theta / 2) / length.
        const int a = t[k];
        if (unknown[a] < 0) continue;
        const int b = t[(k + 1) % 3];
        const int c = t[(k + 2) % 3];
        const Eigen::Vector2d u = uv[b] - uv[a];
        const Eigen::Vector2d w = uv[c] - uv[a];
        const double theta = std::atan2(std::abs(Cross(u, w)), u.dot(w));
        const double half_tan = std::tan(0.5 * theta);
        for (const auto& [j, length] : {std::pair{b, u.norm()}, std::pair{c, w.norm()}}) {
          const double weight = half_tan / std::max(length, 1e-300);
          triplets.emplace_back(unknown[a], unknown[a], weight);
          if (unknown[j] >= 0)
            triplets.emplace_back(unknown[a], unknown[j], -weight);
          else
            rhs.row(unknown[a]) += weight * shift[j].transpose();
        }
      }
    SparseMatrix laplacian(unknowns, unknowns);
    laplacian.setFromTriplets(triplets.begin(), triplets.end());
    if (solver->unknown != unknown) {
      solver->lu.analyzePattern(laplacian);
      solver->unknown = unknown;
    }
    solver->lu.factorize(laplacian);
    if (solver->lu.info() != Eigen::Success) return {};
    const Eigen::MatrixX2d solved = solver->lu.solve(rhs);
    if (solver->lu.info() != Eigen::Success || !solved.allFinite()) return {};
    for (std::size_t v = 0; v < n; ++v)
      if (unknown[v] >= 0) shift[v] = solved.row(unknown[v]).transpose();
  }
  return shift;
}

// Whether the four loop positions `at` come in counter-clockwise loop order, each after the
// last and all distinct.
bool InLoopOrder(const std::array<std::size_t, 4>& at, std::size_t m) {
  std::size_t travelled = 0;
  for (int c = 0; c < 4; ++c) {
    const std::size_t step = (at[(c + 1) % 4] + m - at[c]) % m;
    if (step == 0) return false;
    travelled += step;
  }
  return travelled == m;
}

// The shift onto the chart's minimum-area rectangle: the loop vertices nearest its corners go
// onto them. Empty when those come out of order.
std::vector<Eigen::Vector2d> RectifyingShift(const Chart& chart, const std::vector<int>& loop,
                                             const std::vector<Eigen::Vector2d>& uv,
                                             HarmonicSolver* solver) {
  std::vector<cv::Point2f> points;
  points.reserve(loop.size());
  for (const int v : loop)
    points.emplace_back(static_cast<float>(uv[v].x()), static_cast<float>(uv[v].y()));
  const cv::RotatedRect box = cv::minAreaRect(points);
  const Eigen::Rotation2Dd turn(box.angle * kPi / 180.0);
  const Eigen::Vector2d centre(box.center.x, box.center.y);
  const Eigen::Vector2d half(0.5 * box.size.width, 0.5 * box.size.height);
  std::array<Eigen::Vector2d, 4> corners = {
      Eigen::Vector2d(-half.x(), -half.y()), Eigen::Vector2d(half.x(), -half.y()),
      Eigen::Vector2d(half.x(), half.y()), Eigen::Vector2d(-half.x(), half.y())};
  for (auto& c : corners) c = centre + turn * c;
  // Each rectangle corner's nearest loop vertex; they must come in counter-clockwise order.
  std::array<std::size_t, 4> at{};
  for (int c = 0; c < 4; ++c) {
    double best = std::numeric_limits<double>::infinity();
    for (std::size_t i = 0; i < loop.size(); ++i) {
      const double d = (uv[loop[i]] - corners[c]).squaredNorm();
      if (d < best) {
        best = d;
        at[c] = i;
      }
    }
  }
  if (!InLoopOrder(at, loop.size())) return {};
  return ShiftOntoRectangle(chart, loop, uv, at, corners, false, solver);
}

// The fraction of its minimum-area rectangle the chart's boundary loop covers.
double BoxFill(const std::vector<int>& loop, const std::vector<Eigen::Vector2d>& uv) {
  std::vector<cv::Point2f> points;
  points.reserve(loop.size());
  double area = 0.0;
  for (std::size_t i = 0; i < loop.size(); ++i) {
    const Eigen::Vector2d& p = uv[loop[i]];
    area += 0.5 * Cross(p, uv[loop[(i + 1) % loop.size()]]);
    points.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()));
  }
  const cv::Size2f size = cv::minAreaRect(points).size;
  const double box = static_cast<double>(size.width) * size.height;
  return box > 0.0 ? area / box : 1.0;
}

// The shift that unbends a strip: a chart flattened into a bent band (a ring cut open, an arc
// around a rim) fills little of its box, and no rectangle around it is one to pull it onto.
// The band's four corners are the loop's four sharpest left turns (turning measured over
// half the band's width, they at least that far apart); its sides go onto a rectangle whose
// sides are the mean lengths of the opposite arcs. Empty when no four corners are found.
std::vector<Eigen::Vector2d> UnbendingShift(const Chart& chart, const std::vector<int>& loop,
                                            const std::vector<Eigen::Vector2d>& uv,
                                            HarmonicSolver* solver) {
  const std::size_t m = loop.size();
  if (m < 4) return {};
  std::vector<double> arc(m + 1, 0.0);  // arc length at each loop vertex, and the perimeter
  double area = 0.0;
  for (std::size_t i = 0; i < m; ++i) {
    const Eigen::Vector2d& p = uv[loop[i]];
    const Eigen::Vector2d& q = uv[loop[(i + 1) % m]];
    arc[i + 1] = arc[i] + (q - p).norm();
    area += 0.5 * Cross(p, q);
  }
  const double perimeter = arc[m];
  if (!(area > 0.0) || !(perimeter > 0.0)) return {};
  const double width = 2.0 * area / perimeter;  // a thin band's width
  const double reach = 0.5 * width;
  // The point at arc length s along the loop (cyclic).
  auto at_length = [&](double s) {
    s = std::fmod(s, perimeter);
    if (s < 0.0) s += perimeter;
    const std::size_t i =
        std::min<std::size_t>(m - 1, std::upper_bound(arc.begin(), arc.end(), s) - arc.begin() - 1);
    const double span = arc[i + 1] - arc[i];
    const double t = span > 0.0 ? (s - arc[i]) / span : 0.0;
    return Eigen::Vector2d((1.0 - t) * uv[loop[i]] + t * uv[loop[(i + 1) % m]]);
  };
  std::vector<std::pair<double, std::size_t>> turning(m);
  for (std::size_t i = 0; i < m; ++i) {
    const Eigen::Vector2d in = uv[loop[i]] - at_length(arc[i] - reach);
    const Eigen::Vector2d out = at_length(arc[i] + reach) - uv[loop[i]];
    turning[i] = {std::atan2(Cross(in, out), in.dot(out)), i};
  }
  std::sort(turning.begin(), turning.end(), std::greater<>());
  std::vector<std::size_t> chosen;
  for (const auto& [angle, i] : turning) {
    if (chosen.size() == 4 || angle <= 0.0) break;
    bool apart = true;
    for (const std::size_t j : chosen) {
      const double d = std::abs(arc[i] - arc[j]);
      apart = apart && std::min(d, perimeter - d) >= reach;
    }
    if (apart) chosen.push_back(i);
  }
  if (chosen.size() < 4) return {};
  std::sort(chosen.begin(), chosen.end());
  const std::array<std::size_t, 4> at = {chosen[0], chosen[1], chosen[2], chosen[3]};
  if (!InLoopOrder(at, m)) return {};
  std::array<double, 4> side{};
  for (int c = 0; c < 4; ++c) {
    const double d = arc[at[(c + 1) % 4]] - arc[at[c]];
    side[c] = d > 0.0 ? d : d + perimeter;
  }
  const double w = 0.5 * (side[0] + side[2]);
  const double h = 0.5 * (side[1] + side[3]);
  // Anywhere in the chart's frame: the area is scaled back afterwards.
  const Eigen::Vector2d o = uv[loop[at[0]]];
  const std::array<Eigen::Vector2d, 4> corners = {
      o, o + Eigen::Vector2d(w, 0.0), o + Eigen::Vector2d(w, h), o + Eigen::Vector2d(0.0, h)};
  return ShiftOntoRectangle(chart, loop, uv, at, corners, true, solver);
}

struct Flattened {
  bool valid = false;
  bool abf_converged = true;
  std::vector<Eigen::Vector2d> uv;  // per local vertex
  // A bent band unbent (valid, filling more of its box) whose stretch is over the chart's
  // bound: the atlas-wide stretch budget decides (empty when there is none).
  std::vector<Eigen::Vector2d> unbent;
  bool straightened = false;  // uv is a bent band's straightened within the bound
  double area = 0.0;          // surface area
  double stretch = 1.0, unbent_stretch = 1.0;
  double fill = 1.0, unbent_fill = 1.0;  // of the minimum-area box
};

// Rectification in steps of half the remaining way, each from the last one's result, while
// the chart stays valid and within `bound` (a step that fails is halved, twice at most). The
// displacement is linear in the step: solved once per step.
void Rectify(const FaceGraph& g, const Chart& chart, const std::vector<int>& chart_of_face,
             const std::vector<int>& loop, double bound, HarmonicSolver* solver,
             std::vector<Eigen::Vector2d>* uv) {
  for (int step = 0; step < kRectifySteps && !loop.empty(); ++step) {
    bool taken = false;
    const std::vector<Eigen::Vector2d> shift = RectifyingShift(chart, loop, *uv, solver);
    for (double amount = 0.5; amount > 0.1 && !shift.empty() && !taken; amount *= 0.5) {
      std::vector<Eigen::Vector2d> rectified = *uv;
      for (std::size_t v = 0; v < rectified.size(); ++v) rectified[v] += amount * shift[v];
      ScaleToSurfaceArea(g, chart, &rectified);
      if (!IsValid(g, chart, chart_of_face, rectified) || ChartStretch(g, chart, rectified) > bound)
        continue;
      *uv = std::move(rectified);
      taken = true;
    }
    if (!taken) break;
  }
}

Flattened Flatten(const FaceGraph& g, const Chart& chart, const std::vector<int>& chart_of_face,
                  const ParameterizationOptions& options) {
  Flattened out;
  std::vector<double> alpha;
  out.abf_converged = SolveAbf(g, chart, options, &alpha);
  bool finite = true;
  for (const double a : alpha) finite = finite && std::isfinite(a);
  if (!finite) {  // fall back to the 3D angles
    ParameterizationOptions plain = options;
    plain.max_abf_iterations = 0;
    SolveAbf(g, chart, plain, &alpha);
  }
  out.uv = Reconstruct(g, chart, alpha);
  if (out.uv.empty()) return out;
  ScaleToSurfaceArea(g, chart, &out.uv);
  out.valid =
      IsValid(g, chart, chart_of_face, out.uv) &&
      (chart.faces.size() == 1 || ChartStretch(g, chart, out.uv) <= options.max_chart_stretch);
  for (const int f : chart.faces) out.area += g.areas[f];
  if (!out.valid || !(options.rectify_max_stretch > 1.0) || chart.faces.size() == 1) return out;
  const std::vector<int> loop = BoundaryLoop(g, chart, chart_of_face);
  if (loop.empty()) return out;
  const double bound = std::max(options.rectify_max_stretch, ChartStretch(g, chart, out.uv));
  HarmonicSolver solver;
  // A bent band is also unbent, in one step, then squared up by rectification within its own
  // stretch.
  std::vector<Eigen::Vector2d> unbent;
  const double flattened_fill = BoxFill(loop, out.uv);
  if (flattened_fill < kUnbendBelowFill) {
    const std::vector<Eigen::Vector2d> shift = UnbendingShift(chart, loop, out.uv, &solver);
    if (!shift.empty()) {
      unbent = out.uv;
      for (std::size_t v = 0; v < unbent.size(); ++v) unbent[v] += shift[v];
      ScaleToSurfaceArea(g, chart, &unbent);
      const double stretch = ChartStretch(g, chart, unbent);
      if (!IsValid(g, chart, chart_of_face, unbent) || stretch > options.max_unbent_stretch ||
          !(BoxFill(loop, unbent) > flattened_fill))
        unbent.clear();
      else
        Rectify(g, chart, chart_of_face, loop, std::max(bound, stretch), &solver, &unbent);
    }
  }
  Rectify(g, chart, chart_of_face, loop, bound, &solver, &out.uv);
  out.stretch = ChartStretch(g, chart, out.uv);
  out.fill = BoxFill(loop, out.uv);
  if (!unbent.empty()) {
    const double stretch = ChartStretch(g, chart, unbent);
    const double fill = BoxFill(loop, unbent);
    if (fill > out.fill && stretch <= bound) {  // better at no cost
      out.uv = std::move(unbent);
      out.stretch = stretch;
      out.fill = fill;
      out.straightened = true;
    } else if (fill > out.fill) {
      out.unbent = std::move(unbent);
      out.unbent_stretch = stretch;
      out.unbent_fill = fill;
    }
  }
  return out;
}

}  // namespace

const OptionTable<ParameterizationOptions>& ParameterizationOptions::Fields() {
  using O = ParameterizationOptions;
  static const OptionTable<O> table = [] {
    OptionTable<O> t;
    t.Add(&O::max_abf_iterations, {.name = "abf-iterations",
                                   .help = "Newton steps of ABF++ at most",
                                   .min = 1,
                                   .max = 100,
                                   .special = 0,
                                   .special_meaning = "plain LSCM from the 3D angles",
                                   .advanced = true});
    t.Add(&O::abf_tolerance, {.name = "abf-tolerance",
                              .help = "ABF++ stops when every constraint holds to this",
                              .unit = "rad",
                              .min = 0,
                              .min_exclusive = true,
                              .advanced = true});
    t.Add(&O::max_split_depth,
          {.name = "max-split-depth",
           .help = "a chart that will not flatten validly is split at most this many times over",
           .min = 0,
           .max = 64,
           .advanced = true});
    t.Add(&O::max_chart_stretch,
          {.name = "max-chart-stretch",
           .help = "charts whose L2 stretch exceeds this are split (protrusions keep texels)",
           .min = 1,
           .advanced = true});
    t.Add(&O::rectify_max_stretch,
          {.name = "rectify-stretch",
           .help = "charts pulled towards rectangles (tighter packing) while their L2 stretch "
                   "stays under this; 1 = angle-preserving flattening only",
           .min = 1,
           .advanced = true});
    t.Add(&O::max_unbent_stretch,
          {.name = "unbend-stretch",
           .help = "charts flattened into bent bands are tried straightened up to this L2 "
                   "stretch; 1 = within rectify-stretch only",
           .min = 1,
           .advanced = true});
    t.Add(&O::unbend_budget_stretch,
          {.name = "unbend-budget",
           .help = "straightened bands over rectify-stretch are taken while the L2 stretch of "
                   "all charts stays under this",
           .min = 1,
           .advanced = true});
    return t;
  }();
  return table;
}

void ParameterizationOptions::Validate() const {
  Fields().Check(*this);
  auto finite = [](double value, const char* name) {
    CAROUSEL_THROW_IF(!std::isfinite(value), InvalidArgument,
                      "--" << name << " must be finite, got " << value);
  };
  finite(abf_tolerance, "abf-tolerance");
  finite(max_chart_stretch, "max-chart-stretch");
  finite(rectify_max_stretch, "rectify-stretch");
  finite(max_unbent_stretch, "unbend-stretch");
  finite(unbend_budget_stretch, "unbend-budget");
  CAROUSEL_THROW_IF(threads < 0, InvalidArgument,
                    "ParameterizationOptions.threads must be >= 0, got " << threads);
}

ParameterizationResult ParameterizeCharts(const Mesh& mesh, const std::vector<int>& chart_of_face,
                                          int charts, const ParameterizationOptions& options,
                                          Progress& progress) {
  options.Validate();
  CAROUSEL_THROW_IF(chart_of_face.size() != mesh.n_faces(), InvalidArgument,
                    "parameterization: " << chart_of_face.size() << " chart ids for "
                                         << mesh.n_faces() << " faces");
  for (const int c : chart_of_face)
    CAROUSEL_THROW_IF(c < 0 || c >= charts, InvalidArgument,
                      "parameterization: chart id " << c << " outside 0.." << charts - 1);
  Stopwatch stopwatch;
  progress.BeginStage("atlas: flattening");
  const FaceGraph graph = internal::BuildFaceGraph(mesh);
  ParameterizationResult result;
  result.chart_of_face = chart_of_face;
  result.uv.resize(mesh.n_faces());

  std::vector<std::vector<int>> pending(charts);
  for (int f = 0; f < graph.face_count(); ++f) pending[chart_of_face[f]].push_back(f);
  std::erase_if(pending, [](const std::vector<int>& faces) { return faces.empty(); });
  std::vector<int> depth(pending.size(), 0);
  int next_id = 0;
  std::vector<int> final_chart(mesh.n_faces(), -1);
  std::size_t total_faces = mesh.n_faces();
  std::size_t faces_done = 0;
  // The charts done: their surface area and stretch (for the L2 of all), and the straightened
  // bands waiting for the budget.
  struct Unbent {
    std::vector<int> faces;
    std::vector<std::array<Eigen::Vector2d, 3>> uv;  // per face
    double area, stretch, unbent_stretch, fill, unbent_fill;
  };
  std::vector<Unbent> unbent;
  double area_done = 0.0;
  double stretch_sq_done = 0.0;  // sum of area x stretch^2
  // A valid chart that still fills little of its box (a C around a concavity) is tried split
  // in parts, flattened in the next round; the parts are kept when they are all valid and
  // their boxes together are under kSplitGain of the chart's, else the chart as it was.
  struct SplitTrial {
    std::vector<int> faces;
    std::vector<std::array<Eigen::Vector2d, 3>> uv;  // per face, the chart as it was
    double area, stretch, fill;
    std::vector<std::size_t> parts;  // in the next round's pending
  };
  std::vector<SplitTrial> trials;
  std::vector<int> trial_of(pending.size(), -1);  // per pending chart: the trial it is a part of
  auto per_face = [](const Chart& chart, const std::vector<Eigen::Vector2d>& uv) {
    std::vector<std::array<Eigen::Vector2d, 3>> out(chart.faces.size());
    for (std::size_t i = 0; i < chart.faces.size(); ++i)
      for (int k = 0; k < 3; ++k) out[i][k] = uv[chart.corners[i][k]];
    return out;
  };
  // A chart done: its UVs and its id; its stretch counted; a straightened alternative queued.
  auto finish = [&](const std::vector<int>& faces,
                    const std::vector<std::array<Eigen::Vector2d, 3>>& uv, double area,
                    double stretch) {
    for (std::size_t i = 0; i < faces.size(); ++i) {
      result.uv[faces[i]] = uv[i];
      final_chart[faces[i]] = next_id;
      result.chart_of_face[faces[i]] = -1;  // done: never mistaken for a later round's chart
    }
    area_done += area;
    stretch_sq_done += area * stretch * stretch;
    ++next_id;
    faces_done += faces.size();
  };
  auto finish_flat = [&](const std::vector<int>& faces, const Chart& chart, const Flattened& f) {
    finish(faces, per_face(chart, f.uv), f.area, f.stretch);
    if (f.straightened) ++result.charts_unbent;
    if (!f.unbent.empty())
      unbent.push_back({faces, per_face(chart, f.unbent), f.area, f.stretch, f.unbent_stretch,
                        f.fill, f.unbent_fill});
  };
  // Rounds: flatten every pending chart (in parallel); split the invalid ones for the next.
  while (!pending.empty()) {
    // Chart ids for this round: unique per pending chart, in result.chart_of_face (faces of
    // charts already done hold -1).
    for (std::size_t c = 0; c < pending.size(); ++c)
      for (const int f : pending[c]) result.chart_of_face[f] = static_cast<int>(c);
    std::vector<Flattened> flat(pending.size());
    std::vector<Chart> local(pending.size());
    std::atomic<int> not_converged{0};
    // Largest first: the last chart handed out is a small one, so the threads finish together.
    std::vector<std::size_t> order(pending.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) {
      return pending[a].size() > pending[b].size();
    });
    ParallelFor(pending.size(), 1, options.threads, [&](std::size_t begin, std::size_t end) {
      for (std::size_t i = begin; i < end; ++i) {
        const std::size_t c = order[i];
        progress.CheckCancelled();
        local[c] = MakeChart(graph, pending[c], result.chart_of_face);
        flat[c] = Flatten(graph, local[c], result.chart_of_face, options);
        if (!flat[c].abf_converged) ++not_converged;
      }
    });
    result.abf_not_converged += not_converged;
    // The trials whose parts this round flattened (the last round's, the only ones with parts
    // left): the parts, or the chart as it was.
    for (SplitTrial& trial : trials) {
      if (trial.parts.empty()) continue;
      bool all_valid = true;
      double boxes = 0.0;
      for (const std::size_t p : trial.parts) {
        all_valid = all_valid && flat[p].valid;
        boxes += flat[p].area / std::max(flat[p].fill, 1e-9);
      }
      if (all_valid && boxes < kSplitGain * trial.area / std::max(trial.fill, 1e-9)) {
        for (const std::size_t p : trial.parts) finish_flat(pending[p], local[p], flat[p]);
        ++result.charts_split_for_fill;
      } else {
        finish(trial.faces, trial.uv, trial.area, trial.stretch);
      }
      trial.parts.clear();
    }
    std::vector<std::vector<int>> next;
    std::vector<int> next_depth;
    std::vector<int> next_trial;
    for (std::size_t c = 0; c < pending.size(); ++c) {
      if (trial_of[c] >= 0) continue;  // a part: done above
      const bool single = pending[c].size() == 1;
      const Flattened& f = flat[c];
      if (f.valid && !single && f.fill < kSplitBelowFill && !f.straightened && f.unbent.empty() &&
          pending[c].size() >= kSplitMinFaces) {
        const std::vector<int> parts =
            internal::SplitChart(graph, pending[c], ChartOptions(), progress);
        const int n_parts = *std::max_element(parts.begin(), parts.end()) + 1;
        if (n_parts > 1) {
          SplitTrial trial{pending[c], per_face(local[c], f.uv), f.area, f.stretch, f.fill, {}};
          const std::size_t first = next.size();
          next.resize(first + n_parts);
          next_depth.resize(first + n_parts, depth[c] + 1);
          next_trial.resize(first + n_parts, static_cast<int>(trials.size()));
          for (std::size_t i = 0; i < parts.size(); ++i)
            next[first + parts[i]].push_back(pending[c][i]);
          for (int p = 0; p < n_parts; ++p) trial.parts.push_back(first + p);
          trials.push_back(std::move(trial));
          continue;
        }
      }
      if (f.valid || (single && !f.uv.empty())) {
        finish_flat(pending[c], local[c], f);
        continue;
      }
      ++result.charts_split;
      std::vector<int> parts;
      if (depth[c] < options.max_split_depth && !single) {
        parts = internal::SplitChart(graph, pending[c], ChartOptions(), progress);
      } else {
        parts.resize(pending[c].size());  // last resort: one chart per face
        for (std::size_t i = 0; i < parts.size(); ++i) parts[i] = static_cast<int>(i);
      }
      const int n_parts = parts.empty() ? 0 : *std::max_element(parts.begin(), parts.end()) + 1;
      const std::size_t first = next.size();
      next.resize(first + n_parts);
      next_depth.resize(first + n_parts, depth[c] + 1);
      next_trial.resize(first + n_parts, -1);
      for (std::size_t i = 0; i < parts.size(); ++i)
        next[first + parts[i]].push_back(pending[c][i]);
    }
    pending = std::move(next);
    depth = std::move(next_depth);
    trial_of = std::move(next_trial);
    progress.Report(faces_done, total_faces);
  }
  // The straightened bands: most box area saved per unit of stretch^2 first, while the L2
  // stretch of all charts stays within the budget.
  std::sort(unbent.begin(), unbent.end(), [](const Unbent& a, const Unbent& b) {
    auto worth = [](const Unbent& u) {
      const double saved = u.area / u.fill - u.area / u.unbent_fill;
      const double cost = u.area * (u.unbent_stretch * u.unbent_stretch - u.stretch * u.stretch);
      return saved / std::max(cost, 1e-300);
    };
    return worth(a) > worth(b);
  });
  const double budget = options.unbend_budget_stretch * options.unbend_budget_stretch;
  for (const Unbent& u : unbent) {
    const double sum =
        stretch_sq_done + u.area * (u.unbent_stretch * u.unbent_stretch - u.stretch * u.stretch);
    if (!(area_done > 0.0) || sum > budget * area_done) continue;
    stretch_sq_done = sum;
    for (std::size_t i = 0; i < u.faces.size(); ++i) result.uv[u.faces[i]] = u.uv[i];
    ++result.charts_unbent;
  }
  result.l2_stretch = area_done > 0.0 ? std::sqrt(stretch_sq_done / area_done) : 1.0;
  result.chart_of_face = std::move(final_chart);
  result.charts = next_id;
  if (result.charts_split > 0)
    CAROUSEL_LOG_INFO("atlas: " << result.charts_split
                                << " chart(s) did not flatten one-to-one or within the stretch "
                                   "bound and were split");
  progress.EndStage();
  result.seconds = stopwatch.ElapsedSeconds();
  return result;
}

}  // namespace carousel::texture
