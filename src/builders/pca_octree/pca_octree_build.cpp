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
#include "pbr_lod/core/normal_repair.hpp"
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

void pca_validate_options(const pca_octree_options& o, bool input_normals) {
  const auto need = [](bool ok, const std::string& what) {
    if (!ok) throw InvalidArgument("pca-octree: " + what);
  };
  need(o.leaf_size >= 1, "leaf_size must be at least 1");
  need(o.max_depth >= 1 && o.max_depth <= 30, "max_depth must lie in 1..30");
  need(std::isfinite(o.gamma) && o.gamma > 0 && o.gamma <= 10, "gamma must lie in (0, 10]");
  need(std::isfinite(o.curvature_c) && o.curvature_c >= 0, "curvature_c must be >= 0");
  need(std::isfinite(o.lambda_max) && o.lambda_max >= 1 && o.lambda_max <= 16,
       "lambda_max must lie in [1, 16]");
  need(std::isfinite(o.surface_angle) && o.surface_angle > 0 && o.surface_angle <= 180,
       "surface_angle must lie in (0, 180] degrees");
  need(std::isfinite(o.colour_tolerance) && o.colour_tolerance >= 0,
       "colour_tolerance must be >= 0");
  need(o.position_codebook >= 1 && o.position_codebook <= 4096,
       "position_codebook must lie in 1..4096 (12-bit indices)");
  need(o.normal_codebook >= 1 && o.normal_codebook <= 4096,
       "normal_codebook must lie in 1..4096 (12-bit indices)");
  need(o.colour_codebook >= 1 && o.colour_codebook <= 64,
       "colour_codebook must lie in 1..64 (6-bit indices)");
  need(o.kmeans_sample >= 1, "kmeans_sample must be at least 1");
  need(o.knn >= 3 || input_normals, "knn must be at least 3");
}

unsigned pca_threads(unsigned requested) {
  return resolve_threads(requested);
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
  if (in.axis_u.size() != in.axis_v.size() ||
      (!in.axis_u.empty() && in.axis_u.size() != in.positions.size()))
    throw InvalidArgument("pca-octree: " + std::to_string(in.axis_u.size()) + " and " +
                          std::to_string(in.axis_v.size()) + " splat axes for " +
                          std::to_string(in.positions.size()) + " points");
  for (std::size_t i = 0; i < in.positions.size(); ++i)
    if (!all_finite(in.positions[i]))
      throw InvalidArgument("pca-octree: position " + std::to_string(i) + " is not finite");
  for (std::size_t i = 0; i < in.axis_u.size(); ++i)
    if (!all_finite(in.axis_u[i]) || !all_finite(in.axis_v[i]))
      throw InvalidArgument("pca-octree: the splat axes of point " + std::to_string(i) +
                            " are not finite");
  pca_validate_options(o, !in.normals.empty());
}

/// The points being partitioned (reordered in place, a stable counting sort per node, so that
/// every node's points are contiguous and each pass streams through memory), with the input
/// index of each (normals and colours follow once, at the end: permute_by()), and the split
/// rule's parameters.
struct octree_points {
  std::vector<vec3d>& pos;
  double cube_size;
  std::uint32_t leaf_size, max_depth;
  /// Unit normals in input order (normals[index[k]] is point k's) and the cosine of
  /// pca_octree_options::surface_angle: a small node whose normals differ more is split.
  const std::vector<vec3f>& normals;
  float surface_cos;
  /// Colours in input order (or empty) and pca_octree_options::colour_tolerance squared, in
  /// 8-bit units: a small node whose colours differ more is split.
  const std::vector<rgb8>& colours;
  float colour_tol2;
  std::vector<std::uint32_t> index = identity(pos.size());
  std::vector<vec3d> pos_tmp = std::vector<vec3d>(pos.size());
  std::vector<std::uint32_t> index_tmp = std::vector<std::uint32_t>(pos.size());
  std::vector<std::uint8_t> oct = std::vector<std::uint8_t>(pos.size());

