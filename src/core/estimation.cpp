// pbr_lod — k-NN normals (Hoppe et al. 1992, §3; PCA + MST orientation) and splat ellipses
// (Pajarola 2003, end of §4: the bounding-ellipse rule of Fig. 5/6a applied to the k nearest
// neighbours of each input sample). Its own object library (src/core/estimation.cmake) for the
// TBB and Boost usage requirements.
//
// Every call works on a copy of the positions sorted along a Morton curve (knn.hpp): the k-NN
// queries, the PCA gathers, the MST's edge lists and the ellipse fits then touch neighbours that
// sit next to each other in memory. Results are scattered back to the caller's order at the end.
#include "pbr_lod/core/estimation.hpp"

#include <boost/pending/disjoint_sets.hpp>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <numbers>
#include <numeric>
#include <string>
#include <thread>
#include <tuple>
#include <utility>

#include "moment_ellipse.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/grid_knn.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {

namespace {

// Points per piece of parallel work (a k-NN query is about a µs): long enough to amortise the
// hand-out, many pieces per thread so that a slow core does not hold the others up.
constexpr std::size_t grain = 2048;

void check_positions(std::span<const vec3f> positions, const char* who) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!all_finite(positions[i]))
      throw InvalidArgument(std::string(who) + ": position " + std::to_string(i) +
                            " is not finite");
}

/// Runs body(begin, end) over [0, n) on up to `threads` threads. Each index is written by
/// exactly one call, so results do not depend on how the range is split.
template <class Body>
void parallel_over(std::size_t n, unsigned threads, const Body& body) {
  detail::parallel_pieces(n, threads, 4 * std::size_t(threads), grain, body);
}

/// The distinct positions sorted along a Morton curve, and the way back to the caller's points.
///
/// Exact duplicates (the same position bits; with `normals`, the same normal bits too) are
/// estimated once: a copy adds nothing to a neighbourhood's shape, and a point with thousands of
/// copies made every k-NN query around it visit them all — the fallback search for a duplicate's
/// nearest distinct neighbour (up to 4096 neighbours) made 2,000 copies of a grid take minutes.
/// Every copy gets its representative's normal and ellipse.
struct sorted_points {
  std::vector<std::uint32_t> order;  // order[r] = caller's index of the representative of rank r
  std::vector<vec3f> pos;            // pos[r] = positions[order[r]], all distinct
  std::vector<std::uint32_t> rank;   // rank[i] = the rank of caller's point i's representative
};

/// A point's identity for duplicate collapsing: its position's bits, then its normal's.
using point_key = std::array<std::uint32_t, 6>;

point_key key_of(const vec3f& p, const vec3f* n) {
  point_key k{};
  std::memcpy(k.data(), p.data(), 3 * sizeof(float));
  if (n) std::memcpy(k.data() + 3, n->data(), 3 * sizeof(float));
  return k;
}

sorted_points sort_points(std::span<const vec3f> positions, std::span<const vec3f> normals = {}) {
  const std::size_t n = positions.size();
  // Group exact duplicates; the representative of a group is its first point.
  std::vector<std::uint32_t> by_key(n);
  std::iota(by_key.begin(), by_key.end(), 0u);
  const auto key = [&](std::uint32_t i) {
    return key_of(positions[i], normals.empty() ? nullptr : &normals[i]);
  };
  std::stable_sort(by_key.begin(), by_key.end(),
                   [&](std::uint32_t a, std::uint32_t b) { return key(a) < key(b); });
  std::vector<std::uint32_t> rep(n);  // caller's index of each point's representative
  std::vector<std::uint32_t> reps;
  for (std::size_t t = 0; t < n; ++t) {
    const std::uint32_t i = by_key[t];
    if (t > 0 && key(i) == key(by_key[t - 1])) {
      rep[i] = rep[by_key[t - 1]];
    } else {
      rep[i] = i;
      reps.push_back(i);
    }
  }
  std::sort(reps.begin(), reps.end());  // caller's order: without duplicates, as before
  std::vector<vec3f> distinct(reps.size());
  for (std::size_t u = 0; u < reps.size(); ++u) distinct[u] = positions[reps[u]];
  sorted_points s;
  const std::vector<std::uint32_t> morton = morton_order(distinct);
  s.order.resize(reps.size());
  s.pos.resize(reps.size());
  std::vector<std::uint32_t> rank_of_rep(n, 0);
  for (std::size_t r = 0; r < reps.size(); ++r) {
    s.order[r] = reps[morton[r]];
    s.pos[r] = positions[s.order[r]];
    rank_of_rep[s.order[r]] = static_cast<std::uint32_t>(r);
  }
  s.rank.resize(n);
  for (std::size_t i = 0; i < n; ++i) s.rank[i] = rank_of_rep[rep[i]];
  return s;
}

