// The Gaussian hierarchy's build (Kerbl et al. 2024 §4.1): median splits, then moment matching
// bottom up. builders/gaussian_hierarchy.hpp says what each step implements.
//
// Parallel and deterministic: the tree's shape depends only on the input's size (a range of c
// Gaussians splits into ⌊c/2⌋ and ⌈c/2⌉), so every node's preorder number, its inner Gaussian's
// slot and its leaves' place in the store follow from its range alone. The top of the tree is
// split on the calling thread until there are a few subtrees per worker; the subtrees are then
// built as tasks, each writing only its own slots, and the top is merged last.
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <map>
#include <numeric>
#include <span>

#include <Eigen/Eigenvalues>

#include "gaussian_build.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace {

using node = gaussian_hierarchy::node;

using tree_shape = detail::gaussian_tree_shape;
using split_key = detail::gaussian_split_key;
using detail::enclose;
using detail::gaussian_reach;

/// A subtree to build: Gaussians [lo, hi) of the order, its preorder node number and the slot of
/// its inner Gaussian (counted from the first inner slot).
struct subtree {
  std::uint32_t lo, hi, node, inner;
};

struct builder {
  const gaussian_cloud& in;
  const tree_shape& shape;
  std::vector<split_key>& keys;  // the Gaussian of each store slot [0, n)
  gaussian_cloud& out;           // the store: n leaves' Gaussians, then the inner ones
  std::vector<node>& nodes;
  std::uint32_t n;
  merged_opacity opacity;

  [[nodiscard]] std::uint32_t nodes_of(std::uint32_t c) const {
    return 2 * shape.leaves_known(c) - 1;
  }
  [[nodiscard]] bool is_leaf(std::uint32_t c) const { return c <= shape.leaf_size(); }

  /// Splits [lo, hi) at its median (split_at_median).
  void split(std::uint32_t lo, std::uint32_t hi) const {
    detail::split_at_median(std::span<split_key>(keys).subspan(lo, hi - lo));
  }

  [[nodiscard]] std::pair<subtree, subtree> children(const subtree& t) const {
    const std::uint32_t mid = t.lo + (t.hi - t.lo) / 2;
    const std::uint32_t left_nodes = nodes_of(mid - t.lo);
    const subtree l{t.lo, mid, t.node + 1, t.inner + 1};
    const subtree r{mid, t.hi, t.node + 1 + left_nodes, t.inner + 1 + (left_nodes - 1) / 2};
    return {l, r};
  }

  /// Splits everything below t (sequentially). A leaf's Gaussians go in input order, so that the
  /// store, and the sums of the merges above, do not depend on how the splits left them (a
  /// chunked build splits a chunk from another arrangement and must give the same bytes).
  void split_all(const subtree& t) const {
    if (is_leaf(t.hi - t.lo)) {
      std::sort(keys.begin() + t.lo, keys.begin() + t.hi,
                [](const split_key& a, const split_key& b) { return a.g < b.g; });
      return;
    }
    split(t.lo, t.hi);
    const auto [l, r] = children(t);
    split_all(l);
    split_all(r);
  }

  void copy_leaf_gaussians(std::uint32_t lo, std::uint32_t hi) const;
  void make_leaf(const subtree& t) const;
  void merge(const subtree& t) const;
  /// Builds the nodes of t after its Gaussians are split and copied (post-order merge).
  void merge_all(const subtree& t) const {
    if (is_leaf(t.hi - t.lo)) return make_leaf(t);
    const auto [l, r] = children(t);
    merge_all(l);
    merge_all(r);
    merge(t);
  }
};

void builder::copy_leaf_gaussians(std::uint32_t lo, std::uint32_t hi) const {
  const std::size_t stride = in.sh_stride();
  for (std::uint32_t i = lo; i < hi; ++i) {
    const std::uint32_t g = keys[i].g;
    out.positions[i] = in.positions[g];
    out.scales[i] = in.scales[g];
    out.rotations[i] = in.rotations[g];
    out.opacities[i] = in.opacities[g];
    std::copy_n(in.sh.begin() + static_cast<std::ptrdiff_t>(g * stride), stride,
                out.sh.begin() + static_cast<std::ptrdiff_t>(i * stride));
  }
}

void builder::make_leaf(const subtree& t) const {
  node& d = nodes[t.node];
  d.gaussian = t.lo;
  d.count = t.hi - t.lo;
  d.right = 0;
  d.bounds = gaussian_reach(out, t.lo);
  d.size = out.scales[t.lo].maxCoeff();
  for (std::uint32_t i = t.lo + 1; i < t.hi; ++i) {
    d.bounds = enclose(d.bounds, gaussian_reach(out, i));
    d.size = std::max(d.size, out.scales[i].maxCoeff());
  }
}