  static std::vector<std::uint32_t> identity(std::size_t n) {
    std::vector<std::uint32_t> v(n);
    for (std::size_t i = 0; i < n; ++i) v[i] = static_cast<std::uint32_t>(i);
    return v;
  }
};

/// v reordered as the octree ordered the points: out[i] = v[index[i]].
template <class T>
std::vector<T> permute_by(const std::vector<T>& v, const std::vector<std::uint32_t>& index,
                          unsigned threads) {
  std::vector<T> out(v.size());
  if (v.empty()) return out;
  parallel_chunks(v.size(), threads, 1u << 16, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t i = lo; i < hi; ++i) out[i] = v[index[i]];
  });
  return out;
}

/// A node of a part of the octree while it is built: structure, points, cell.
struct part_node {
  build_node range;
  vec3d cell_min;
  std::uint32_t first = 0;
  std::uint8_t count = 0, mask = 0, depth = 0;
};

/// Octant of q about mid (bit 0 = +x half, 1 = +y, 2 = +z).
inline std::uint8_t octant(const vec3d& q, const vec3d& mid) {
  return static_cast<std::uint8_t>((q.x() >= mid.x() ? 1u : 0u) | (q.y() >= mid.y() ? 2u : 0u) |
                                   (q.z() >= mid.z() ? 4u : 0u));
}

/// Moves point k of the range to slot `to` of the scratch arrays.
inline void move_to_scratch(octree_points& p, std::uint32_t k, std::uint32_t to) {
  p.pos_tmp[to] = p.pos[k];
  p.index_tmp[to] = p.index[k];
}
void copy_back(octree_points& p, std::size_t b, std::size_t e) {
  using d = std::ptrdiff_t;
  std::copy(p.pos_tmp.begin() + d(b), p.pos_tmp.begin() + d(e), p.pos.begin() + d(b));
  std::copy(p.index_tmp.begin() + d(b), p.index_tmp.begin() + d(e), p.index.begin() + d(b));
}

/// Stable counting sort of the points of r by octant about mid; start[o] is where octant o
/// begins (relative to r.begin), start[8] the count. False (nothing moved) when all of r's
/// positions coincide.
bool partition_serial(octree_points& p, build_node r, const vec3d& mid,
                      std::array<std::uint32_t, 9>& start) {
  start = {};
  vec3d plo = p.pos[r.begin], phi = plo;
  for (std::uint32_t k = r.begin; k < r.end; ++k) {
    plo = plo.cwiseMin(p.pos[k]);
    phi = phi.cwiseMax(p.pos[k]);
    p.oct[k] = octant(p.pos[k], mid);
    ++start[p.oct[k] + 1u];
  }
  if (plo == phi) return false;
  for (int o8 = 0; o8 < 8; ++o8) start[o8 + 1] += start[o8];
  std::array<std::uint32_t, 8> at{};
  for (int o8 = 0; o8 < 8; ++o8) at[o8] = r.begin + start[o8];
  for (std::uint32_t k = r.begin; k < r.end; ++k) move_to_scratch(p, k, at[p.oct[k]]++);
  copy_back(p, r.begin, r.end);
  return true;
}