/// out[i] = in[rank[i]]: each of the caller's points gets its representative's value.
std::vector<vec3f> unsort(const std::vector<vec3f>& in, const sorted_points& s) {
  std::vector<vec3f> out(s.rank.size());
  for (std::size_t i = 0; i < s.rank.size(); ++i) out[i] = in[s.rank[i]];
  return out;
}

/// A unit vector orthogonal to unit n, in double (math.hpp's any_orthogonal is float).
vec3d orthogonal(const vec3d& n) {
  const vec3d a = n.cwiseAbs();
  const vec3d axis = (a.x() <= a.y() && a.x() <= a.z()) ? vec3d::UnitX()
                     : (a.y() <= a.z())                 ? vec3d::UnitY()
                                                        : vec3d::UnitZ();
  return n.cross(axis).normalized();
}

/// Flips n so that its largest-magnitude component is positive (first of equals wins).
vec3d canonical_sign(const vec3d& n) {
  int m = 0;
  for (int c = 1; c < 3; ++c)
    if (std::abs(n[c]) > std::abs(n[m])) m = c;
  return n[m] < 0 ? vec3d(-n) : n;
}

/// PCA normal of the neighbourhood idx (see estimate_normals for the degenerate cases).
vec3d pca_normal(std::span<const vec3f> pts, std::span<const std::uint32_t> idx) {
  vec3d mean = vec3d::Zero();
  for (const auto j : idx) mean += pts[j].cast<double>();
  mean /= double(idx.size());
  // Two-pass, centred: the one-pass Σppᵀ − n·μμᵀ cancels catastrophically (DEPENDENCIES.md).
  mat3d cov = mat3d::Zero();
  for (const auto j : idx) {
    const vec3d d = pts[j].cast<double>() - mean;
    cov.noalias() += d * d.transpose();
  }
  // The closed-form 3×3 solver is about 3× faster than the iterative one and as accurate for
  // the smallest eigenvector while it is well separated from the middle one (a surface); near
  // ties (a line, a blob, a single position) take the iterative solver.
  Eigen::SelfAdjointEigenSolver<mat3d> es;
  es.computeDirect(cov);
  vec3d lambda = es.eigenvalues();  // ascending
  if (!all_finite(lambda) || !(lambda[1] - lambda[0] > 1e-3 * lambda[2])) {
    es.compute(cov);
    lambda = es.eigenvalues();
  }
  if (es.info() != Eigen::Success || !(lambda[2] > 0) || !all_finite(lambda))
    return vec3d::UnitZ();  // one position (duplicates, single point)
  vec3d n = lambda[1] <= 1e-12 * lambda[2] ? orthogonal(es.eigenvectors().col(2).normalized())
                                           : vec3d(es.eigenvectors().col(0));
  n.normalize();
  return all_finite(n) ? canonical_sign(n) : vec3d::UnitZ();
}

/// The k nearest neighbours of every position (itself included), k per row, from one FLANN index
/// queried in parallel in the order of the (Morton-sorted) positions, each query writing into
/// its row. k ≤ #P, so every row is full.
std::vector<std::uint32_t> knn_table(std::span<const vec3f> positions, const knn_index& index,
                                     int k, unsigned threads) {
  const std::size_t n = positions.size(), kk = static_cast<std::size_t>(k);
  std::vector<std::uint32_t> table(n * kk);
  parallel_over(n, threads, [&](std::size_t begin, std::size_t end) {
    std::vector<float> d2(kk);
    for (std::size_t i = begin; i < end; ++i)
      index.query(positions[i], kk, &table[i * kk], d2.data());
  });
  return table;
}

/// Cost classes of the MST's edges: 1 − |nᵢ·nⱼ| ≈ θ²/2 for an angle θ between the normals, so
/// √cost is about proportional to θ and 256 classes of √cost are 0.35° wide.
constexpr std::size_t cost_classes = 256;

std::size_t cost_class(const vec3f& a, const vec3f& b) {
  const float cost = std::max(0.0f, 1.0f - std::abs(a.dot(b)));
  return std::min(cost_classes - 1, static_cast<std::size_t>(std::sqrt(cost) * cost_classes));
}