/// The surface proxy of Kerbl et al. 2024 (their weights' area term): s₀s₁ + s₀s₂ + s₁s₂.
double surface(const vec3f& s) {
  return double(s[0]) * s[1] + double(s[0]) * s[2] + double(s[1]) * s[2];
}

/// The merged Gaussian's scales and rotation from its covariance (eigen-decomposition in
/// double; a right-handed frame, so the quaternion is a rotation), its smallest axis on the
/// side of `side` (the children's weighted normals: splat_of()'s normal keeps their side).
void decompose(const Eigen::Matrix3d& cov, const Eigen::Vector3d& side, vec3f& scale,
               vec4f& rotation) {
  // The closed form for 3 × 3 (Eigen's computeDirect): in double it is within ~1e-9 of the
  // iterative solver where both are exact to float, at a fraction of the cost (the merge runs once
  // per inner node: about one per input Gaussian).
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
  eig.computeDirect(cov);
  (void)0;
  Eigen::Matrix3d r = eig.eigenvectors();  // ascending: column 0 is the smallest axis
  if (r.col(0).dot(side) < 0) r.col(0) = -r.col(0);
  if (r.determinant() < 0) r.col(2) = -r.col(2);
  for (int a = 0; a < 3; ++a)
    scale[a] = static_cast<float>(std::sqrt(std::max(eig.eigenvalues()[a], 0.0)));
  Eigen::Quaterniond q(r);
  q.normalize();
  if (q.w() < 0) q.coeffs() = -q.coeffs();
  rotation = vec4f(static_cast<float>(q.w()), static_cast<float>(q.x()), static_cast<float>(q.y()),
                   static_cast<float>(q.z()));
  const float len = rotation.norm();
  rotation = len > 0 && std::isfinite(len) ? vec4f(rotation / len) : vec4f(1, 0, 0, 0);
}

/// The axis of Gaussian i's smallest scale, with its rotation's sign (splat_of()'s normal).
Eigen::Vector3d normal_of(const gaussian_cloud& g, std::size_t i) {
  const vec4f& q = g.rotations[i];
  const Eigen::Matrix3d r = Eigen::Quaterniond(q[0], q[1], q[2], q[3]).toRotationMatrix();
  const vec3f& s = g.scales[i];
  int small = 0;
  for (int a = 1; a < 3; ++a)
    if (s[a] < s[small]) small = a;
  return r.col(small);
}

Eigen::Matrix3d covariance_of(const gaussian_cloud& g, std::size_t i) {
  const auto c = gaussian_covariance(g.scales[i], g.rotations[i]);
  Eigen::Matrix3d m;
  m << c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5];
  return m;
}

/// The Gaussians a node merges: its children's representatives (a leaf child's Gaussians, an
/// inner child's merged one), as store slots: at most two leaves of 64 (leaf_size ≤ 64). A fixed
/// array, since a merge runs once per inner node (half the nodes) and needs no allocation.
struct part_list {
  std::array<std::uint32_t, 128> slot;
  std::size_t n = 0;
};

void representatives(const builder& b, const subtree& c, part_list& out) {
  if (b.is_leaf(c.hi - c.lo)) {
    for (std::uint32_t i = c.lo; i < c.hi; ++i) out.slot[out.n++] = i;
  } else {
    out.slot[out.n++] = b.n + c.inner;
  }
}

void builder::merge(const subtree& t) const {
  const auto [l, r] = children(t);
  part_list list;
  representatives(*this, l, list);
  representatives(*this, r, list);
  const std::uint32_t slot = n + t.inner;
  detail::merge_gaussians(out, std::span<const std::uint32_t>(list.slot.data(), list.n), slot,
                          opacity);
  node& d = nodes[t.node];
  d.gaussian = slot;
  d.count = 0;
  d.right = r.node;
  const node &nl = nodes[l.node], &nr = nodes[r.node];
  d.size = std::max({out.scales[slot].maxCoeff(), nl.size, nr.size});
  d.bounds = enclose(enclose(nl.bounds, nr.bounds), gaussian_reach(out, slot));
}

void validate_input(const gaussian_cloud& in, const gaussian_hierarchy_options& o) {
  if (o.leaf_size < 1 || o.leaf_size > 64)
    throw InvalidArgument("gaussian hierarchy: leaf_size must be 1–64, got " +
                          std::to_string(o.leaf_size));
  if (in.empty())
    throw InvalidArgument(
        "gaussian hierarchy: no points to build from (the input has no Gaussians)");
  if (in.size() > (std::size_t{1} << 31))
    throw InvalidArgument("gaussian hierarchy: more than 2^31 Gaussians (" +
                          std::to_string(in.size()) + ")");
  in.validate("gaussian hierarchy input");
}