/// partition_serial() in contiguous chunks on up to `threads` threads: chunk c's points of
/// octant o go after those of chunks before c, which is the serial (stable) order.
bool partition_parallel(octree_points& p, build_node r, const vec3d& mid, unsigned threads,
                        std::array<std::uint32_t, 9>& start) {
  const std::size_t m = r.end - r.begin,
                    chunks = std::min<std::size_t>(m, 4 * std::size_t{threads});
  std::vector<std::array<std::uint32_t, 8>> at(chunks);
  std::vector<std::array<vec3d, 2>> box(chunks);
  parallel_tasks(chunks, threads, [&](std::size_t c, unsigned) {
    const auto [lo, hi] = piece_range(m, chunks, c);
    at[c] = {};
    box[c] = {p.pos[r.begin + lo], p.pos[r.begin + lo]};
    for (std::size_t k = r.begin + lo; k < r.begin + hi; ++k) {
      box[c][0] = box[c][0].cwiseMin(p.pos[k]);
      box[c][1] = box[c][1].cwiseMax(p.pos[k]);
      p.oct[k] = octant(p.pos[k], mid);
      ++at[c][p.oct[k]];
    }
  });
  bool same = true;
  for (const auto& b : box) same = same && b[0] == box[0][0] && b[1] == box[0][0];
  if (same) return false;
  start = {};
  for (const auto& a : at)
    for (int o8 = 0; o8 < 8; ++o8) start[o8 + 1] += a[o8];
  for (int o8 = 0; o8 < 8; ++o8) start[o8 + 1] += start[o8];
  std::array<std::uint32_t, 8> next{};
  for (int o8 = 0; o8 < 8; ++o8) next[o8] = r.begin + start[o8];
  for (auto& a : at)  // counts → where each chunk's points of each octant go
    for (int o8 = 0; o8 < 8; ++o8) {
      const std::uint32_t count = a[o8];
      a[o8] = next[o8];
      next[o8] += count;
    }
  parallel_tasks(chunks, threads, [&](std::size_t c, unsigned) {
    const auto [lo, hi] = piece_range(m, chunks, c);
    for (std::size_t k = r.begin + lo; k < r.begin + hi; ++k)
      move_to_scratch(p, static_cast<std::uint32_t>(k), at[c][p.oct[k]]++);
  });
  parallel_tasks(chunks, threads, [&](std::size_t c, unsigned) {
    const auto [lo, hi] = piece_range(m, chunks, c);
    copy_back(p, r.begin + lo, r.begin + hi);
  });
  return true;
}

/// Whether the normals of a node's points all lie within surface_angle of the first one (§6's
/// "normal-coherent part") and their colours within colour_tolerance of its colour: if not, the
/// node holds two surfaces, a crease or a colour edge and is split on.
bool one_surface(const octree_points& p, build_node r) {
  const vec3f& n0 = p.normals[p.index[r.begin]];
  for (std::uint32_t k = r.begin + 1; k < r.end; ++k)
    if (p.normals[p.index[k]].dot(n0) < p.surface_cos) return false;
  if (p.colours.empty()) return true;
  const rgb8 c0 = p.colours[p.index[r.begin]];
  for (std::uint32_t k = r.begin + 1; k < r.end; ++k) {
    const rgb8 c = p.colours[p.index[k]];
    const float dr = float(c.r) - float(c0.r), dg = float(c.g) - float(c0.g),
                db = float(c.b) - float(c0.b);
    if (dr * dr + dg * dg + db * db > p.colour_tol2) return false;
  }
  return true;
}

/// Splits node `i` of `part` at its cell centre (§3) unless it holds at most leaf_size points,
/// reaches max_depth or holds one position only; appends its children to `part` in octant order.
/// Touches only the node's own range of the points, so disjoint nodes split concurrently; a
/// large node's points are partitioned on `threads` threads.
void split_node(octree_points& p, std::vector<part_node>& part, std::size_t i, unsigned threads) {
  const build_node r = part[i].range;
  const std::uint8_t depth = part[i].depth;
  if (depth >= p.max_depth) return;
  if (r.end - r.begin <= p.leaf_size && one_surface(p, r)) return;
  const double half = p.cube_size / std::ldexp(1.0, depth + 1);
  const vec3d cmin = part[i].cell_min, mid = cmin + vec3d::Constant(half);
  std::array<std::uint32_t, 9> start{};
  const bool split = threads > 1 && r.end - r.begin >= (1u << 16)
                         ? partition_parallel(p, r, mid, threads, start)
                         : partition_serial(p, r, mid, start);
  if (!split) return;  // all points identical: no split separates them
  part[i].first = static_cast<std::uint32_t>(part.size());
  for (unsigned o8 = 0; o8 < 8; ++o8) {
    if (start[o8 + 1] == start[o8]) continue;
    part[i].mask = static_cast<std::uint8_t>(part[i].mask | (1u << o8));
    ++part[i].count;
    part.push_back({{r.begin + start[o8], r.begin + start[o8 + 1]},
                    cmin + vec3d((o8 & 1) ? half : 0, (o8 & 2) ? half : 0, (o8 & 4) ? half : 0),
                    0,
                    0,
                    0,
                    static_cast<std::uint8_t>(depth + 1)});
  }
}

