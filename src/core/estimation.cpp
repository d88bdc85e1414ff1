// pbr_lod — k-NN normals (Hoppe et al. 1992, §3; PCA + MST orientation) and splat ellipses
// (Pajarola 2003, end of §4: the bounding-ellipse rule of Fig. 5/6a applied to the k nearest
// neighbours of each input sample). The only translation unit that includes CGAL: it is built
// as its own object library (src/core/estimation.cmake) so CGAL's -frounding-math stays here.
#include "pbr_lod/core/estimation.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>

#include <boost/pending/disjoint_sets.hpp>

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <tuple>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"

namespace pbr_lod {

namespace {

// Points per TBB task: a k-NN query is a few µs, so 1024 points amortise the scheduling.
constexpr std::size_t grain = 1024;

void check_positions(std::span<const vec3f> positions, const char* who) {
  for (std::size_t i = 0; i < positions.size(); ++i)
    if (!all_finite(positions[i]))
      throw InvalidArgument(std::string(who) + ": position " + std::to_string(i) +
                            " is not finite");
}

/// Runs body(begin, end) over [0, n) in parallel. Each index is written by exactly one call,
/// so results do not depend on how TBB splits the range.
template <class Body>
void parallel_over(std::size_t n, const Body& body) {
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, n, grain),
                    [&](const tbb::blocked_range<std::size_t>& r) { body(r.begin(), r.end()); });
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
  const Eigen::SelfAdjointEigenSolver<mat3d> es(cov);  // eigenvalues ascending
  const vec3d lambda = es.eigenvalues();
  if (es.info() != Eigen::Success || !(lambda[2] > 0) || !all_finite(lambda))
    return vec3d::UnitZ();  // one position (duplicates, single point)
  vec3d n = lambda[1] <= 1e-12 * lambda[2] ? orthogonal(es.eigenvectors().col(2).normalized())
                                           : vec3d(es.eigenvectors().col(0));
  n.normalize();
  return all_finite(n) ? canonical_sign(n) : vec3d::UnitZ();
}

/// The k nearest neighbours of every position (itself included), k per row, from one FLANN index
/// queried in parallel. Rows of points with fewer than k neighbours (n < k) are padded with the
/// point itself.
std::vector<std::uint32_t> knn_table(std::span<const vec3f> positions, const knn_index& index,
                                     int k) {
  const std::size_t n = positions.size(), kk = static_cast<std::size_t>(k);
  std::vector<std::uint32_t> table(n * kk);
  parallel_over(n, [&](std::size_t begin, std::size_t end) {
    std::vector<std::uint32_t> idx;
    std::vector<float> d2;
    for (std::size_t i = begin; i < end; ++i) {
      index.query(positions[i], k, idx, d2);
      for (std::size_t j = 0; j < kk; ++j)
        table[i * kk + j] = j < idx.size() ? idx[j] : static_cast<std::uint32_t>(i);
    }
  });
  return table;
}

/// Makes the signs of `normals` consistent (Hoppe et al. 1992, §3.3): a minimum spanning forest
/// of the k-NN ("Riemannian") graph with edge cost 1 − |nᵢ·nⱼ| (Kruskal: a parallel sort of the
/// edges, then Boost's union-find); in every connected component the sample with the largest z gets
/// a normal with z ≥ 0 and the sign is propagated along the tree, flipping a child whose normal
/// points against its parent's. This is CGAL::mst_orient_normals' rule, but on the k-NN table the
/// PCA pass already computed (CGAL re-searched every neighbourhood with its own sequential k-d
/// tree: 85 % of the time of estimate_normals; Boost's own kruskal_minimum_spanning_tree, tried
/// first, spent 40 % of the bunny's estimation in its edge heap), and every component is oriented
/// where CGAL orients only the top sample's.
void mst_orient(std::span<const vec3f> pts, std::vector<vec3f>& normals,
                const std::vector<std::uint32_t>& table, int stride_k, int k) {
  const std::size_t n = pts.size(), stride = static_cast<std::size_t>(stride_k),
                    kk = static_cast<std::size_t>(k);
  // The undirected k-NN graph: edge {i, t} once (from the smaller index, or from i when t's row
  // does not list i), in parallel per row, then concatenated in row order.
  struct edge {
    float cost;
    std::uint32_t a, b;
  };
  const auto lists = [&](std::uint32_t t, std::uint32_t i) {
    const auto row = std::span(table).subspan(t * stride, kk);
    return std::find(row.begin(), row.end(), i) != row.end();
  };
  std::vector<std::uint32_t> count(n + 1, 0);
  parallel_over(n, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      for (std::size_t j = 0; j < kk; ++j) {
        const std::uint32_t t = table[i * stride + j];
        count[i + 1] += t != i && (i < t || !lists(t, static_cast<std::uint32_t>(i)));
      }
  });
  for (std::size_t i = 0; i < n; ++i) count[i + 1] += count[i];
  std::vector<edge> edges(count[n]);
  parallel_over(n, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      std::size_t at = count[i];
      for (std::size_t j = 0; j < kk; ++j) {
        const std::uint32_t t = table[i * stride + j];
        if (t != i && (i < t || !lists(t, static_cast<std::uint32_t>(i))))
          edges[at++] = {1.0f - std::abs(normals[i].dot(normals[t])), static_cast<std::uint32_t>(i),
                         t};
      }
    }
  });
  // Kruskal: edges by cost (ties by index, so the forest is deterministic), joined with Boost's
  // union-find (path compression, union by rank).
  tbb::parallel_sort(edges.begin(), edges.end(), [](const edge& x, const edge& y) {
    return std::tie(x.cost, x.a, x.b) < std::tie(y.cost, y.a, y.b);
  });
  std::vector<std::uint32_t> rank(n), parent(n);
  boost::disjoint_sets<std::uint32_t*, std::uint32_t*> sets(rank.data(), parent.data());
  for (std::uint32_t i = 0; i < n; ++i) sets.make_set(i);
  std::vector<std::pair<std::uint32_t, std::uint32_t>> tree;
  tree.reserve(n);
  for (const auto& e : edges) {
    const std::uint32_t ra = sets.find_set(e.a), rb = sets.find_set(e.b);
    if (ra == rb) continue;
    sets.link(ra, rb);
    tree.emplace_back(e.a, e.b);
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

int clamp_k(int k, std::size_t n) {
  return static_cast<int>(std::min<std::size_t>(std::size_t(k), n));
}

/// PCA normals from the first kk neighbours of each row of `table` (rows of `stride`), then
/// the MST orientation over the same neighbourhoods.
std::vector<vec3f> normals_from(std::span<const vec3f> positions,
                                const std::vector<std::uint32_t>& table, int stride_k, int kk,
                                bool orient) {
  const std::size_t n = positions.size(), stride = static_cast<std::size_t>(stride_k),
                    kz = static_cast<std::size_t>(kk);
  std::vector<vec3f> normals(n);
  parallel_over(n, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i)
      normals[i] = pca_normal(positions, std::span(table).subspan(i * stride, kz)).cast<float>();
  });
  if (orient && n >= 2) mst_orient(positions, normals, table, stride_k, kk);
  return normals;
}

