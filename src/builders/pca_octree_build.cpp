// pbr_lod — the hierarchical PCA octree: octree and per-node statistics.
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003.
// What this file implements:
//   §3    the top-down octree (a node with more than leaf_size points splits at its cell centre),
//         the per-node PCA of position with the degenerate rules (pca_positions), of the normals
//         on the unit sphere through the unwrap at the pole (pca_normals, unwrap_normal,
//         wrap_normal), of colour when the scene has it (pca_colours), the extent γ and the
//         curvature scale λ (pca_derive_bounds). Input without normals gets them from
//         core/estimation (k-NN PCA, oriented).
//   The classification and quantisation of §3.1 are in pca_octree_quantise.cpp, the file in
//   pca_octree_io.cpp, the randomised rendering of §4 in pca_octree_render.cpp.

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>
#include <thread>

#include "pbr_lod/builders/pca_octree.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pca_octree_internal.hpp"

namespace pbr_lod {
template class pca_octree<with_normals>;
template class pca_octree<with_normals_colours>;
}  // namespace pbr_lod

namespace pbr_lod::detail {

namespace {
using clock_type = std::chrono::steady_clock;
double seconds_since(clock_type::time_point t0) {
  return std::chrono::duration<double>(clock_type::now() - t0).count();
}

/// §3: "we set a minimum value for σ_p^i (of the order 10⁻¹⁵)".
constexpr double sigma_floor = 1e-15;

/// Makes [f1 f2 f3] right-handed with f3·toward ≥ 0 and a canonical sign for f1 (its largest
/// component positive), so that the frame is a deterministic function of the data.
mat3d canonical_frame(vec3d f1, vec3d f3, const vec3d& toward) {
  if (f3.dot(toward) < 0) f3 = -f3;
  f1 -= f3 * f3.dot(f1);
  f1.normalize();
  Eigen::Index i = 0;
  f1.cwiseAbs().maxCoeff(&i);
  if (f1[i] < 0) f1 = -f1;
  mat3d f;
  f.col(0) = f1;
  f.col(1) = f3.cross(f1);
  f.col(2) = f3;
  return f;
}

/// any_orthogonal() in double (the float one would leave 1e-8 of non-orthogonality).
vec3d any_orthogonal_d(const vec3d& n) {
  const vec3d a = n.cwiseAbs();
  const vec3d axis = (a.x() <= a.y() && a.x() <= a.z()) ? vec3d::UnitX()
                     : (a.y() <= a.z())                 ? vec3d::UnitY()
                                                        : vec3d::UnitZ();
  return n.cross(axis).normalized();
}

}  // namespace

unsigned pca_threads(unsigned requested) {
  if (requested != 0) return requested;
  return std::max(1u, std::thread::hardware_concurrency());
}

// ---------------------------------------------------------------------------------------------
// §3: position PCA with the degenerate rules.
// ---------------------------------------------------------------------------------------------
pca_position_result pca_positions(const vec3d* p, std::size_t n, const vec3d& mean_normal) {
  pca_position_result r;
  if (n == 0) return r;
  vec3d mean = vec3d::Zero();
  for (std::size_t i = 0; i < n; ++i) mean += p[i];
  mean /= static_cast<double>(n);
  mat3d cov = mat3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d d = p[i] - mean;
    cov.noalias() += d * d.transpose();
  }
  cov /= static_cast<double>(n);
  r.mean = mean;
  const vec3d normal = (all_finite(mean_normal) && mean_normal.norm() > 0.5)
                           ? mean_normal.normalized()
                           : vec3d::UnitZ();
  Eigen::SelfAdjointEigenSolver<mat3d> es(cov);
  // Eigen sorts ascending: column 2 is the principal direction.
  const vec3d ev = es.eigenvalues().cwiseMax(0.0);
  vec3d sigma(std::sqrt(ev[2]), std::sqrt(ev[1]), std::sqrt(ev[0]));
  // "Zero" variance: below the floor, or below what float coordinates of this magnitude and
  // double rounding of the sums can resolve (a collinear float cloud is collinear only to
  // within its rounding).
  const double tol = sigma_floor + 1e-6 * std::max(sigma[0], mean.cwiseAbs().maxCoeff());
  int zeros = 0;
  for (int i = 0; i < 3; ++i) zeros += sigma[i] <= tol ? 1 : 0;
  r.zero_variances = zeros;
  if (!all_finite(es.eigenvectors()) || !all_finite(sigma)) zeros = 3;
  switch (zeros) {
    case 0:
    case 1:  // a plane: f³ is its normal
      r.frame = canonical_frame(es.eigenvectors().col(2), es.eigenvectors().col(0), normal);
      break;
    case 2: {  // a line: keep the principal direction, z along the mean normal
      const vec3d f1 = es.eigenvectors().col(2).normalized();
      vec3d z = normal - f1 * f1.dot(normal);
      if (!(z.norm() > 1e-6)) z = any_orthogonal_d(f1);
      r.frame = canonical_frame(f1, z.normalized(), normal);
      sigma[1] = sigma[2] = 0;
      break;
    }
    default:  // a point: z along the normal, any tangent pair
      r.frame = canonical_frame(any_orthogonal_d(normal), normal, normal);
      sigma.setZero();
  }
  r.sigma = sigma.cwiseMax(sigma_floor);
  return r;
}