/// Appends the subtrees of `parts` (each a subtree in breadth-first order, parts[s][0] the
/// frontier node top[frontier + s]) to the tree `top` in breadth-first order. A level of the whole
/// tree is the concatenation of the parts' nodes at that level, in part order, because the frontier
/// is one whole level: this is the order of the one-part build.
void merge_parts(std::vector<part_node>& top, std::size_t frontier,
                 const std::vector<std::vector<part_node>>& parts) {
  std::size_t levels = 0;
  for (const auto& part : parts) levels = std::max<std::size_t>(levels, part.back().depth);
  const std::size_t d0 = top[frontier].depth, span = levels - d0 + 1;
  // local[s][l]: where level d0 + l starts in part s (breadth first: levels are contiguous);
  // global[s][l]: where it goes in the whole tree.
  std::vector<std::vector<std::size_t>> local(parts.size(), std::vector<std::size_t>(span + 1));
  std::vector<std::vector<std::size_t>> global(parts.size(), std::vector<std::size_t>(span));
  for (std::size_t s = 0; s < parts.size(); ++s) {
    for (const auto& nd : parts[s]) ++local[s][nd.depth - d0 + 1];
    for (std::size_t l = 0; l < span; ++l) local[s][l + 1] += local[s][l];
  }
  std::size_t next = top.size();
  for (std::size_t l = 1; l < span; ++l)
    for (std::size_t s = 0; s < parts.size(); ++s) {
      global[s][l] = next;
      next += local[s][l + 1] - local[s][l];
    }
  const auto where = [&](std::size_t s, std::size_t j) -> std::uint32_t {
    if (j == 0) return static_cast<std::uint32_t>(frontier + s);
    const std::size_t l = parts[s][j].depth - d0;
    return static_cast<std::uint32_t>(global[s][l] + j - local[s][l]);
  };
  top.resize(next);
  for (std::size_t s = 0; s < parts.size(); ++s)
    for (std::size_t j = 0; j < parts[s].size(); ++j) {
      part_node nd = parts[s][j];
      if (nd.count > 0) nd.first = where(s, nd.first);
      top[where(s, j)] = nd;
    }
}

/// §3's octree: breadth first until a whole level holds enough nodes to share among threads,
/// then each of that level's subtrees on its own (the points of different subtrees are
/// disjoint ranges), merged back into breadth-first order. The tree and the order of the
/// points do not depend on the number of threads. Returns each node's range of points.
std::vector<build_node> build_octree(octree_points& p, pca_data& d, std::uint8_t root_depth,
                                     unsigned threads) {
  constexpr std::size_t frontier_nodes = 256;
  std::vector<part_node> top{
      {{0, static_cast<std::uint32_t>(p.pos.size())}, d.cube_min, 0, 0, 0, root_depth}};
  std::size_t level = 0;  // first node of the level being split
  while (level < top.size() && top.size() - level < frontier_nodes) {
    const std::size_t end = top.size();
    for (std::size_t i = level; i < end; ++i) split_node(p, top, i, threads);
    level = end;
  }
  if (level < top.size()) {
    std::vector<std::vector<part_node>> parts(top.size() - level);
    parallel_tasks(parts.size(), threads, [&](std::size_t s, unsigned) {
      auto& part = parts[s];
      part.push_back(top[level + s]);
      for (std::size_t i = 0; i < part.size(); ++i) split_node(p, part, i, 1);
    });
    merge_parts(top, level, parts);
  }
  d.nodes.assign(top.size(), pca_node{});
  std::vector<build_node> ranges(top.size());
  for (std::size_t i = 0; i < top.size(); ++i) {
    d.nodes[i].first = top[i].first;
    d.nodes[i].count = top[i].count;
    d.nodes[i].mask = top[i].mask;
    d.nodes[i].depth = top[i].depth;
    ranges[i] = top[i].range;
  }
  return ranges;
}