/// The subtrees the top of the tree splits into: about four per worker. Each level's splits run
/// side by side (the root's alone).
std::vector<subtree> top_subtrees(const builder& b, const subtree& root, unsigned threads,
                                  std::vector<subtree>& top) {
  std::vector<subtree> level{root};
  const std::size_t want = threads <= 1 ? 1 : 4 * std::size_t{threads};
  const auto splits = [&b](const subtree& t) {
    return !b.is_leaf(t.hi - t.lo) && t.hi - t.lo >= 4096;
  };
  while (level.size() < want) {
    std::vector<subtree> split_here;
    for (const subtree& t : level)
      if (splits(t)) split_here.push_back(t);
    if (split_here.empty()) break;
    detail::parallel_tasks(split_here.size(), threads, [&](std::size_t i, unsigned) {
      b.split(split_here[i].lo, split_here[i].hi);
    });
    std::vector<subtree> next;
    for (const subtree& t : level) {
      if (!splits(t)) {
        next.push_back(t);
        continue;
      }
      top.push_back(t);
      const auto [l, r] = b.children(t);
      next.push_back(l);
      next.push_back(r);
    }
    level = std::move(next);
  }
  return level;
}

}  // namespace

gaussian_hierarchy build_gaussian_hierarchy(const gaussian_cloud& in,
                                            const gaussian_hierarchy_options& o,
                                            gaussian_hierarchy_stats* stats) {
  const auto t0 = std::chrono::steady_clock::now();
  validate_input(in, o);
  gaussian_hierarchy h;
  h.g_.origin = in.origin;
  h.g_.sh_degree = in.sh_degree;
  const auto n = static_cast<std::uint32_t>(in.size());
  h.input_ = n;
  if (n > 0) {
    tree_shape shape(static_cast<std::uint32_t>(o.leaf_size));
    const std::uint32_t leaves = shape.leaves(n);
    const std::size_t total = std::size_t{n} + (leaves - 1);
    const unsigned threads = resolve_threads(o.threads);
    // The store is 1.6–2.3 × the input (leaves of two or one): on huge pages, faulted in by every
    // thread (core/memory.hpp: 4 kB first touches and the zeroing were half of a one-thread
    // build). The vectors' own value-initialisation (a memset per vector, which a
    // std::vector<float> cannot skip) then runs as two tasks: the SH, ~80 % of the bytes at
    // degree 3, beside everything else.
    const std::size_t sh_size = total * in.sh_stride(), node_count = 2 * std::size_t{leaves} - 1;
    detail::populate_fresh(h.g_.positions, total, threads);
    detail::populate_fresh(h.g_.scales, total, threads);
    detail::populate_fresh(h.g_.rotations, total, threads);
    detail::populate_fresh(h.g_.opacities, total, threads);
    detail::populate_fresh(h.g_.sh, sh_size, threads);
    detail::populate_fresh(h.nodes_, node_count, threads);
    detail::parallel_tasks(2, threads, [&](std::size_t task, unsigned) {
      if (task == 0) {
        h.g_.sh.resize(sh_size);
        return;
      }
      h.g_.positions.resize(total);
      h.g_.scales.resize(total);
      h.g_.rotations.resize(total);
      h.g_.opacities.resize(total);
      h.nodes_.resize(node_count);
    });
    std::vector<split_key> keys;  // 16 B per Gaussian: on huge pages too
    detail::resize_fresh(keys, n, threads);
    detail::parallel_chunks(n, threads, 1 << 16, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = lo; i < hi; ++i)
        keys[i] = {in.positions[i], 3 * in.scales[i].maxCoeff(), static_cast<std::uint32_t>(i)};
    });
    const builder b{in, shape, keys, h.g_, h.nodes_, n, o.opacity};
    std::vector<subtree> top;  // split here, merged last (parents before children)
    const std::vector<subtree> parts = top_subtrees(b, subtree{0, n, 0, 0}, threads, top);
    detail::parallel_tasks(parts.size(), threads, [&](std::size_t i, unsigned) {
      b.split_all(parts[i]);
      b.copy_leaf_gaussians(parts[i].lo, parts[i].hi);
      b.merge_all(parts[i]);
    });
    for (auto it = top.rbegin(); it != top.rend(); ++it) b.merge(*it);
  }
  if (stats) {
    stats->input = n;
    stats->inner = h.inner_gaussians();
    stats->nodes = h.nodes_.size();
    stats->depth = h.depth();
    stats->seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  }
  return h;
}