// ---------------------------------------------------------------------------------------------
// §3: normals on the unit sphere.
// ---------------------------------------------------------------------------------------------
vec2d unwrap_normal(const mat3d& frame, const vec3d& n) {
  const vec3d l = frame.transpose() * n;
  const double r = std::hypot(l.x(), l.y());
  const double theta = std::atan2(r, l.z());
  if (!(r > 0)) return {theta, 0.0};  // the pole (θ = 0) or its antipode (θ = π: any azimuth)
  return {theta * l.x() / r, theta * l.y() / r};
}

vec3d wrap_normal(const mat3d& frame, const vec2d& uv) {
  const double theta = uv.norm();
  if (!(theta > 0)) return frame.col(2);
  const double s = std::sin(theta) / theta;
  return (frame * vec3d(uv.x() * s, uv.y() * s, std::cos(theta))).normalized();
}

pca_normal_result pca_normals(const vec3f* n, std::size_t count, const vec3d& fallback) {
  pca_normal_result r;
  vec3d sum = vec3d::Zero();
  for (std::size_t i = 0; i < count; ++i) sum += n[i].cast<double>();
  // The normals cancel out (a thin sheet seen from both sides): no mean direction exists, use
  // the caller's.
  vec3d z = sum.norm() > 1e-9 * static_cast<double>(count) ? vec3d(sum.normalized()) : fallback;
  if (!(z.norm() > 0.5)) z = vec3d::UnitZ();
  z.normalize();
  mat3d f;
  f.col(0) = any_orthogonal_d(z);
  f.col(1) = z.cross(f.col(0));
  f.col(2) = z;
  // Second moments of the unwrapped normals about the pole (the generator of §4 is centred
  // there).
  Eigen::Matrix2d m = Eigen::Matrix2d::Zero();
  for (std::size_t i = 0; i < count; ++i) {
    const vec2d uv = unwrap_normal(f, n[i].cast<double>());
    m.noalias() += uv * uv.transpose();
  }
  if (count > 0) m /= static_cast<double>(count);
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(m);
  const vec2d ev = es.eigenvalues().cwiseMax(0.0);
  vec2d axis = es.eigenvectors().col(1);
  if (!all_finite(axis) || !(axis.norm() > 0.5) || !(ev[1] > 0)) axis = vec2d::UnitX();
  axis.normalize();
  if (axis.x() < 0 || (axis.x() == 0 && axis.y() < 0)) axis = -axis;
  r.frame.col(0) = (f.col(0) * axis.x() + f.col(1) * axis.y()).normalized();
  r.frame.col(1) = z.cross(r.frame.col(0));
  r.frame.col(2) = z;
  r.sigma = vec2d(std::sqrt(ev[1]), std::sqrt(ev[0]));
  if (!all_finite(r.sigma)) r.sigma.setZero();
  return r;
}