/// Edges of the undirected k-NN graph, each {i, t} once (from the smaller index, or from i when
/// t's row does not list i), ordered by cost class, then by row and slot (a stable counting
/// sort). Within a class the edges keep the Morton order of their rows, so Kruskal's union-find
/// walks memory in order instead of jumping across the whole cloud with every edge.
std::vector<std::pair<std::uint32_t, std::uint32_t>> sorted_edges(
    const std::vector<vec3f>& normals, const std::vector<std::uint32_t>& table, std::size_t stride,
    std::size_t kk, unsigned threads) {
  const std::size_t n = normals.size();
  const auto lists = [&](std::uint32_t t, std::uint32_t i) {
    const auto row = std::span(table).subspan(t * stride, kk);
    return std::find(row.begin(), row.end(), i) != row.end();
  };
  const auto keep = [&](std::size_t i, std::uint32_t t) {
    return t != i && (i < t || !lists(t, static_cast<std::uint32_t>(i)));
  };
  // Per piece of rows a histogram of classes; a piece's edges of class c go after those of the
  // earlier classes and of class c in the earlier pieces.
  const std::size_t pieces = detail::piece_count(n, threads, 4 * std::size_t(threads), grain);
  std::vector<std::size_t> count(pieces * cost_classes, 0);
  detail::parallel_tasks(pieces, threads, [&](std::size_t p, unsigned) {
    const auto [lo, hi] = detail::piece_range(n, pieces, p);
    for (std::size_t i = lo; i < hi; ++i)
      for (std::size_t j = 0; j < kk; ++j) {
        const std::uint32_t t = table[i * stride + j];
        if (keep(i, t)) ++count[p * cost_classes + cost_class(normals[i], normals[t])];
      }
  });
  std::size_t total = 0;
  for (std::size_t c = 0; c < cost_classes; ++c)
    for (std::size_t p = 0; p < pieces; ++p) {
      const std::size_t k = count[p * cost_classes + c];
      count[p * cost_classes + c] = total;
      total += k;
    }
  std::vector<std::pair<std::uint32_t, std::uint32_t>> edges(total);
  detail::parallel_tasks(pieces, threads, [&](std::size_t p, unsigned) {
    const auto [lo, hi] = detail::piece_range(n, pieces, p);
    std::size_t* at = &count[p * cost_classes];
    for (std::size_t i = lo; i < hi; ++i)
      for (std::size_t j = 0; j < kk; ++j) {
        const std::uint32_t t = table[i * stride + j];
        if (keep(i, t))
          edges[at[cost_class(normals[i], normals[t])]++] = {static_cast<std::uint32_t>(i), t};
      }
  });
  return edges;
}

/// Makes the signs of `normals` consistent (Hoppe et al. 1992, §3.3): a spanning forest of the
/// k-NN ("Riemannian") graph of minimum cost 1 − |nᵢ·nⱼ| up to 0.35° classes (Kruskal over
/// sorted_edges with Boost's union-find); in every connected component the sample with the
/// largest z gets a normal with z ≥ 0 and the sign is propagated along the tree, flipping a child
/// whose normal points against its parent's. This is CGAL::mst_orient_normals' rule, but on the
/// k-NN table the PCA pass already computed (CGAL re-searches every neighbourhood with its own
/// sequential k-d tree), with classes of cost instead of exact costs (an edge is only a path for
/// the sign; docs/estimation.md measures the flips), and every component is oriented where CGAL
/// orients only the top sample's.
void mst_orient(std::span<const vec3f> pts, std::vector<vec3f>& normals,
                const std::vector<std::uint32_t>& table, int stride_k, int k, unsigned threads) {
  const std::size_t n = pts.size(), stride = static_cast<std::size_t>(stride_k),
                    kk = static_cast<std::size_t>(k);
  auto edges = sorted_edges(normals, table, stride, kk, threads);
  std::vector<std::uint32_t> rank(n), parent(n);
  boost::disjoint_sets<std::uint32_t*, std::uint32_t*> sets(rank.data(), parent.data());
  for (std::uint32_t i = 0; i < n; ++i) sets.make_set(i);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> tree;
  tree.reserve(n);
  for (const auto& [a, b] : edges) {
    const std::uint32_t ra = sets.find_set(a), rb = sets.find_set(b);
    if (ra == rb) continue;
    sets.link(ra, rb);
    tree.emplace_back(a, b);
    if (tree.size() + 1 == n) break;
  }
  edges = {};

  // The forest as adjacency lists (CSR), then one traversal per component from its top sample.
  std::vector<std::uint32_t> degree(n + 1, 0), adj(2 * tree.size());
  for (const auto& [a, b] : tree) {
    ++degree[a + 1];
    ++degree[b + 1];
  }
  for (std::size_t i = 0; i < n; ++i) degree[i + 1] += degree[i];
  {
    std::vector<std::uint32_t> fill(degree.begin(), degree.end() - 1);
    for (const auto& [a, b] : tree) {
      adj[fill[a]++] = b;
      adj[fill[b]++] = a;
    }
  }
  // Components, each with its sample of largest z (ties: the lowest index).
  constexpr std::uint32_t none = std::numeric_limits<std::uint32_t>::max();
  std::vector<std::uint32_t> component(n, none), stack;
  std::vector<std::uint32_t> tops;
  for (std::uint32_t s = 0; s < n; ++s) {
    if (component[s] != none) continue;
    const auto c = static_cast<std::uint32_t>(tops.size());
    std::uint32_t top = s;
    component[s] = c;
    stack.push_back(s);
    while (!stack.empty()) {
      const std::uint32_t v = stack.back();
      stack.pop_back();
      if (pts[v].z() > pts[top].z()) top = v;
      for (std::uint32_t e = degree[v]; e < degree[v + 1]; ++e)
        if (component[adj[e]] == none) {
          component[adj[e]] = c;
          stack.push_back(adj[e]);
        }
    }
    tops.push_back(top);
  }
  std::vector<char> seen(n, 0);
  for (const std::uint32_t top : tops) {
    if (normals[top].z() < 0) normals[top] = -normals[top];
    seen[top] = 1;
    stack.push_back(top);
    while (!stack.empty()) {
      const std::uint32_t v = stack.back();
      stack.pop_back();
      for (std::uint32_t e = degree[v]; e < degree[v + 1]; ++e) {
        const std::uint32_t w = adj[e];
        if (seen[w]) continue;
        seen[w] = 1;
        if (normals[w].dot(normals[v]) < 0) normals[w] = -normals[w];
        stack.push_back(w);
      }
    }
  }
}