namespace detail {

sphere enclose(const sphere& a, const sphere& b) {
  const vec3f d = b.centre - a.centre;
  const float dist = d.norm();
  if (dist + b.radius <= a.radius) return a;
  if (dist + a.radius <= b.radius) return b;
  const float r = 0.5f * (dist + a.radius + b.radius);
  const vec3f c = a.centre + d * ((r - a.radius) / dist);
  // Float rounding may leave a or b a hair outside: grow by a relative epsilon.
  return {c,
          r * (1 + 4 * std::numeric_limits<float>::epsilon()) + std::numeric_limits<float>::min()};
}

void split_at_median(std::span<gaussian_split_key> keys) {
  vec3f mn = vec3f::Constant(std::numeric_limits<float>::max()), mx = -mn;
  for (const gaussian_split_key& k : keys) {
    mn = mn.cwiseMin(k.p - vec3f::Constant(k.reach));
    mx = mx.cwiseMax(k.p + vec3f::Constant(k.reach));
  }
  int axis = 0;
  const vec3f ext = mx - mn;
  for (int a = 1; a < 3; ++a)
    if (ext[a] > ext[axis]) axis = a;
  const auto less = [axis](const gaussian_split_key& a, const gaussian_split_key& b) {
    const float pa = a.p[axis], pb = b.p[axis];
    return pa < pb || (pa == pb && a.g < b.g);
  };
  std::nth_element(keys.begin(), keys.begin() + static_cast<std::ptrdiff_t>(keys.size() / 2),
                   keys.end(), less);
}

void merge_gaussians(gaussian_cloud& g, std::span<const std::uint32_t> parts, std::size_t slot,
                     merged_opacity opacity) {
  std::array<double, 128> weights;  // parts.size() ≤ 128 (two leaves of ≤ 64)
  const std::span<double> w(weights.data(), parts.size());
  // Weights w_i ∝ o_i S(s_i); all zero (zero sizes or opacities): equal weights.
  double total = 0;
  for (std::size_t k = 0; k < parts.size(); ++k) {
    w[k] = double(g.opacities[parts[k]]) * surface(g.scales[parts[k]]);
    total += w[k];
  }
  if (!(total > 0) || !std::isfinite(total)) std::fill(w.begin(), w.end(), 1.0);
  const double sum = std::accumulate(w.begin(), w.end(), 0.0);
  std::array<double, 128> shares;  // w[k] / sum, once per part
  for (std::size_t k = 0; k < parts.size(); ++k) shares[k] = w[k] / sum;
  // Mean, then the covariance about it (both in double, origin-relative).
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < parts.size(); ++k)
    mean += shares[k] * g.positions[parts[k]].cast<double>();
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (std::size_t k = 0; k < parts.size(); ++k) {
    const Eigen::Vector3d d = g.positions[parts[k]].cast<double>() - mean;
    cov += shares[k] * (covariance_of(g, parts[k]) + d * d.transpose());
  }
  Eigen::Vector3d side = Eigen::Vector3d::Zero();
  for (std::size_t k = 0; k < parts.size(); ++k) side += w[k] * normal_of(g, parts[k]);
  g.positions[slot] = mean.cast<float>();
  decompose(cov, side, g.scales[slot], g.rotations[slot]);
  // Opacity: the weighted opacity-area Σ oᵢS(sᵢ) conserved. Where the children overlap it
  // exceeds the merged Gaussian's surface: the paper keeps o > 1 (conserve); grow keeps o = 1
  // and scales the Gaussian by √o (S goes as s²), the same product in a valid 3DGS Gaussian (a
  // file stores opacity as a logit), so a cut exports as drawn. A merged Gaussian of no size
  // takes its most opaque part's opacity.
  float most = 0;
  for (const std::uint32_t p : parts) most = std::max(most, g.opacities[p]);
  const double area = surface(g.scales[slot]);
  double o = area > 0 && total > 0 ? total / area : double(most);
  if (opacity == merged_opacity::grow && o > 1 && std::isfinite(o)) {
    g.scales[slot] *= static_cast<float>(std::sqrt(o));
    o = 1;
  }
  g.opacities[slot] = static_cast<float>(std::min(o, double(std::numeric_limits<float>::max())));
  // SH: the same weights.
  const std::size_t stride = g.sh_stride();
  float* sh = g.sh.data() + slot * stride;
  for (std::size_t j = 0; j < stride; ++j) {
    double v = 0;
    for (std::size_t k = 0; k < parts.size(); ++k) v += shares[k] * g.sh[parts[k] * stride + j];
    sh[j] = static_cast<float>(v);
  }
}

}  // namespace detail

}  // namespace pbr_lod