/// §3: the PCA of every node's positions, normals and colours. The normals need each node's
/// own frame (the unwrap is about its mean normal), so every node visits its points; the
/// positions' and colours' moments are summed at the leaves and merged up the tree level by
/// level (Chan et al.'s update, core/covariance.hpp), so each point is summed once.
pca_subtree_moments node_statistics(pca_data& d, const std::vector<build_node>& ranges,
                                    const pca_points& pts, std::uint32_t leaf_size,
                                    unsigned threads, double root_parent_spacing) {
  const std::vector<vec3d>& pos = pts.pos;
  const std::vector<vec3f>& normals = pts.normals;
  const std::vector<rgb8>& cols = pts.colours;
  const bool splats = !pts.axis_u.empty();
  const std::size_t n = d.nodes.size();
  // A leaf of one or two points takes the spacing of its parent's points: its cell edge over
  // the square root of their count. A parent of at most leaf_size points was split for its
  // normals or colours (two surfaces, a crease, a colour edge), not for its count, and its few
  // points say nothing of their spacing: its children take its own parent's.
  std::vector<double> parent_spacing(n, root_parent_spacing);
  for (std::size_t i = 0; i < n; ++i) {
    const std::uint32_t k = ranges[i].end - ranges[i].begin;
    const double s = k > leaf_size ? d.nodes[i].cell_size / std::sqrt(static_cast<double>(k))
                                   : parent_spacing[i];
    for (std::uint32_t c = d.nodes[i].first; c < d.nodes[i].first + d.nodes[i].count; ++c)
      parent_spacing[c] = s;
  }
  const bool colour = !cols.empty();
  if (colour) d.colours.resize(n);
  std::vector<double> leaf_h(n, 0);               // the spacing each leaf's extents were widened by
  std::vector<vec3f> for_parent(splats ? n : 0);  // a leaf's extents without its points' patches
  // The normals first: their mean is what the degenerate position rules align z with. If they
  // cancel out, the first sample's normal stands in (deterministic).
  std::vector<pca_normal_result> normal(n);
  const std::size_t pieces = std::min<std::size_t>(n, 64 * threads);
  parallel_tasks(pieces, threads, [&](std::size_t t, unsigned) {
    const auto [lo_n, hi_n] = piece_range(n, pieces, t);
    for (std::size_t i = lo_n; i < hi_n; ++i) {
      const build_node r = ranges[i];
      normal[i] =
          pca_normals(normals.data() + r.begin, r.end - r.begin, normals[r.begin].cast<double>());
    }
  });
  // Breadth first: each level is a contiguous range, its children all in the next one, so the
  // moments of two levels at a time suffice.
  std::vector<std::size_t> level{0};
  for (std::size_t i = 1; i < n; ++i)
    if (d.nodes[i].depth != d.nodes[i - 1].depth) level.push_back(i);
  level.push_back(n);
  std::vector<scatter_accumulator> below, here, colour_below, colour_here;
  for (std::size_t l = level.size() - 1; l-- > 0;) {
    const std::size_t b = level[l], e = level[l + 1];
    here.assign(e - b, {});
    if (colour) colour_here.assign(e - b, {});
    parallel_pieces(e - b, threads, 16 * threads, 256, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = b + lo; i < b + hi; ++i) {
        pca_node& nd = d.nodes[i];
        scatter_accumulator& mp = here[i - b];
        const build_node r = ranges[i];
        if (nd.count == 0) {
          mp = position_moments(pos.data() + r.begin, r.end - r.begin);
          if (colour) colour_here[i - b] = colour_moments(cols.data() + r.begin, r.end - r.begin);
        }
        for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c) {
          mp += below[c - e];
          if (colour) colour_here[i - b] += colour_below[c - e];
        }
        pca_set_statistics(nd, mp, normal[i]);
        if (colour)
          d.colours[i] = pca_colours_from(colour_here[i - b].mean, colour_here[i - b].covariance());
        if (nd.count == 0) {
          leaf_h[i] = pca_leaf_extents(
              nd, colour ? &d.colours[i] : nullptr, pos.data() + r.begin, normals.data() + r.begin,
              colour ? cols.data() + r.begin : nullptr, r.end - r.begin, parent_spacing[i],
              splats ? pts.axis_u.data() + r.begin : nullptr,
              splats ? pts.axis_v.data() + r.begin : nullptr, splats ? &for_parent[i] : nullptr);
          continue;
        }
        // The node's span first, from its children as their points left them: a widened leaf
        // overhangs its points by up to a spacing, and that overhang must not grow every
        // ancestor's span (the points generated there would leave the surface).
        // With patches, the span of the leaves' points, not of their patches.
        pca_inner_extents(d, i, for_parent);
        // The leaves below a node of a surface cover their points' patches in every tangential
        // direction; below a line of points (or one point) they stay on it.
        if (nd.sigma.y() > 2 * sigma_floor)
          for (std::uint32_t c = nd.first; c < nd.first + nd.count; ++c)
            if (d.nodes[c].count == 0) pca_widen_leaf(d.nodes[c], leaf_h[c], nd.frame);
      }
    });
    std::swap(below, here);
    std::swap(colour_below, colour_here);
  }
  return {below[0], colour ? colour_below[0] : scatter_accumulator{},
          d.nodes[0].count == 0 ? leaf_h[0] : 0.0};
}

}  // namespace