/// Flips every normal that faces away from the sensor: n·(viewpoint − p) ≥ 0 afterwards
/// (a normal perpendicular to the line of sight keeps its sign).
void orient_towards(std::span<const vec3f> positions, std::vector<vec3f>& normals,
                    const vec3f& viewpoint, unsigned threads) {
  parallel_over(positions.size(), threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      if (normals[i].dot(viewpoint - positions[i]) < 0) normals[i] = -normals[i];
  });
}

int clamp_k(int k, std::size_t n) {
  return static_cast<int>(std::min<std::size_t>(std::size_t(k), n));
}

/// PCA normals from the first kk neighbours of each row of `table` (rows of `stride`), then
/// the MST orientation over the same neighbourhoods.
std::vector<vec3f> normals_from(std::span<const vec3f> positions,
                                const std::vector<std::uint32_t>& table, int stride_k, int kk,
                                const estimation_options& opt, unsigned threads) {
  const std::size_t n = positions.size(), stride = static_cast<std::size_t>(stride_k),
                    kz = static_cast<std::size_t>(kk);
  std::vector<vec3f> normals(n);
  parallel_over(n, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      normals[i] = pca_normal(positions, std::span(table).subspan(i * stride, kz)).cast<float>();
  });
  if (opt.orientation == normal_orientation::mst && n >= 2)
    mst_orient(positions, normals, table, stride_k, kk, threads);
  if (opt.orientation == normal_orientation::viewpoint)
    orient_towards(positions, normals, opt.viewpoint, threads);
  return normals;
}

/// The per-sample bounds of ellipse_rule::local_spacing.
struct spacing_bounds {
  /// local_spacing_reach × ρᵢ, the distance to the farthest of the kk neighbours, but at most
  /// local_spacing_outlier_factor × the median ρⱼ of those neighbours — an isolated sample (an
  /// outlier) has neighbours whose own neighbourhoods are small. A median of 0 (the neighbours
  /// are duplicates) bounds nothing.
  std::vector<float> cap;
  /// Whether ρᵢ exceeds local_spacing_sparse_factor × the median ρ of the whole cloud.
  std::vector<char> sparse;
  /// The median over the cloud of the distance to the disk neighbour (0 when all are 0).
  float median_disk_spacing = 0;
};

/// The n/2-th smallest positive value of v (0 when none is positive); v is reordered.
float median_positive(std::vector<float>& v) {
  const auto end = std::partition(v.begin(), v.end(), [](float x) { return x > 0; });
  if (end == v.begin()) return 0;
  const auto mid = v.begin() + (end - v.begin()) / 2;
  std::nth_element(v.begin(), mid, end);
  return *mid;
}