namespace {

/// §3: colour PCA of (r, g, b) in [0, 1]; no floor on σ_c (the paper finds none necessary).
pca_colour pca_colours(const rgb8* c, const std::uint32_t* idx, std::size_t n) {
  pca_colour r;
  vec3d mean = vec3d::Zero();
  const auto get = [&](std::size_t i) -> vec3d {
    const rgb8 k = c[idx[i]];
    return vec3d(k.r, k.g, k.b) / 255.0;
  };
  for (std::size_t i = 0; i < n; ++i) mean += get(i);
  mean /= static_cast<double>(n);
  mat3d cov = mat3d::Zero();
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d d = get(i) - mean;
    cov.noalias() += d * d.transpose();
  }
  cov /= static_cast<double>(n);
  Eigen::SelfAdjointEigenSolver<mat3d> es(cov);
  const vec3d ev = es.eigenvalues().cwiseMax(0.0);
  mat3d f = mat3d::Identity();
  if (all_finite(es.eigenvectors()))
    f = canonical_frame(es.eigenvectors().col(2), es.eigenvectors().col(0), vec3d(1, 1, 1));
  r.mean = mean.cast<float>();
  r.frame = f.cast<float>();
  r.sigma = vec3d(std::sqrt(ev[2]), std::sqrt(ev[1]), std::sqrt(ev[0])).cast<float>();
  return r;
}

struct build_node {
  std::uint32_t begin, end;  // range of perm
};

void check_progress(const pca_octree_options& o, double f) {
  if (o.progress && !o.progress(f)) throw Cancelled("pca-octree build cancelled");
}

void validate(const pca_input& in, const pca_octree_options& o) {
  if (in.positions.empty()) throw InvalidArgument("pca-octree: the input has no points");
  if (in.positions.size() >= (1ull << 32) - 1)
    throw InvalidArgument("pca-octree: more than 2^32 - 2 points");
  if (!all_finite(in.origin)) throw InvalidArgument("pca-octree: the origin is not finite");
  if (!in.normals.empty() && in.normals.size() != in.positions.size())
    throw InvalidArgument("pca-octree: " + std::to_string(in.normals.size()) + " normals for " +
                          std::to_string(in.positions.size()) + " points");
  if (!in.colours.empty() && in.colours.size() != in.positions.size())
    throw InvalidArgument("pca-octree: " + std::to_string(in.colours.size()) + " colours for " +
                          std::to_string(in.positions.size()) + " points");
  for (std::size_t i = 0; i < in.positions.size(); ++i)
    if (!all_finite(in.positions[i]))
      throw InvalidArgument("pca-octree: position " + std::to_string(i) + " is not finite");
  for (std::size_t i = 0; i < in.normals.size(); ++i)
    if (!all_finite(in.normals[i]) || !(in.normals[i].squaredNorm() > 0))
      throw InvalidArgument("pca-octree: normal " + std::to_string(i) + " is zero or not finite");
  const auto need = [](bool ok, const std::string& what) {
    if (!ok) throw InvalidArgument("pca-octree: " + what);
  };
  need(o.leaf_size >= 1, "leaf_size must be at least 1");
  need(o.max_depth >= 1 && o.max_depth <= 30, "max_depth must lie in 1..30");
  need(std::isfinite(o.gamma) && o.gamma > 0 && o.gamma <= 10, "gamma must lie in (0, 10]");
  need(std::isfinite(o.curvature_c) && o.curvature_c >= 0, "curvature_c must be >= 0");
  need(std::isfinite(o.lambda_max) && o.lambda_max >= 1 && o.lambda_max <= 16,
       "lambda_max must lie in [1, 16]");
  need(o.position_codebook >= 1 && o.position_codebook <= 4096,
       "position_codebook must lie in 1..4096 (12-bit indices)");
  need(o.normal_codebook >= 1 && o.normal_codebook <= 4096,
       "normal_codebook must lie in 1..4096 (12-bit indices)");
  need(o.colour_codebook >= 1 && o.colour_codebook <= 64,
       "colour_codebook must lie in 1..64 (6-bit indices)");
  need(o.kmeans_sample >= 1, "kmeans_sample must be at least 1");
  need(o.knn >= 3 || !in.normals.empty(), "knn must be at least 3");
}

}  // namespace