void pca_set_statistics(pca_node& nd, const scatter_accumulator& positions,
                        const pca_normal_result& normals) {
  nd.normal_frame = normals.frame.cast<float>();
  nd.normal_sigma = normals.sigma.cast<float>();
  const pca_position_result pp =
      pca_positions_from(positions.mean, positions.covariance(), normals.frame.col(2));
  nd.mean = pp.mean.cast<float>();
  nd.frame = pp.frame.cast<float>();
  nd.sigma = pp.sigma.cast<float>().cwiseMax(static_cast<float>(sigma_floor));
}

pca_subtree_moments pca_build_subtree(pca_data& d, pca_points& pts, const vec3d& cell_min,
                                      std::uint8_t depth, double root_size,
                                      const pca_octree_options& o, unsigned threads,
                                      double root_parent_spacing) {
  d.cube_min = cell_min;
  d.cube_size = root_size / std::ldexp(1.0, depth);
  const auto surface_cos =
      static_cast<float>(std::cos(static_cast<double>(o.surface_angle) * std::numbers::pi / 180));
  const float colour_tol = 255 * std::min(o.colour_tolerance, 2.0f);
  octree_points p{pts.pos,     root_size,   o.leaf_size, o.max_depth,
                  pts.normals, surface_cos, pts.colours, colour_tol * colour_tol};
  const std::vector<build_node> ranges = build_octree(p, d, depth, threads);
  pts.normals = permute_by(pts.normals, p.index, threads);
  pts.colours = permute_by(pts.colours, p.index, threads);
  pts.axis_u = permute_by(pts.axis_u, p.index, threads);
  pts.axis_v = permute_by(pts.axis_v, p.index, threads);
  pca_derive_cells(d, threads);    // a leaf of one point takes its spacing from its cell
  if (!(root_parent_spacing > 0))  // the whole tree's root: its own cell and points
    root_parent_spacing = d.cube_size / std::sqrt(static_cast<double>(pts.pos.size()));
  return node_statistics(d, ranges, pts, o.leaf_size, threads, root_parent_spacing);
}

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
    normals = estimate_normals(in.positions, o.knn, true, threads);
    st.estimation_seconds = seconds_since(te);
    st.estimated_normals = true;
  } else {
    normals.resize(n);
    parallel_chunks(n, threads, 1u << 16, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = lo; i < hi; ++i)
        normals[i] =
            missing_normal(in.normals[i]) ? vec3f::Zero() : vec3f(in.normals[i].normalized());
    });
    // A zero or non-finite normal is no normal (3DGS files store zeros): estimated from the
    // positions, oriented by the given normals around it.
    const auto te = clock_type::now();
    const normal_repair r = fill_missing_normals(in.positions, normals, o.knn, threads);
    st.normals_filled = r.missing;
    st.estimated_normals = r.all_estimated;
    if (r.missing > 0) st.estimation_seconds = seconds_since(te);
  }
  check_progress(o, 0.2);
  const auto tt = clock_type::now();

  // A double origin at the centre of the data's box; positions relative to it in double.
  // (Minima and maxima do not depend on the order of the chunks.)
  constexpr std::size_t chunks = 64;
  std::vector<std::array<vec3d, 2>> box(chunks);
  parallel_tasks(chunks, threads, [&](std::size_t c, unsigned) {
    const auto [b, e] = piece_range(n, chunks, c);
    vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
    for (std::size_t i = b; i < e; ++i) {
      lo = lo.cwiseMin(in.positions[i].cast<double>());
      hi = hi.cwiseMax(in.positions[i].cast<double>());
    }
    box[c] = {lo, hi};
  });
  vec3d lo = box[0][0], hi = box[0][1];
  for (const auto& b : box) {
    lo = lo.cwiseMin(b[0]);
    hi = hi.cwiseMax(b[1]);
  }
  const vec3d centre_rel = 0.5 * (lo + hi);
  d.origin = in.origin + centre_rel;
  std::vector<vec3d> pos(n);
  std::vector<double> radius(chunks, 0.0);
  parallel_tasks(chunks, threads, [&](std::size_t c, unsigned) {
    const auto [b, e] = piece_range(n, chunks, c);
    for (std::size_t i = b; i < e; ++i) {
      pos[i] = in.positions[i].cast<double>() - centre_rel;
      radius[c] = std::max(radius[c], pos[i].norm());
    }
  });
  d.input_radius = *std::max_element(radius.begin(), radius.end());
  // The root cell: a cube about the box, enlarged by a hair so that no point lies on its far
  // faces after rounding.
  double size = (hi - lo).maxCoeff();
  size = size > 0 ? size * (1 + 1e-9) : 1e-9 * std::max(1.0, in.origin.cwiseAbs().maxCoeff());
  d.cube_size = size;
  d.cube_min = vec3d::Constant(-0.5 * size);

  // ---- §3: top-down octree, breadth first, children contiguous in octant order; the
  // independent PCA of each node's positions, normals and colours.
  pca_points pts{std::move(pos), std::move(normals),
                 std::vector<rgb8>(in.colours.begin(), in.colours.end()),
                 std::vector<vec3f>(in.axis_u.begin(), in.axis_u.end()),
                 std::vector<vec3f>(in.axis_v.begin(), in.axis_v.end())};
  (void)pca_build_subtree(d, pts, vec3d::Constant(-0.5 * size), 0, size, o, threads);
  for (const auto& nd : d.nodes) st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  st.nodes = d.nodes.size();
  for (const auto& nd : d.nodes) st.leaves += nd.count == 0 ? 1 : 0;
  check_progress(o, 0.35);
  st.tree_seconds = seconds_since(tt);
  check_progress(o, 0.6);

  // ---- §3.1: classification and quantisation (the hierarchy then holds the decoded values).
  if (o.quantise) pca_quantise(d, o, threads);
  pca_derive_bounds(d, threads);
  check_progress(o, 1);
  st.seconds = seconds_since(t0);
  st.has_timings = true;
  return d;
}