spacing_bounds spacing_caps(std::span<const vec3f> positions,
                            const std::vector<std::uint32_t>& table, std::size_t stride,
                            std::size_t kk, std::size_t disk_neighbour, unsigned threads) {
  const std::size_t n = positions.size();
  std::vector<float> rho(n), disk(n);
  spacing_bounds out{std::vector<float>(n), std::vector<char>(n, 0), 0};
  parallel_over(n, threads, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      rho[i] = (positions[table[i * stride + kk - 1]] - positions[i]).norm();
      disk[i] = (positions[table[i * stride + disk_neighbour]] - positions[i]).norm();
    }
  });
  std::vector<float> scratch = rho;
  const float sparse_above =
      static_cast<float>(local_spacing_sparse_factor) * median_positive(scratch);
  scratch = std::move(disk);
  out.median_disk_spacing = median_positive(scratch);
  parallel_over(n, threads, [&](std::size_t begin, std::size_t end) {
    std::vector<float> around(kk);
    for (std::size_t i = begin; i < end; ++i) {
      for (std::size_t j = 0; j < kk; ++j) around[j] = rho[table[i * stride + j]];
      const auto mid = around.begin() + static_cast<std::ptrdiff_t>(kk / 2);
      std::nth_element(around.begin(), mid, around.end());
      const auto reach = static_cast<float>(local_spacing_reach * rho[i]);
      out.cap[i] = *mid > 0
                       ? std::min(reach, static_cast<float>(local_spacing_outlier_factor) * *mid)
                       : reach;
      out.sparse[i] = sparse_above > 0 && rho[i] > sparse_above;
    }
  });
  return out;
}

/// Semi-axis lengths (major, minor) of the ellipse along e1, e2 (unit, in the tangent frame)
/// centred at the origin that holds every offset of xy, with the major at most `cap` (the minor
/// grown to keep the neighbours inside, at least splat_min_axis_ratio·major, at most the major).
/// With cap = local_spacing_reach·ρ every neighbour (|q| ≤ ρ) stays inside: the minor needed is
/// at most ρ/√(1 − 1/reach²) ≈ 1.34ρ < cap.
std::pair<double, double> capped_axes(double major, double minor, double cap,
                                      const std::vector<vec2d>& xy, const vec2d& e1,
                                      const vec2d& e2) {
  if (!(major > cap)) return {major, minor};
  double need = 0;
  for (const auto& q : xy) {
    const double x = q.dot(e1) / cap, y = std::abs(q.dot(e2));
    if (x * x < 1) need = std::max(need, y / std::sqrt(1 - x * x));
  }
  return {cap, std::clamp(need * (1 + 1e-5), splat_min_axis_ratio * cap, cap)};
}

/// ellipse_rule::local_spacing at open edges and creases: the ellipse (semi-axes major along
/// e1, minor along e2, centred at the sample) is compressed, direction by direction, until its
/// reach in every tangent direction d is at most the neighbourhood's own reach on the nearer
/// side, min(max_j q_j·d, max_j −q_j·d), plus `margin`. Inside a surface both sides reach about
/// ρ and nothing changes; at an open edge the neighbours lie on one side and the splat no longer
/// sticks out by ρ beyond it (nor beyond a crease, where the other face's neighbours project
/// onto the crease line). The compression along d keeps the reach across d; returns the new
/// (major, minor, e1), minor ≥ splat_min_axis_ratio·major.
constexpr double local_spacing_clip_min_ratio = 0.25;
struct clipped_ellipse {
  double major, minor;
  vec2d e1;
};
clipped_ellipse clip_to_neighbourhood(double major, double minor, const vec2d& e1,
                                      const std::vector<vec2d>& xy, double margin) {
  constexpr int directions = 16;
  // The directions kπ/16 and how far the neighbourhood reaches along each on its nearer side:
  // the same for both passes, so computed once (cos and sin once per process).
  static const std::array<vec2d, directions> dirs = [] {
    std::array<vec2d, directions> d;
    for (int k = 0; k < directions; ++k) {
      const double a = std::numbers::pi * k / directions;
      d[static_cast<std::size_t>(k)] = vec2d(std::cos(a), std::sin(a));
    }
    return d;
  }();
  std::array<double, directions> nearer_reach;
  for (std::size_t k = 0; k < dirs.size(); ++k) {
    double fwd = 0, back = 0;
    for (const auto& q : xy) {
      fwd = std::max(fwd, q.dot(dirs[k]));
      back = std::max(back, -q.dot(dirs[k]));
    }
    nearer_reach[k] = std::min(fwd, back);
  }
  // M: the ellipse's shape matrix (reach along unit d: √(dᵀ M d)).
  const vec2d e2(-e1.y(), e1.x());
  Eigen::Matrix2d m = major * major * e1 * e1.transpose() + minor * minor * e2 * e2.transpose();
  bool changed = false;
  for (int pass = 0; pass < 2; ++pass)
    for (std::size_t k = 0; k < dirs.size(); ++k) {
      const vec2d& d = dirs[k];
      const double allowed = nearer_reach[k] + margin, reach = std::sqrt(d.dot(m * d));
      if (!(reach > allowed * (1 + 1e-9))) continue;
      const Eigen::Matrix2d squeeze =
          Eigen::Matrix2d::Identity() - (1 - allowed / reach) * d * d.transpose();
      m = squeeze * m * squeeze.transpose();
      changed = true;
    }
  if (!changed) return {major, minor, e1};
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(m);  // ascending eigenvalues
  const double l1 = std::max(eig.eigenvalues()(1), 0.0);
  const double l2 = std::max(eig.eigenvalues()(0), 0.0);
  const double big = std::sqrt(l1);
  return {big, std::max(std::sqrt(l2), splat_min_axis_ratio * big),
          vec2d(eig.eigenvectors().col(1))};
}