pca_data build_pca_data(const pca_input& in, const pca_octree_options& o) {
  const auto t0 = clock_type::now();
  validate(in, o);
  const unsigned threads = pca_threads(o.threads);
  pca_data d;
  d.leaf_size = o.leaf_size;
  d.max_depth = o.max_depth;
  d.gamma = o.gamma;
  d.curvature_c = o.curvature_c;
  d.lambda_max = o.lambda_max;
  d.quantised = o.quantise;
  auto& st = d.stats;
  st.input_points = in.positions.size();
  const std::size_t n = in.positions.size();
  check_progress(o, 0);

  // Normals: the input's (normalised), or k-NN estimates (Hoppe et al., oriented).
  std::vector<vec3f> normals;
  if (in.normals.empty()) {
    const auto te = clock_type::now();
    normals = estimate_normals(in.positions, o.knn, true);
    st.estimation_seconds = seconds_since(te);
    st.estimated_normals = true;
  } else {
    normals.resize(n);
    for (std::size_t i = 0; i < n; ++i) normals[i] = in.normals[i].normalized();
  }
  check_progress(o, 0.2);
  const auto tt = clock_type::now();

  // A double origin at the centre of the data's box; positions relative to it in double.
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : in.positions) {
    lo = lo.cwiseMin(p.cast<double>());
    hi = hi.cwiseMax(p.cast<double>());
  }
  const vec3d centre_rel = 0.5 * (lo + hi);
  d.origin = in.origin + centre_rel;
  std::vector<vec3d> pos(n);
  for (std::size_t i = 0; i < n; ++i) {
    pos[i] = in.positions[i].cast<double>() - centre_rel;
    d.input_radius = std::max(d.input_radius, pos[i].norm());
  }
  // The root cell: a cube about the box, enlarged by a hair so that no point lies on its far
  // faces after rounding.
  double size = (hi - lo).maxCoeff();
  size = size > 0 ? size * (1 + 1e-9) : 1e-9 * std::max(1.0, in.origin.cwiseAbs().maxCoeff());
  d.cube_size = size;
  d.cube_min = vec3d::Constant(-0.5 * size);

  // ---- §3: top-down octree, breadth first; children contiguous, in octant order.
  std::vector<std::uint32_t> perm(n), tmp(n);
  for (std::size_t i = 0; i < n; ++i) perm[i] = static_cast<std::uint32_t>(i);
  std::vector<build_node> ranges{{0, static_cast<std::uint32_t>(n)}};
  std::vector<vec3d> cell_min{d.cube_min};
  d.nodes.emplace_back();
  for (std::size_t i = 0; i < d.nodes.size(); ++i) {
    const build_node r = ranges[i];
    const std::uint32_t count = r.end - r.begin;
    pca_node& nd = d.nodes[i];
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
    if (count <= o.leaf_size || nd.depth >= o.max_depth) continue;
    vec3d plo = pos[perm[r.begin]], phi = plo;
    for (std::uint32_t k = r.begin; k < r.end; ++k) {
      plo = plo.cwiseMin(pos[perm[k]]);
      phi = phi.cwiseMax(pos[perm[k]]);
    }
    if (plo == phi) continue;  // all points identical: no split separates them
    const double half = d.cube_size / std::ldexp(1.0, nd.depth + 1);
    const vec3d mid = cell_min[i] + vec3d::Constant(half);
    const auto octant = [&](std::uint32_t p) {
      const vec3d& q = pos[p];
      return (q.x() >= mid.x() ? 1u : 0u) | (q.y() >= mid.y() ? 2u : 0u) |
             (q.z() >= mid.z() ? 4u : 0u);
    };
    std::array<std::uint32_t, 9> start{};
    for (std::uint32_t k = r.begin; k < r.end; ++k) ++start[octant(perm[k]) + 1];
    for (int o8 = 0; o8 < 8; ++o8) start[o8 + 1] += start[o8];
    std::array<std::uint32_t, 8> at{};
    for (int o8 = 0; o8 < 8; ++o8) at[o8] = r.begin + start[o8];
    for (std::uint32_t k = r.begin; k < r.end; ++k) tmp[at[octant(perm[k])]++] = perm[k];
    std::copy(tmp.begin() + r.begin, tmp.begin() + r.end, perm.begin() + r.begin);
    const auto first = static_cast<std::uint32_t>(d.nodes.size());
    std::uint8_t mask = 0, kids = 0;
    const std::uint8_t depth = static_cast<std::uint8_t>(nd.depth + 1);
    const vec3d cmin = cell_min[i];
    for (unsigned o8 = 0; o8 < 8; ++o8) {
      if (start[o8 + 1] == start[o8]) continue;
      mask = static_cast<std::uint8_t>(mask | (1u << o8));
      ++kids;
      ranges.push_back({r.begin + start[o8], r.begin + start[o8 + 1]});
      cell_min.push_back(cmin +
                         vec3d((o8 & 1) ? half : 0, (o8 & 2) ? half : 0, (o8 & 4) ? half : 0));
      pca_node c;
      c.depth = depth;
      d.nodes.push_back(c);
    }
    pca_node& parent = d.nodes[i];  // (push_back may have moved it)
    parent.first = first;
    parent.count = kids;
    parent.mask = mask;
  }
  st.nodes = d.nodes.size();
  for (const auto& nd : d.nodes) st.leaves += nd.count == 0 ? 1 : 0;
  check_progress(o, 0.35);

  // ---- §3: independent PCA of each node's positions, normals and colours.
  const bool colour = !in.colours.empty();
  if (colour) d.colours.resize(d.nodes.size());
  const std::size_t pieces = std::min<std::size_t>(d.nodes.size(), 64 * threads);
  parallel_tasks(pieces, threads, [&](std::size_t t, unsigned) {
    std::vector<vec3d> p;
    std::vector<vec3f> nn;
    const auto [lo_n, hi_n] = piece_range(d.nodes.size(), pieces, t);
    for (std::size_t i = lo_n; i < hi_n; ++i) {
      const build_node r = ranges[i];
      const std::size_t m = r.end - r.begin;
      p.resize(m);
      nn.resize(m);
      for (std::size_t k = 0; k < m; ++k) {
        p[k] = pos[perm[r.begin + k]];
        nn[k] = normals[perm[r.begin + k]];
      }
      // The normals first: their mean is what the degenerate position rules align z with.
      // If they cancel out, the first sample's normal stands in (deterministic).
      const pca_normal_result pn = pca_normals(nn.data(), m, nn[0].cast<double>());
      const pca_position_result pp = pca_positions(p.data(), m, pn.frame.col(2));
      pca_node& nd = d.nodes[i];
      nd.mean = pp.mean.cast<float>();
      nd.frame = pp.frame.cast<float>();
      nd.sigma = pp.sigma.cast<float>().cwiseMax(static_cast<float>(sigma_floor));
      nd.normal_frame = pn.frame.cast<float>();
      nd.normal_sigma = pn.sigma.cast<float>();
      if (colour) d.colours[i] = pca_colours(in.colours.data(), perm.data() + r.begin, m);
    }
  });
  pca_derive_cells(d);
  st.tree_seconds = seconds_since(tt);
  check_progress(o, 0.6);

  // ---- §3.1: classification and quantisation (the hierarchy then holds the decoded values).
  if (o.quantise) pca_quantise(d, o, threads);
  pca_derive_bounds(d);
  check_progress(o, 1);
  st.seconds = seconds_since(t0);
  st.has_timings = true;
  return d;
}

