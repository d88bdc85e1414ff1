// pbr_lod — the hierarchical PCA octree: the octree and the build.
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003.
// What this file implements:
//   §3    the top-down octree (a node with more than leaf_size points splits at its cell centre)
//         and the build in the paper's order: normals (from core/estimation, k-NN PCA, oriented,
//         when the input has none), octree, per-node statistics (pca_octree_stats.cpp), §3.1
//         classification and quantisation (pca_octree_quantise.cpp); then the extent γ and the
//         curvature scale λ with the bounds they give (pca_derive_bounds).
//   The file is in pca_octree_io.cpp, the randomised rendering of §4 in pca_octree_render.cpp.

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
}  // namespace

unsigned pca_threads(unsigned requested) {
  if (requested != 0) return requested;
  return std::max(1u, std::thread::hardware_concurrency());
}

namespace {

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
  // The points are reordered in place with their normals and colours (a stable counting sort
  // per node), so every node's points are contiguous: each pass streams through memory.
  const bool colour = !in.colours.empty();
  std::vector<rgb8> cols(in.colours.begin(), in.colours.end());
  std::vector<vec3d> pos_tmp(n);
  std::vector<vec3f> nrm_tmp(n);
  std::vector<rgb8> col_tmp(cols.size());
  std::vector<std::uint8_t> oct(n);
  std::vector<build_node> ranges{{0, static_cast<std::uint32_t>(n)}};
  std::vector<vec3d> cell_min{d.cube_min};
  d.nodes.emplace_back();
  for (std::size_t i = 0; i < d.nodes.size(); ++i) {
    const build_node r = ranges[i];
    const std::uint32_t count = r.end - r.begin;
    pca_node& nd = d.nodes[i];
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
    if (count <= o.leaf_size || nd.depth >= o.max_depth) continue;
    vec3d plo = pos[r.begin], phi = plo;
    for (std::uint32_t k = r.begin; k < r.end; ++k) {
      plo = plo.cwiseMin(pos[k]);
      phi = phi.cwiseMax(pos[k]);
    }
    if (plo == phi) continue;  // all points identical: no split separates them
    const double half = d.cube_size / std::ldexp(1.0, nd.depth + 1);
    const vec3d mid = cell_min[i] + vec3d::Constant(half);
    std::array<std::uint32_t, 9> start{};
    for (std::uint32_t k = r.begin; k < r.end; ++k) {
      const vec3d& q = pos[k];
      oct[k] =
          static_cast<std::uint8_t>((q.x() >= mid.x() ? 1u : 0u) | (q.y() >= mid.y() ? 2u : 0u) |
                                    (q.z() >= mid.z() ? 4u : 0u));
      ++start[oct[k] + 1u];
    }
    for (int o8 = 0; o8 < 8; ++o8) start[o8 + 1] += start[o8];
    std::array<std::uint32_t, 8> at{};
    for (int o8 = 0; o8 < 8; ++o8) at[o8] = r.begin + start[o8];
    for (std::uint32_t k = r.begin; k < r.end; ++k) {
      const std::uint32_t to = at[oct[k]]++;
      pos_tmp[to] = pos[k];
      nrm_tmp[to] = normals[k];
      if (colour) col_tmp[to] = cols[k];
    }
    std::copy(pos_tmp.begin() + r.begin, pos_tmp.begin() + r.end, pos.begin() + r.begin);
    std::copy(nrm_tmp.begin() + r.begin, nrm_tmp.begin() + r.end, normals.begin() + r.begin);
    if (colour)
      std::copy(col_tmp.begin() + r.begin, col_tmp.begin() + r.end, cols.begin() + r.begin);
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
  if (colour) d.colours.resize(d.nodes.size());
  const std::size_t pieces = std::min<std::size_t>(d.nodes.size(), 64 * threads);
  parallel_tasks(pieces, threads, [&](std::size_t t, unsigned) {
    const auto [lo_n, hi_n] = piece_range(d.nodes.size(), pieces, t);
    for (std::size_t i = lo_n; i < hi_n; ++i) {
      const build_node r = ranges[i];
      const std::size_t m = r.end - r.begin;
      // The normals first: their mean is what the degenerate position rules align z with.
      // If they cancel out, the first sample's normal stands in (deterministic).
      const pca_normal_result pn =
          pca_normals(normals.data() + r.begin, m, normals[r.begin].cast<double>());
      const pca_position_result pp = pca_positions(pos.data() + r.begin, m, pn.frame.col(2));
      pca_node& nd = d.nodes[i];
      nd.mean = pp.mean.cast<float>();
      nd.frame = pp.frame.cast<float>();
      nd.sigma = pp.sigma.cast<float>().cwiseMax(static_cast<float>(sigma_floor));
      nd.normal_frame = pn.frame.cast<float>();
      nd.normal_sigma = pn.sigma.cast<float>();
      if (colour) d.colours[i] = pca_colours(cols.data() + r.begin, m);
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