/// Splat ellipses from the first kk neighbours of each row of `table` (rows of `stride`).
splat_axes ellipses_from(std::span<const vec3f> positions, std::span<const vec3f> normals,
                         const knn_index& index, const std::vector<std::uint32_t>& table,
                         int stride_k, int kk, ellipse_rule rule, unsigned threads) {
  const std::size_t n = positions.size(), stride = static_cast<std::size_t>(stride_k),
                    kz = static_cast<std::size_t>(kk);
  splat_axes out;
  out.u.resize(n);
  out.v.resize(n);

  // Scale of the last-resort disk: the bounding-box half-diagonal of all positions.
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  for (const auto& p : positions) {
    lo = lo.cwiseMin(p.cast<double>());
    hi = hi.cwiseMax(p.cast<double>());
  }
  const double half_diagonal = 0.5 * (hi - lo).norm();

  constexpr double ratio2 = splat_min_axis_ratio * splat_min_axis_ratio;
  constexpr double cover_margin = 1 + 1e-5;
  constexpr int max_fallback_k = 4096;
  const bool bounded = rule == ellipse_rule::local_spacing;
  // The disk of a sample whose neighbourhood is no surface is sized by its 8th nearest
  // neighbour's distance, as the full-detail reference's splat (raster/reference.hpp).
  const std::size_t disk_neighbour = std::min<std::size_t>(8, kz - 1);
  const spacing_bounds bounds =
      bounded ? spacing_caps(positions, table, stride, kz, disk_neighbour, threads)
              : spacing_bounds{};
  // A sparse sample's disk is no larger than a typical sample's: the non-surface disk at the
  // cloud's median d₈.
  const double sparse_radius = non_surface_disk_factor * double(bounds.median_disk_spacing);

  parallel_over(n, threads, [&](std::size_t begin, std::size_t end) {
    std::vector<std::uint32_t> more;
    std::vector<float> d2;
    std::vector<vec2d> xy;
    for (std::size_t i = begin; i < end; ++i) {
      const vec3d p = positions[i].cast<double>();
      const vec3d nrm = normals[i].cast<double>().normalized();
      const vec3d t1 = orthogonal(nrm), t2 = nrm.cross(t1);
      const auto idx = std::span(table).subspan(i * stride, kz);
      // Second moments of the tangent-plane offsets about pᵢ (the splat's centre, not the
      // neighbourhood mean: at a boundary the neighbours lie on one side and must still be
      // covered). No division by the count: only the eigenvalue ratio and f·√λ matter.
      xy.clear();
      detail::moments_2d mom;
      double extent2 = 0, z1 = 0, z2 = 0;
      vec3d sum = vec3d::Zero();
      for (const auto j : idx) {
        const vec3d d = positions[j].cast<double>() - p;
        const vec2d q(d.dot(t1), d.dot(t2));
        xy.push_back(q);
        mom.add(q);
        extent2 += d.squaredNorm();
        const double z = d.dot(nrm);
        z1 += z;
        z2 += z * z;
        sum += d;
      }
      const double l1 = mom.major();
      if (!(l1 > 1e-10 * extent2) || !(l1 > 0)) {
        // Degenerate: every neighbour projects onto pᵢ. A disk reaching the nearest sample
        // that is not at pᵢ, searched among more and more neighbours.
        double radius = 0;
        for (int want = kk;; want = std::min(2 * want, max_fallback_k)) {
          index.query(positions[i], want, more, d2);
          for (const float e : d2)
            if (e > 0) {
              radius = std::sqrt(double(e));
              break;
            }
          if (radius > 0 || want >= max_fallback_k || std::size_t(want) >= n) break;
        }
        if (!(radius > 0)) radius = 1e-6 * half_diagonal;
        if (!(radius > 0)) radius = 1e-6 * std::max(1.0, p.cwiseAbs().maxCoeff());
        out.u[i] = (radius * t1).cast<float>();
        out.v[i] = (radius * t2).cast<float>();
        continue;
      }
      if (bounded && kz >= 3) {
        // Thickness: the neighbourhood's variance along the normal over its total variance
        // (Pauly's surface variation λ₀/(λ₀+λ₁+λ₂) for the PCA normal): 0 on a plane, 1/3 for
        // an isotropic blob. Above the threshold the tangent plane means nothing (a tree
        // crown, a corner), and a sparse sample's neighbourhood (an isolated return, a stray
        // hit on a wall) says little about a surface: a round disk at the reference's
        // spacing, not a plane-fitted ellipse.
        const double m = double(kz);
        const double along = z2 - z1 * z1 / m, total = extent2 - sum.squaredNorm() / m;
        const bool thick = total > 0 && along > local_spacing_max_thickness * total;
        if (thick || bounds.sparse[i]) {
          double radius = std::min<double>(
              bounds.cap[i],
              non_surface_disk_factor * (positions[idx[disk_neighbour]] - positions[i]).norm());
          if (bounds.sparse[i] && sparse_radius > 0) radius = std::min(radius, sparse_radius);
          if (radius > 0) {
            out.u[i] = (radius * t1).cast<float>();
            out.v[i] = (radius * t2).cast<float>();
            continue;
          }
        }
      }
      const detail::moment_ellipse el = detail::covering_ellipse(mom, xy, ratio2);
      const vec2d e1 = el.e1, e2 = el.e2;
      const double l2 = el.l2, f = el.f * cover_margin;
      const vec3d axis1 = e1.x() * t1 + e1.y() * t2, axis2 = e2.x() * t1 + e2.y() * t2;
      auto [major, minor] = std::pair(f * std::sqrt(l1), f * std::sqrt(l2));
      vec3d dir1 = axis1, dir2 = axis2;
      if (bounded) std::tie(major, minor) = capped_axes(major, minor, bounds.cap[i], xy, e1, e2);
      // Clipped at open edges and creases where the neighbours spread in two directions about
      // the sample (second moments λ₂ ≥ 0.25·λ₁): a neighbourhood stretched along a scan line
      // sees the next line on one side only, and clipping it would open gaps between lines.
      if (bounded && mom.minor() >= local_spacing_clip_min_ratio * l1) {
        const double margin = local_spacing_edge_margin *
                              (positions[idx[disk_neighbour]] - positions[i]).cast<double>().norm();
        const auto clip = clip_to_neighbourhood(major, minor, e1, xy, margin);
        major = clip.major;
        minor = clip.minor;
        dir1 = clip.e1.x() * t1 + clip.e1.y() * t2;
        dir2 = nrm.cross(dir1);
      }
      out.u[i] = (major * dir1).cast<float>();
      out.v[i] = (minor * dir2).cast<float>();
    }
  });
  return out;
}