// ---------------------------------------------------------------------------------------------
// Derived data (build and load).
// ---------------------------------------------------------------------------------------------
void pca_derive_cells(pca_data& d) {
  if (d.nodes.empty()) return;
  d.nodes[0].cell_min = d.cube_min;
  d.nodes[0].cell_size = d.cube_size;
  for (auto& nd : d.nodes) {
    if (nd.count == 0) continue;
    const double half = 0.5 * nd.cell_size;
    std::uint32_t c = nd.first;
    for (unsigned o8 = 0; o8 < 8; ++o8) {
      if (!(nd.mask & (1u << o8))) continue;
      pca_node& ch = d.nodes[c++];
      ch.cell_min =
          nd.cell_min + vec3d((o8 & 1) ? half : 0, (o8 & 2) ? half : 0, (o8 & 4) ? half : 0);
      ch.cell_size = half;
      ch.depth = static_cast<std::uint8_t>(nd.depth + 1);
    }
  }
}

void pca_derive_bounds(pca_data& d) {
  if (d.nodes.empty()) return;
  const float root_norm = d.nodes[0].sigma.norm();
  d.lambda_norm = root_norm > 0 ? root_norm : 1.0f;
  const float pi = std::numbers::pi_v<float>;
  for (std::size_t i = d.nodes.size(); i-- > 0;) {
    pca_node& nd = d.nodes[i];
    // §3: λ = c·√(σ_n¹/‖σ_p‖), ‖σ_p‖ in units of the root's (see pca_octree_options).
    float lambda = 1;
    if (d.curvature_c > 0) {
      const float rel = nd.sigma.norm() / d.lambda_norm;
      const float l = d.curvature_c * std::sqrt(nd.normal_sigma.x() / std::max(rel, 1e-30f));
      lambda = std::clamp(std::isfinite(l) ? l : d.lambda_max, 1.0f, d.lambda_max);
    }
    nd.lambda = lambda;
    // The generator truncates at γ: positions lie in the ellipsoid of semi-axes γ·λ·σ_p,
    // normals within γ·σ_n¹ of the mean normal. Children's bounds are added so that the
    // sphere and the cone hold everything the subtree generates.
    float r = d.gamma * lambda * nd.sigma.x();
    float cone = std::min(pi, d.gamma * nd.normal_sigma.x());
    const vec3f axis = nd.normal_frame.col(2);
    for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) {
      const pca_node& ch = d.nodes[c];
      r = std::max(r, (ch.mean - nd.mean).norm() + ch.radius);
      const float a = std::acos(std::clamp(axis.dot(ch.normal_frame.col(2)), -1.0f, 1.0f));
      cone = std::max(cone, a + ch.cone_angle);
    }
    // Float rounding of the generated points: a relative hair on top.
    nd.radius = r * (1 + 1e-5f) + 1e-6f * nd.mean.cwiseAbs().maxCoeff() + 1e-30f;
    nd.cone_angle = std::min(pi, cone + 1e-4f);
  }
}

bool operator==(const pca_data& a, const pca_data& b) {
  return a.origin == b.origin && a.cube_min == b.cube_min && a.cube_size == b.cube_size &&
         a.input_radius == b.input_radius && a.nodes == b.nodes && a.colours == b.colours &&
         a.leaf_size == b.leaf_size && a.max_depth == b.max_depth && a.gamma == b.gamma &&
         a.curvature_c == b.curvature_c && a.lambda_max == b.lambda_max &&
         a.lambda_norm == b.lambda_norm && a.quantised == b.quantised &&
         a.codebook_p == b.codebook_p && a.codebook_n == b.codebook_n &&
         a.codebook_c == b.codebook_c && a.records == b.records &&
         a.colour_records == b.colour_records;
}

}  // namespace pbr_lod::detail