// ---------------------------------------------------------------------------------------------
// Derived data (build and load).
// ---------------------------------------------------------------------------------------------
namespace {
/// Where each level of the breadth-first tree starts (and, last, the node count): a level's
/// children are the next level, in order.
std::vector<std::size_t> tree_levels(const pca_data& d) {
  std::vector<std::size_t> at{0, 1};
  while (at.back() < d.nodes.size()) {
    std::size_t kids = 0;
    for (std::size_t i = at[at.size() - 2]; i < at.back(); ++i) kids += d.nodes[i].count;
    if (kids == 0) break;
    at.push_back(std::min(d.nodes.size(), at.back() + kids));
  }
  return at;
}
}  // namespace

void pca_derive_cells(pca_data& d, unsigned threads) {
  if (d.nodes.empty()) return;
  d.nodes[0].cell_min = d.cube_min;
  d.nodes[0].cell_size = d.cube_size;
  const std::vector<std::size_t> level = tree_levels(d);
  for (std::size_t l = 0; l + 1 < level.size(); ++l) {
    parallel_pieces(
        level[l + 1] - level[l], threads, 8 * threads, 4096, [&](std::size_t lo, std::size_t hi) {
          for (std::size_t i = level[l] + lo; i < level[l] + hi; ++i) {
            const pca_node& nd = d.nodes[i];
            if (nd.count == 0) continue;
            const double half = 0.5 * nd.cell_size;
            std::uint32_t c = nd.first;
            for (unsigned o8 = 0; o8 < 8; ++o8) {
              if (!(nd.mask & (1u << o8))) continue;
              pca_node& ch = d.nodes[c++];
              ch.cell_min = nd.cell_min +
                            vec3d((o8 & 1) ? half : 0, (o8 & 2) ? half : 0, (o8 & 4) ? half : 0);
              ch.cell_size = half;
              ch.depth = static_cast<std::uint8_t>(nd.depth + 1);
            }
          }
        });
  }
}