void check_normals(std::span<const vec3f> positions, std::span<const vec3f> normals) {
  if (normals.size() != positions.size())
    throw InvalidArgument("estimate_splat_ellipses: " + std::to_string(normals.size()) +
                          " normals for " + std::to_string(positions.size()) + " positions");
  for (std::size_t i = 0; i < normals.size(); ++i)
    if (!all_finite(normals[i]) || normals[i].squaredNorm() == 0)
      throw InvalidArgument("estimate_splat_ellipses: normal " + std::to_string(i) +
                            " is zero or not finite");
}

/// Reports the fraction done between stages; a false answer cancels.
void report(const estimation_options& opt, double fraction) {
  if (opt.progress && !opt.progress(fraction)) throw Cancelled("estimation: cancelled");
}

void check_options(const estimation_options& opt) {
  if (opt.k_normals < 3)
    throw InvalidArgument("estimate_normals: k = " + std::to_string(opt.k_normals) + " < 3");
  if (opt.k_ellipses < 2)
    throw InvalidArgument("estimate_splat_ellipses: k = " + std::to_string(opt.k_ellipses) +
                          " < 2");
  if (opt.orientation == normal_orientation::viewpoint && !all_finite(opt.viewpoint))
    throw InvalidArgument("estimate_normals: the viewpoint is not finite");
}