/// Splat ellipses from the first kk neighbours of each row of `table` (rows of `stride`).
splat_axes ellipses_from(std::span<const vec3f> positions, std::span<const vec3f> normals,
                         const knn_index& index, const std::vector<std::uint32_t>& table,
                         int stride_k, int kk) {
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

  parallel_over(n, [&](std::size_t begin, std::size_t end) {
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
      double a = 0, b = 0, c = 0, extent2 = 0;
      for (const auto j : idx) {
        const vec3d d = positions[j].cast<double>() - p;
        const vec2d q(d.dot(t1), d.dot(t2));
        xy.push_back(q);
        a += q.x() * q.x();
        b += q.x() * q.y();
        c += q.y() * q.y();
        extent2 += d.squaredNorm();
      }
      const double h = 0.5 * (a - c), r = std::hypot(h, b);
      const double l1 = 0.5 * (a + c) + r;
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
      const double l2 = std::max(0.5 * (a + c) - r, ratio2 * l1);
      // Major axis at angle ψ = ½·atan2(2b, a − c) in the (t1, t2) frame (r > 0 here unless
      // the moments are isotropic, where any direction is an eigenvector: ψ = 0).
      const double psi = r > 0 ? 0.5 * std::atan2(b, h) : 0.0;
      const vec2d e1(std::cos(psi), std::sin(psi)), e2(-e1.y(), e1.x());
      double f2 = 0;
      for (const auto& q : xy) {
        const double x = q.dot(e1), y = q.dot(e2);
        f2 = std::max(f2, x * x / l1 + y * y / l2);
      }
      const double f = std::sqrt(f2) * cover_margin;
      const vec3d axis1 = e1.x() * t1 + e1.y() * t2, axis2 = e2.x() * t1 + e2.y() * t2;
      out.u[i] = (f * std::sqrt(l1) * axis1).cast<float>();
      out.v[i] = (f * std::sqrt(l2) * axis2).cast<float>();
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

}  // namespace

std::vector<vec3f> estimate_normals(std::span<const vec3f> positions, int k, bool orient) {
  if (k < 3) throw InvalidArgument("estimate_normals: k = " + std::to_string(k) + " < 3");
  check_positions(positions, "estimate_normals");
  if (positions.empty()) return {};
  const knn_index index(positions);
  const int kk = clamp_k(k, positions.size());
  return normals_from(positions, knn_table(positions, index, kk), kk, kk, orient);
}

splat_axes estimate_splat_ellipses(std::span<const vec3f> positions, std::span<const vec3f> normals,
                                   int k) {
  if (k < 2) throw InvalidArgument("estimate_splat_ellipses: k = " + std::to_string(k) + " < 2");
  check_normals(positions, normals);
  check_positions(positions, "estimate_splat_ellipses");
  if (positions.empty()) return {};
  const knn_index index(positions);
  const int kk = clamp_k(k, positions.size());
  return ellipses_from(positions, normals, index, knn_table(positions, index, kk), kk, kk);
}

estimated_splats estimate_normals_and_ellipses(std::span<const vec3f> positions, int k_normals,
                                               int k_ellipses, bool orient) {
  if (k_normals < 3)
    throw InvalidArgument("estimate_normals: k = " + std::to_string(k_normals) + " < 3");
  if (k_ellipses < 2)
    throw InvalidArgument("estimate_splat_ellipses: k = " + std::to_string(k_ellipses) + " < 2");
  check_positions(positions, "estimate_normals");
  if (positions.empty()) return {};
  const knn_index index(positions);
  const int kn = clamp_k(k_normals, positions.size()), ke = clamp_k(k_ellipses, positions.size());
  const int stride = std::max(kn, ke);
  const auto table = knn_table(positions, index, stride);
  estimated_splats out;
  out.normals = normals_from(positions, table, stride, kn, orient);
  out.axes = ellipses_from(positions, out.normals, index, table, stride, ke);
  return out;
}

}  // namespace pbr_lod