namespace {
/// λ, the bounding sphere and the normal cone of node i, from its statistics and its children's
/// bounds (pca_derive_bounds).
void derive_node_bounds(pca_data& d, std::size_t i) {
  const float pi = std::numbers::pi_v<float>;
  pca_node& nd = d.nodes[i];
  // §3: λ = c·√(σ_n¹/‖σ_p‖), ‖σ_p‖ in units of the root's (see pca_octree_options).
  float lambda = 1;
  if (d.curvature_c > 0) {
    const float rel = nd.sigma.norm() / d.lambda_norm;
    const float l = d.curvature_c * std::sqrt(nd.normal_sigma.x() / std::max(rel, 1e-30f));
    lambda = std::clamp(std::isfinite(l) ? l : d.lambda_max, 1.0f, d.lambda_max);
  }
  nd.lambda = lambda;
  // Generated positions lie in the span box (half-extents `extent` along f_p), normals within
  // normal_extent of the mean normal. Children's bounds are added so that the sphere and the
  // cone hold everything the subtree generates.
  float r = nd.extent.norm();
  float cone = std::min(pi, nd.normal_extent);
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
}  // namespace

void pca_derive_bounds(pca_data& d, unsigned threads) {
  if (d.nodes.empty()) return;
  const float root_norm = d.nodes[0].sigma.norm();
  pca_derive_bounds_with(d, root_norm > 0 ? root_norm : 1.0f, threads);
}

void pca_derive_bounds_with(pca_data& d, float lambda_norm, unsigned threads,
                            const std::vector<char>* fixed) {
  d.lambda_norm = lambda_norm;
  if (d.nodes.empty()) return;
  const std::vector<std::size_t> level = tree_levels(d);
  for (std::size_t l = level.size() - 1; l-- > 0;)
    parallel_pieces(level[l + 1] - level[l], threads, 8 * threads, 4096,
                    [&](std::size_t lo, std::size_t hi) {
                      for (std::size_t i = level[l] + lo; i < level[l] + hi; ++i)
                        if (fixed == nullptr || !(*fixed)[i]) derive_node_bounds(d, i);
                    });
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