/// The estimators' common start: the points sorted (duplicates collapsed), and each one's
/// `stride` nearest in a table, stride = k clamped to the distinct points; reports progress 0.1
/// after sorting and `done` after the table. The table comes from the uniform grid
/// (core/grid_knn.hpp: FLANN's rows, bit for bit, faster on scans); the FLANN index only where
/// a caller searches further (the ellipses' wider neighbourhoods: index()).
struct neighbourhoods {
  sorted_points s;
  int stride;
  std::vector<std::uint32_t> table;
  neighbourhoods(std::span<const vec3f> positions, int k, unsigned threads,
                 const estimation_options& opt, double done)
      : s(sort_points(positions)), stride(clamp_k(k, s.pos.size())) {
    report(opt, 0.1);
    table = grid_knn_table(s.pos, stride, threads);
    report(opt, done);
  }
};

}  // namespace

std::vector<vec3f> estimate_normals(std::span<const vec3f> positions,
                                    const estimation_options& opt) {
  check_options(opt);
  check_positions(positions, "estimate_normals");
  if (positions.empty()) return {};
  const unsigned threads = resolve_threads(opt.threads);
  const neighbourhoods nb(positions, opt.k_normals, threads, opt, 0.7);
  const int kk = nb.stride;
  auto normals = unsort(normals_from(nb.s.pos, nb.table, kk, kk, opt, threads), nb.s);
  report(opt, 1);
  return normals;
}

std::vector<vec3f> estimate_normals(std::span<const vec3f> positions, int k, bool orient,
                                    unsigned threads) {
  return estimate_normals(
      positions, {.k_normals = k,
                  .orientation = orient ? normal_orientation::mst : normal_orientation::none,
                  .threads = threads});
}

splat_axes estimate_splat_ellipses(std::span<const vec3f> positions, std::span<const vec3f> normals,
                                   int k, unsigned threads, ellipse_rule rule) {
  if (k < 2) throw InvalidArgument("estimate_splat_ellipses: k = " + std::to_string(k) + " < 2");
  check_normals(positions, normals);
  check_positions(positions, "estimate_splat_ellipses");
  if (positions.empty()) return {};
  threads = resolve_threads(threads);
  // Copies with their own normals are distinct samples here: each ellipse lies in its normal's
  // tangent plane.
  const sorted_points s = sort_points(positions, normals);
  std::vector<vec3f> sorted_normals(s.pos.size());
  for (std::size_t r = 0; r < s.pos.size(); ++r) sorted_normals[r] = normals[s.order[r]];
  const knn_index index(s.pos);
  const int kk = clamp_k(k, s.pos.size());
  const auto table = knn_table(s.pos, index, kk, threads);
  splat_axes e = ellipses_from(s.pos, sorted_normals, index, table, kk, kk, rule, threads);
  return {unsort(e.u, s), unsort(e.v, s)};
}

estimated_splats estimate_normals_and_ellipses(std::span<const vec3f> positions,
                                               const estimation_options& opt) {
  check_options(opt);
  check_positions(positions, "estimate_normals");
  if (positions.empty()) return {};
  const unsigned threads = resolve_threads(opt.threads);
  const neighbourhoods nb(positions, std::max(opt.k_normals, opt.k_ellipses), threads, opt, 0.6);
  const int kn = clamp_k(opt.k_normals, nb.s.pos.size());
  const int ke = clamp_k(opt.k_ellipses, nb.s.pos.size());
  const int stride = nb.stride;  // = max(kn, ke): clamping is monotone
  const sorted_points& s = nb.s;
  const knn_index index(s.pos);
  const auto& table = nb.table;
  const std::vector<vec3f> normals = normals_from(s.pos, table, stride, kn, opt, threads);
  report(opt, 0.85);
  splat_axes e = ellipses_from(s.pos, normals, index, table, stride, ke, opt.ellipses, threads);
  estimated_splats out{unsort(normals, s), {unsort(e.u, s), unsort(e.v, s)}};
  report(opt, 1);
  return out;
}

estimated_splats estimate_normals_and_ellipses(std::span<const vec3f> positions, int k_normals,
                                               int k_ellipses, bool orient, unsigned threads) {
  return estimate_normals_and_ellipses(
      positions, {.k_normals = k_normals,
                  .k_ellipses = k_ellipses,
                  .orientation = orient ? normal_orientation::mst : normal_orientation::none,
                  .threads = threads});
}

}  // namespace pbr_lod
