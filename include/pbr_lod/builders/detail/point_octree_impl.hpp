// pbr_lod — the point-octree builder (implementation of builders/point_octree.hpp). This work is
// based on:
//   R. Pajarola, "Efficient Level-of-Details for Point Based Rendering", CGIM 2003.
// point_octree_builder::run() estimates normals and ellipses where the input has none (§4 end),
// quantises them (§5), then build() makes each node through named stages:
//   octant_pass()           §3, Fig. 3   split rule (octant about p̄_c), sphere radius, cone
//   node_centre_and_cone()  §3           representative sample: p̄_c, n̄_c, normal cone, colour
//   finish_leaf()           EQ 1–3, 5–6  covariance of the samples, bounding ellipse, sphere
//   scatter_by_octant(), child_inputs(), build_children()   §3 "divide S_c into the subsets S_i"
//   finish_inner()          EQ 4, 5–6    covariances merged bottom up, bounding ellipse, sphere
// fit_ellipse() is EQ 5–6 with Fig. 6b's scale; the file format is in point_octree_io.hpp.
#pragma once

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <memory>
#include <numbers>
#include <numeric>
#include <optional>
#include <span>
#include <thread>
#include <utility>

#include <Eigen/Eigenvalues>

#include "pbr_lod/core/covariance.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/memory.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/normal_repair.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace detail {

/// Unit tangent frame of a unit normal n: rows t1, t2, n with t1 = t2 × n. The paper's choice
/// R_y = (0, −n_z, n_y) degenerates for n ∥ x; any_orthogonal() never does.
inline void tangent_frame(const vec3f& n, vec3f& t1, vec3f& t2) {
  t2 = any_orthogonal(n);
  t1 = t2.cross(n).normalized();
}

/// (normal, major axis, minor axis) from their quantisation codes; the major axis is made exactly
/// orthogonal to the decoded normal, the minor one is normal × major. Used by the builder and
/// by load(), so both derive bit-identical vectors.
inline void axes_from_codes(const normal_quantizer& q, std::uint32_t ncode, std::uint32_t ecode,
                            vec3f& n, vec3f& e1, vec3f& e2) {  // NOLINT
  n = q.decode(ncode);
  vec3f e = q.decode(ecode);
  e -= n * n.dot(e);
  e = e.squaredNorm() > 1e-12f ? vec3f(e.normalized()) : any_orthogonal(n);
  e1 = e;
  e2 = n.cross(e1);
}

/// Eigen decomposition of the symmetric 2×2 [[a, b], [b, c]] (EQ 5–6). EQ 5 as printed reads
/// λ² + tr·λ + det = 0; the characteristic polynomial is λ² − tr·λ + det = 0, solved here in the
/// cancellation-free form. Returns λ₁ ≥ λ₂ and the unit eigenvector of λ₁.
inline void eigen_2x2(double a, double b, double c, double& l1, double& l2, vec2d& v1) {
  const double half_diff = 0.5 * (a - c);
  const double disc = std::hypot(half_diff, b);
  const double mid = 0.5 * (a + c);
  l1 = mid + disc;
  l2 = mid - disc;
  if (disc <= 1e-300) {
    v1 = vec2d(1, 0);
    return;
  }
  // (b, λ₁ − a) and (λ₁ − c, b) are both eigenvectors; take the better conditioned one.
  const vec2d x(b, l1 - a), y(l1 - c, b);
  v1 = x.squaredNorm() >= y.squaredNorm() ? x.normalized() : y.normalized();
}

inline double squared(double x) {
  return x * x;
}

/// f(lo, hi) over contiguous chunks of at least ~4096 samples (core/parallel.hpp).
template <class F>
void parallel_for(std::size_t n, unsigned threads, F&& f) {
  parallel_chunks(n, threads, 4096, f);
}

}  // namespace detail

namespace detail {

template <attributes A>
struct point_octree_builder {
  using tree = point_octree<A>;
  using node = typename tree::node;

  /// What a subtree reports to its parent (Fig. 4, bottom-up data flow).
  struct summary {
    scatter_accumulator scatter;                // covariance_method::stable
    generic_homogeneous_covariance<double> gd;  // covariance_method::generic_double
    generic_homogeneous_covariance<float> gf;   // covariance_method::generic_float
    mat3d disk = mat3d::Zero();  // Σ over samples of the disk's own covariance (uuᵀ + vvᵀ)/4
    double n = 0;
  };
  /// Nodes of one subtree, built by one thread; spliced into the tree afterwards.
  struct local {
    std::vector<node> nodes;
    std::vector<rgb8> colours;
    std::vector<typename tree::orientation_code> codes;  // one per node when quantising
  };

  // The samples with normals and ellipses (quantised when asked). The build reorders them in
  // place — "divide S_c into the subsets S_i" — so every node's samples are contiguous and each
  // pass streams through memory instead of gathering through an index (≈5× faster on 1M points).
  point_set<A>& in;
  std::vector<typename tree::orientation_code>* in_codes;  // reordered with the samples, or null
  const point_octree_options& opt;
  const normal_quantizer* q;      // null: no quantisation
  std::vector<std::uint8_t> oct;  // octant of sample k during its node's pass
  std::vector<vec3f> scratch3;    // scatter buffers; subtrees own disjoint ranges of all of these
  std::vector<rgb8> scratch_rgb;
  std::vector<typename tree::orientation_code> scratch_code;
  unsigned threads = 1;                                 // for the passes near the root
  std::thread::id caller = std::this_thread::get_id();  // the only thread that calls progress
  std::atomic<std::size_t> done{0};
  std::atomic<bool> cancel{false};

  point_octree_builder(point_set<A>& pts, std::vector<typename tree::orientation_code>* codes,
                       const point_octree_options& o, const normal_quantizer* quant,
                       unsigned workers)
      : in(pts), in_codes(codes), opt(o), q(quant), threads(workers) {
    // Scratch written by the scatters only: on huge pages, faulted in by all workers (see
    // core/memory.hpp for what first touch costs here).
    const auto fresh = [n = pts.size(), workers](auto& v) { resize_fresh(v, n, workers); };
    fresh(oct);
    fresh(scratch3);
    if constexpr (A.colour) fresh(scratch_rgb);
    if (codes) fresh(scratch_code);
  }

  /// Per-octant sums of one pass over a node's samples (or one block of them).
  struct pass_sums {
    std::array<std::uint32_t, 8> cnt{};
    std::array<vec3d, 8> psum, nsum, csum;
    double r2 = 0;
    float min_dot = 1;
    pass_sums() {
      psum.fill(vec3d::Zero());
      nsum.fill(vec3d::Zero());
      csum.fill(vec3d::Zero());
    }
    pass_sums& operator+=(const pass_sums& o) {
      for (std::size_t u = 0; u < 8; ++u) {
        cnt[u] += o.cnt[u];
        psum[u] += o.psum[u];
        nsum[u] += o.nsum[u];
        csum[u] += o.csum[u];
      }
      r2 = std::max(r2, o.r2);
      min_dot = std::min(min_dot, o.min_dot);
      return *this;
    }
  };
  /// Samples per block of a pass (see build()).
  static constexpr std::uint32_t block = 1u << 16;
  /// [lo, hi) of block b of the range [first, first + count).
  static std::pair<std::uint32_t, std::uint32_t> block_range(std::uint32_t first,
                                                             std::uint32_t count, std::size_t b) {
    return {first + static_cast<std::uint32_t>(b) * block,
            first + static_cast<std::uint32_t>(std::min<std::size_t>(count, (b + 1) * block))};
  }

  /// Stable counting-sort scatter of [first, first + count) of one array by octant, block b
  /// starting each octant at at[b]; then the copy back. Blocks in parallel over `workers`.
  template <class T>
  void scatter(std::vector<T>& v, std::vector<T>& scratch, std::uint32_t first, std::uint32_t count,
               const std::vector<std::array<std::uint32_t, 8>>& at, unsigned workers) {
    parallel_chunks(at.size(), workers, 1, [&](std::size_t b0, std::size_t b1) {
      for (std::size_t b = b0; b < b1; ++b) {
        std::array<std::uint32_t, 8> pos = at[b];
        const auto [lo, hi] = block_range(first, count, b);
        for (std::uint32_t k = lo; k < hi; ++k) scratch[pos[oct[k]]++] = v[k];
      }
    });
    parallel_chunks(count, workers, block, [&](std::size_t lo, std::size_t hi) {
      std::copy(scratch.begin() + first + lo, scratch.begin() + first + hi, v.begin() + first + lo);
    });
  }

  /// Top-down input of a node (Fig. 3): its samples and the averages its parent accumulated.
  struct input {
    std::uint32_t first, count;
    vec3d mean;        // p̄_c (relative to the origin)
    vec3d normal_sum;  // Σ n_i
    vec3d colour_sum;  // Σ c_i
    std::uint32_t depth;
  };

  /// The root's sums, block by block (in parallel), combined in block order.
  static input root_input(const point_set<A>& pts, unsigned workers) {
    const auto n = static_cast<std::uint32_t>(pts.size());
    std::vector<std::array<vec3d, 3>> part((n + block - 1) / block);
    parallel_chunks(part.size(), workers, 1, [&](std::size_t b0, std::size_t b1) {
      for (std::size_t b = b0; b < b1; ++b) {
        std::array<vec3d, 3> t{vec3d::Zero(), vec3d::Zero(), vec3d::Zero()};
        const auto [lo, hi] = block_range(0, n, b);
        for (std::uint32_t i = lo; i < hi; ++i) {
          t[0] += pts.positions[i].template cast<double>();
          t[1] += pts.normals[i].template cast<double>();
          if constexpr (A.colour)
            t[2] += vec3d(pts.colours[i].r, pts.colours[i].g, pts.colours[i].b);
        }
        part[b] = t;
      }
    });
    input r{0, n, vec3d::Zero(), vec3d::Zero(), vec3d::Zero(), 0};
    for (const auto& t : part) {
      r.mean += t[0];
      r.normal_sum += t[1];
      r.colour_sum += t[2];
    }
    r.mean /= static_cast<double>(n);
    return r;
  }

  void add_sample(summary& s, std::uint32_t i) const {
    const vec3f& p = in.positions[i];
    switch (opt.covariance) {
      case covariance_method::stable:
        s.scatter.add(p.template cast<double>());
        break;
      case covariance_method::generic_double:
        s.gd.add(in.origin + p.template cast<double>());
        break;
      case covariance_method::generic_float:
        s.gf.add((in.origin + p.template cast<double>()).template cast<float>());
        break;
    }
    const vec3d u = in.axis_u[i].template cast<double>(), v = in.axis_v[i].template cast<double>();
    s.disk += 0.25 * (u * u.transpose() + v * v.transpose());
    s.n += 1;
  }
  void add_summary(summary& s, const summary& c) const {
    switch (opt.covariance) {
      case covariance_method::stable:
        s.scatter += c.scatter;
        break;  // Chan et al.
      case covariance_method::generic_double:
        s.gd += c.gd;
        break;  // EQ 4
      case covariance_method::generic_float:
        s.gf += c.gf;
        break;  // EQ 4
    }
    s.disk += c.disk;
    s.n += c.n;
  }

  /// Tangent-plane 2×2 covariance about `centre` in the frame (t1, t2, n): EQ 3 with R's rows
  /// (t1, t2, n), keeping the upper-left 2×2; plus the mean covariance of the disks themselves.
  Eigen::Matrix2d tangent_covariance(const summary& s, const vec3f& centre, const vec3f& t1,
                                     const vec3f& t2, const vec3f& n) const {
    Eigen::Matrix<double, 2, 3> P;
    P.row(0) = t1.template cast<double>();
    P.row(1) = t2.template cast<double>();
    Eigen::Matrix2d m;
    switch (opt.covariance) {
      case covariance_method::stable:
        m = P * s.scatter.covariance_about(centre.template cast<double>()) * P.transpose();
        break;
      case covariance_method::generic_double: {
        mat3d R;
        R << t1.template cast<double>().transpose(), t2.template cast<double>().transpose(),
            n.template cast<double>().transpose();
        m = s.gd.in_frame(in.origin + centre.template cast<double>(), R).template block<2, 2>(0, 0);
        break;
      }
      case covariance_method::generic_float: {
        mat3f R;
        R << t1.transpose(), t2.transpose(), n.transpose();
        const vec3f c = (in.origin + centre.template cast<double>()).template cast<float>();
        m = s.gf.in_frame(c, R).template block<2, 2>(0, 0).template cast<double>();
        break;
      }
    }
    if (s.n > 0) m += P * (s.disk / s.n) * P.transpose();
    return m;
  }

  /// 3×3 covariance about the mean, by the configured method.
  mat3d covariance3(const summary& s) const {
    switch (opt.covariance) {
      case covariance_method::generic_double:
        return s.gd.covariance();
      case covariance_method::generic_float:
        return s.gf.covariance().template cast<double>();
      case covariance_method::stable:
        break;
    }
    return s.scatter.covariance();
  }

  /// EQ 5–6 and Fig. 6b: axes from the tangent covariance, then the scale f that makes the
  /// ellipse cover every corner given by for_each_corner. Writes normal/axes into nd (and codes).
  template <class Corners>
  void fit_ellipse(node& nd, typename tree::orientation_code* code, const summary& s,
                   bool normal_valid, Corners&& for_each_corner) const {
    vec3f n = nd.normal;
    if (!normal_valid) {
      // Normals cancel (a thin sheet seen from both sides): take the plane of least variance.
      const mat3d c = s.n > 0 ? mat3d(covariance3(s) + s.disk / s.n) : mat3d(mat3d::Identity());
      Eigen::SelfAdjointEigenSolver<mat3d> es(c);
      n = es.eigenvectors().col(0).template cast<float>();
      if (!all_finite(n) || n.squaredNorm() < 0.5f) n = vec3f::UnitZ();
      n.normalize();
    }
    vec3f t1, t2;
    detail::tangent_frame(n, t1, t2);
    const Eigen::Matrix2d m = tangent_covariance(s, nd.centre, t1, t2, n);
    double l1 = 0, l2 = 0;
    vec2d v1(1, 0);
    if (all_finite(m)) detail::eigen_2x2(m(0, 0), m(0, 1), m(1, 1), l1, l2, v1);
    vec3f e1 = (t1 * static_cast<float>(v1.x()) + t2 * static_cast<float>(v1.y())).normalized();
    if (!all_finite(e1)) e1 = t1;
    vec3f e2 = n.cross(e1);
    if (q) {
      code->normal = q->encode(n);
      code->axis = q->encode(e1);
      const vec3f n_exact = n;
      axes_from_codes(*q, code->normal, code->axis, n, e1, e2);
      // The cone was bounded about the exact mean normal; widen it by the quantisation error.
      if (nd.cone_angle < std::numbers::pi_v<float>)
        nd.cone_angle =
            std::min(std::numbers::pi_v<float>,
                     nd.cone_angle + std::acos(std::clamp(n.dot(n_exact), -1.0f, 1.0f)) + 1e-6f);
    }
    nd.normal = n;
    // Axis lengths before scaling.
    l1 = std::max(0.0, l1);
    l2 = std::max(0.0, l2);
    double a1 = opt.axis_rule == ellipse_axis_rule::eigenvalue ? l1 : std::sqrt(l1);
    double b1 = opt.axis_rule == ellipse_axis_rule::eigenvalue ? l2 : std::sqrt(l2);
    if (!(a1 > 1e-300) || !std::isfinite(a1)) {
      a1 = b1 = 1;  // zero variance: a circle, sized by the corners alone
    }
    b1 = std::max(b1, 1e-3 * a1);  // never a zero minor axis (collinear samples)
    double f2 = 0, r2 = 0;
    const vec3d c = nd.centre.template cast<double>(), E1 = e1.template cast<double>(),
                E2 = e2.template cast<double>();
    for_each_corner([&](const vec3f& corner) {
      const vec3d d = corner.template cast<double>() - c;
      const double x = d.dot(E1), y = d.dot(E2);
      f2 = std::max(f2, squared(x / a1) + squared(y / b1));
      r2 = std::max(r2, x * x + y * y);
    });
    // A hair more than f so float rounding of the stored axes never uncovers a corner.
    const double f = std::sqrt(f2) * (1 + 1e-5);
    double fa = f * a1, fb = f * b1;
    // Choice (ours): the bounding circle of the corners (radius r) also bounds them. The scaled
    // covariance ellipse wins when the corners are elongated, but on a round corner set it is
    // larger (a·b ≥ r²·a'/b'), and when the covariance is garbage (the paper's float sums far
    // from the origin) its major axis can reach 1000·r through the minor-axis floor and compound
    // level by level. Keep the ellipse only if its area is smaller and a ≤ 2r.
    const double rc = std::sqrt(r2) * (1 + 1e-5);
    // (Counted afterwards on the stored nodes: point_octree::is_circle.)
    const bool ellipse_wins = !opt.circle_guard || (fa * fb < rc * rc && fa <= 2 * rc);
    if (!ellipse_wins || !std::isfinite(fa) || !std::isfinite(fb)) fa = fb = rc;
    const auto a = static_cast<float>(fa), b = static_cast<float>(fb);
    nd.axis_u = e1 * a;
    nd.axis_v = e2 * b;
    if (q) {
      code->a = a;
      code->b = b;
    }
  }

  static float extent(const vec3f& u, const vec3f& v) {
    return std::sqrt(std::max(u.squaredNorm(), v.squaredNorm()));
  }

  /// Stage 1 (§3, Fig. 3): one linear pass over the node's samples — the octant of each about
  /// the split point p̄_c (the split rule), the children's sums, the sphere radius about p̄_c and
  /// the cone about n̄_c. Ranges longer than a block run block by block — in parallel near the
  /// root — and combine the blocks' sums in block order, so the tree does not depend on the
  /// thread count. `parts` gets the per-block sums when there is more than one block.
  pass_sums octant_pass(const input& inp, const vec3f& nbar, bool can_split, unsigned workers,
                        std::vector<pass_sums>& parts) {
    const std::uint32_t first = inp.first, count = inp.count;
    const vec3d m = inp.mean;
    const auto scan = [&](std::uint32_t lo, std::uint32_t hi, pass_sums& ps) {
      for (std::uint32_t k = lo; k < hi; ++k) {
        const vec3d p = in.positions[k].template cast<double>();
        ps.r2 = std::max(ps.r2, (p - m).squaredNorm());
        ps.min_dot = std::min(ps.min_dot, nbar.dot(in.normals[k]));
        if (!can_split) continue;
        const int o =
            (p.x() >= m.x() ? 1 : 0) | (p.y() >= m.y() ? 2 : 0) | (p.z() >= m.z() ? 4 : 0);
        oct[k] = static_cast<std::uint8_t>(o);
        ++ps.cnt[o];
        ps.psum[o] += p;
        ps.nsum[o] += in.normals[k].template cast<double>();
        if constexpr (A.colour)
          ps.csum[o] += vec3d(in.colours[k].r, in.colours[k].g, in.colours[k].b);
      }
    };
    const std::uint32_t blocks = (count + block - 1) / block;
    pass_sums all;
    if (blocks <= 1) {
      scan(first, first + count, all);
    } else {
      parts.resize(blocks);
      parallel_chunks(blocks, workers, 1, [&](std::size_t b0, std::size_t b1) {
        for (std::size_t b = b0; b < b1; ++b) {
          const auto [lo, hi] = block_range(first, count, b);
          scan(lo, hi, parts[b]);
        }
      });
      for (const auto& ps : parts) all += ps;
    }
    return all;
  }

  /// Stage 2 (§3): the node's representative sample — centre p̄_c, normal n̄_c, the normal cone
  /// from the pass's smallest cosine, the mean colour. Axes and radius come with the ellipse.
  /// (mean, colour sum, count, depth) rather than an input: the chunked build's top nodes hold
  /// more samples than an input's 32-bit count (builders/chunked_point_octree.hpp).
  static node node_centre_and_cone(local& L, std::uint32_t ni, const vec3d& mean,
                                   const vec3d& colour_sum, std::uint64_t count,
                                   std::uint32_t depth, const vec3f& nbar, bool normal_valid,
                                   float min_dot) {
    node nd{};
    nd.centre = mean.template cast<float>();
    nd.normal = nbar;
    nd.cone_angle = normal_valid ? std::acos(std::clamp(min_dot, -1.0f, 1.0f)) + 1e-6f
                                 : std::numbers::pi_v<float>;
    nd.cone_angle = std::min(nd.cone_angle, std::numbers::pi_v<float>);
    nd.depth = static_cast<std::uint8_t>(std::min<std::uint32_t>(depth, 255));
    if constexpr (A.colour) {
      const vec3d cavg = colour_sum / static_cast<double>(count);
      L.colours[ni] = {static_cast<std::uint8_t>(std::lround(cavg.x())),
                       static_cast<std::uint8_t>(std::lround(cavg.y())),
                       static_cast<std::uint8_t>(std::lround(cavg.z()))};
    }
    return nd;
  }

  /// Stage 3a (EQ 1–3, EQ 5–6): a leaf's covariance from its samples, its ellipse over the
  /// corners of their disks, its bounding sphere over the same disks.
  summary finish_leaf(local& L, std::uint32_t ni, node& nd, const input& inp, float radius,
                      bool normal_valid) {
    const std::uint32_t first = inp.first, count = inp.count;
    summary s;
    nd.leaf = 1;
    nd.first = first;
    nd.count = count;
    for (std::uint32_t k = first; k < first + count; ++k) add_sample(s, k);
    fit_ellipse(nd, q ? &L.codes[ni] : nullptr, s, normal_valid, [&](auto&& visit) {
      for (std::uint32_t k = first; k < first + count; ++k) {
        const vec3f &p = in.positions[k], &u = in.axis_u[k], &v = in.axis_v[k];
        visit(p + u + v);
        visit(p + u - v);
        visit(p - u + v);
        visit(p - u - v);
      }
    });
    for (std::uint32_t k = first; k < first + count; ++k) {
      radius = std::max(radius,
                        (in.positions[k] - nd.centre).norm() + extent(in.axis_u[k], in.axis_v[k]));
    }
    nd.radius = std::max(radius, extent(nd.axis_u, nd.axis_v)) * (1 + 1e-6f);
    L.nodes[ni] = nd;
    done.fetch_add(count, std::memory_order_relaxed);
    return s;
  }

  /// Stage 3b (§3, "divide S_c into the subsets S_i"): the samples scattered by octant (a
  /// counting sort), children contiguous in octant order; returns each octant's start.
  std::array<std::uint32_t, 8> scatter_by_octant(const input& inp, const pass_sums& all,
                                                 const std::vector<pass_sums>& parts,
                                                 unsigned workers) {
    const std::uint32_t first = inp.first, count = inp.count;
    std::array<std::uint32_t, 8> start{};
    std::uint32_t acc = first;
    for (int o = 0; o < 8; ++o) {
      start[static_cast<std::size_t>(o)] = acc;
      acc += all.cnt[static_cast<std::size_t>(o)];
    }
    // Where each block's samples of each octant go: the octant's start plus the counts of the
    // blocks before it.
    std::vector<std::array<std::uint32_t, 8>> at(std::max<std::size_t>(1, parts.size()));
    if (parts.empty()) {
      at[0] = start;
    } else {
      std::array<std::uint32_t, 8> next = start;
      for (std::size_t b = 0; b < parts.size(); ++b)
        for (std::size_t o = 0; o < 8; ++o) {
          at[b][o] = next[o];
          next[o] += parts[b].cnt[o];
        }
    }
    const auto scatter_all = [&](auto& v, auto& scratch) {
      scatter(v, scratch, first, count, at, workers);
    };
    scatter_all(in.positions, scratch3);
    scatter_all(in.normals, scratch3);
    scatter_all(in.axis_u, scratch3);
    scatter_all(in.axis_v, scratch3);
    if constexpr (A.colour) scatter_all(in.colours, scratch_rgb);
    if (in_codes) scatter_all(*in_codes, scratch_code);
    return start;
  }

  /// Stage 3c (Fig. 3, top down): the children's inputs, their averages from the pass's sums.
  static std::vector<input> child_inputs(const input& inp, const pass_sums& all,
                                         const std::array<std::uint32_t, 8>& start) {
    std::vector<input> kids;
    for (std::size_t o = 0; o < 8; ++o) {
      const auto c = all.cnt[o];
      if (c == 0) continue;
      kids.push_back({start[o], c, all.psum[o] / c, all.nsum[o], all.csum[o], inp.depth + 1});
    }
    return kids;
  }

  /// Stage 3d: the children's subtrees, as nodes first_child + j of L; their summaries, or
  /// nothing when cancelled.
  std::optional<std::vector<summary>> build_children(local& L, std::uint32_t first_child,
                                                     const std::vector<input>& kids, bool parallel,
                                                     unsigned workers, std::uint32_t count) {
    std::vector<summary> sums(kids.size());
    if (!(parallel && kids.size() > 1)) {
      for (std::size_t j = 0; j < kids.size(); ++j) {
        sums[j] = build(L, first_child + static_cast<std::uint32_t>(j), kids[j], false);
        // Large nodes only: a few dozen reports per subtree, not a clock read per node.
        if (parallel || (count >= 65536 && std::this_thread::get_id() == caller)) report();
      }
      return sums;
    }
    // Each child subtree in its own node array, spliced in below. `workers` threads take the
    // children largest first (the old one-thread-per-child oversubscribed 2 cores fourfold);
    // the calling thread reports progress meanwhile. Which thread builds a subtree does not
    // change it.
    std::vector<local> locals(kids.size());
    std::vector<std::size_t> order(kids.size());
    std::iota(order.begin(), order.end(), std::size_t{0});
    std::stable_sort(order.begin(), order.end(),
                     [&](std::size_t a, std::size_t b) { return kids[a].count > kids[b].count; });
    for (std::size_t j = 0; j < kids.size(); ++j) {
      reserve(locals[j], node_estimate(kids[j].count));
      locals[j].nodes.resize(1);
      if constexpr (A.colour) locals[j].colours.resize(1);
      if (q) locals[j].codes.resize(1);
    }
    // The subtrees as tasks on the pool (core/parallel.hpp), largest first. The calling thread
    // reports progress between the subtrees it builds and inside them (below); a pool thread
    // never calls the user's callback.
    std::vector<std::exception_ptr> errors(kids.size());
    parallel_tasks(order.size(), workers, [&](std::size_t i, unsigned) {
      const std::size_t j = order[i];
      try {
        if (!cancel.load(std::memory_order_relaxed)) sums[j] = build(locals[j], 0, kids[j], false);
      } catch (...) {
        errors[j] = std::current_exception();
        cancel.store(true);
      }
      if (std::this_thread::get_id() == caller) report();
    });
    for (const auto& e : errors)
      if (e) std::rethrow_exception(e);
    if (cancel.load(std::memory_order_relaxed)) return std::nullopt;
    splice(L, first_child, locals, workers);
    return sums;
  }

  /// Stage 4 (EQ 4, EQ 5–6, bottom up): an inner node's covariance merged from its children's,
  /// its ellipse over the corners of theirs, its bounding sphere over their spheres.
  summary finish_inner(local& L, std::uint32_t ni, node& nd, std::uint32_t first_child,
                       const std::vector<summary>& sums, float radius, bool normal_valid) {
    summary s;
    for (const auto& c : sums) add_summary(s, c);
    fit_ellipse(nd, q ? &L.codes[ni] : nullptr, s, normal_valid, [&](auto&& visit) {
      for (std::uint32_t j = 0; j < nd.count; ++j) {
        const node& c = L.nodes[first_child + j];
        visit(c.centre + c.axis_u + c.axis_v);
        visit(c.centre + c.axis_u - c.axis_v);
        visit(c.centre - c.axis_u + c.axis_v);
        visit(c.centre - c.axis_u - c.axis_v);
      }
    });
    for (std::uint32_t j = 0; j < nd.count; ++j) {
      const node& c = L.nodes[first_child + j];
      radius = std::max(radius, (c.centre - nd.centre).norm() + c.radius);
    }
    nd.radius = std::max(radius, extent(nd.axis_u, nd.axis_v)) * (1 + 1e-6f);
    L.nodes[ni] = nd;
    return s;
  }

  /// Builds node `ni` of L from `inp`, recursing into its children; returns its summary. The
  /// stages above, in order: the pass, the node's centre and cone, then either the leaf or the
  /// split into children and the inner node.
  summary build(local& L, std::uint32_t ni, const input& inp, bool parallel) {
    if (cancel.load(std::memory_order_relaxed)) return {};
    const std::uint32_t count = inp.count;
    const double nlen = inp.normal_sum.norm();
    const bool normal_valid = nlen > 1e-6 * count;
    const vec3f nbar =
        normal_valid ? vec3f((inp.normal_sum / nlen).template cast<float>()) : vec3f::UnitZ();
    const bool can_split = count > opt.leaf_size && inp.depth < opt.max_depth;
    const unsigned workers = parallel ? threads : 1;
    std::vector<pass_sums> parts;  // per block, when there is more than one
    const pass_sums all = octant_pass(inp, nbar, can_split, workers, parts);
    int nonempty = 0;
    for (auto c : all.cnt) nonempty += c > 0;

    node nd = node_centre_and_cone(L, ni, inp.mean, inp.colour_sum, inp.count, inp.depth, nbar,
                                   normal_valid, all.min_dot);
    const float radius = static_cast<float>(std::sqrt(all.r2));
    // A leaf also when every sample coincides: no split separates duplicates.
    if (!can_split || nonempty < 2) return finish_leaf(L, ni, nd, inp, radius, normal_valid);

    const auto start = scatter_by_octant(inp, all, parts, workers);
    const auto first_child = static_cast<std::uint32_t>(L.nodes.size());
    nd.leaf = 0;
    nd.first = first_child;
    nd.count = static_cast<std::uint32_t>(nonempty);
    L.nodes.resize(L.nodes.size() + static_cast<std::size_t>(nonempty));
    if constexpr (A.colour) L.colours.resize(L.nodes.size());
    if (q) L.codes.resize(L.nodes.size());

    const auto sums =
        build_children(L, first_child, child_inputs(inp, all, start), parallel, workers, count);
    if (!sums || cancel.load(std::memory_order_relaxed)) return {};
    return finish_inner(L, ni, nd, first_child, *sums, radius, normal_valid);
  }

  /// Room for the nodes of n samples without regrowing: ≈ 0.4 per sample at leaf size 8
  /// (Table 2; 0.25 was reserved before, so a sequential build regrew its node array once).
  std::size_t node_estimate(std::size_t n) const { return n * 5 / (opt.leaf_size + 2) + 16; }

  /// Room for n nodes in L (on huge pages when large).
  void reserve(local& L, std::size_t n) const {
    reserve_huge(L.nodes, n);
    if constexpr (A.colour) reserve_huge(L.colours, n);
    if (q) reserve_huge(L.codes, n);
  }

  /// Moves the subtrees of `subs` (each rooted at its index 0) into L: root j to `at + j`, the
  /// rest appended in order, child indices shifted. The layout is the sequential build's. The
  /// tail is sized once and its fresh pages are faulted in by all workers — first touch of new
  /// memory is most of a splice's cost on a VM — then each subtree is copied by one worker.
  void splice(local& L, std::uint32_t at, std::vector<local>& subs, unsigned workers) const {
    std::vector<std::uint32_t> base(subs.size());  // where subtree j's nodes 1.. go
    std::size_t total = L.nodes.size();
    for (std::size_t j = 0; j < subs.size(); ++j) {
      base[j] = static_cast<std::uint32_t>(total);
      total += subs[j].nodes.size() - 1;
    }
    resize_fresh(L.nodes, total, workers);
    if constexpr (A.colour) resize_fresh(L.colours, total, workers);
    if (q) resize_fresh(L.codes, total, workers);
    parallel_chunks(subs.size(), workers, 1, [&](std::size_t j0, std::size_t j1) {
      for (std::size_t j = j0; j < j1; ++j) {
        local& sub = subs[j];
        const std::uint32_t offset = base[j] - 1;  // local i ≥ 1 → i + offset
        const auto remap = [offset](node nd) {
          if (!nd.leaf) nd.first += offset;
          return nd;
        };
        const std::uint32_t root = at + static_cast<std::uint32_t>(j);
        L.nodes[root] = remap(sub.nodes[0]);
        std::transform(sub.nodes.begin() + 1, sub.nodes.end(), L.nodes.begin() + base[j], remap);
        if constexpr (A.colour) {
          L.colours[root] = sub.colours[0];
          std::copy(sub.colours.begin() + 1, sub.colours.end(), L.colours.begin() + base[j]);
        }
        if (q) {
          L.codes[root] = sub.codes[0];
          std::copy(sub.codes.begin() + 1, sub.codes.end(), L.codes.begin() + base[j]);
        }
        sub = {};
      }
    });
  }

  /// The whole build: validation, estimation (§4 end), quantisation (§5), the tree.
  template <attributes In>
  static point_octree<A> run(const point_set<In>& points, const point_octree_options& opt);

  /// Progress from the calling thread; a false answer cancels every task.
  void report() {
    if (!opt.progress || cancel.load()) return;
    const double frac =
        static_cast<double>(done.load()) / static_cast<double>(std::max<std::size_t>(1, in.size()));
    if (!opt.progress(0.1 + 0.9 * frac)) cancel.store(true);
  }
};

/// Quantises a sample's normal and major axis (§5) and re-derives its ellipse axes from the
/// codes, keeping the axis lengths.
template <attributes A>
void quantize_samples(point_set<A>& pts, const normal_quantizer& q,
                      std::vector<typename point_octree<A>::orientation_code>& codes,
                      unsigned threads) {
  resize_fresh(codes, pts.size(), threads);
  // In runs, each run's normals and axes through encode(span, span), which overlaps the
  // encoder's table loads (the same codes as one encode() each).
  constexpr std::size_t run = 128;
  parallel_for(pts.size(), threads, [&](std::size_t lo, std::size_t hi) {
    std::array<vec3f, run> major;
    std::array<float, run> major_length;
    std::array<std::uint32_t, run> normal_code, axis_code;
    for (std::size_t r = lo; r < hi; r += run) {
      const std::size_t m = std::min(run, hi - r);
      for (std::size_t k = 0; k < m; ++k) {
        const std::size_t i = r + k;
        const float a = pts.axis_u[i].norm();
        major_length[k] = a;
        major[k] = a > 0 ? vec3f(pts.axis_u[i] / a) : any_orthogonal(pts.normals[i]);
      }
      q.encode(std::span<const vec3f>(pts.normals.data() + r, m), std::span(normal_code.data(), m));
      q.encode(std::span<const vec3f>(major.data(), m), std::span(axis_code.data(), m));
      for (std::size_t k = 0; k < m; ++k) {
        const std::size_t i = r + k;
        const float a = major_length[k], b = pts.axis_v[i].norm();
        codes[i] = {normal_code[k], axis_code[k], a, b};
        vec3f n, e1, e2;
        axes_from_codes(q, codes[i].normal, codes[i].axis, n, e1, e2);
        pts.normals[i] = n;
        pts.axis_u[i] = e1 * a;
        pts.axis_v[i] = e2 * b;
      }
    }
  });
}

/// The working copy of a build (§4 end): the input's attributes, unit normals, and what it lacks
/// estimated from its k nearest neighbours. Only the first `keep` points are returned, estimated
/// among all of them: the chunked build passes a chunk followed by its halo, the neighbours
/// beyond the chunk's border (builders/chunked_point_octree.hpp).
template <attributes A, attributes In>
point_set<A> prepare_samples(const point_set<In>& points, const point_octree_options& opt,
                             unsigned threads, point_octree_build_stats& st,
                             std::size_t keep = std::numeric_limits<std::size_t>::max()) {
  const std::size_t n = points.size();
  point_set<A> work;
  work.origin = points.origin;
  const auto copy = [&](auto& to, const auto& from) {
    resize_fresh(to, n, threads);
    parallel_for(n, threads, [&](std::size_t lo, std::size_t hi) {
      std::copy(from.begin() + static_cast<std::ptrdiff_t>(lo),
                from.begin() + static_cast<std::ptrdiff_t>(hi),
                to.begin() + static_cast<std::ptrdiff_t>(lo));
    });
  };
  copy(work.positions, points.positions);
  if constexpr (In.colour) copy(work.colours, points.colours);
  estimation_options est_opt{
      .k_normals = opt.knn, .k_ellipses = opt.knn_ellipses, .threads = threads};
  // The estimation is the first tenth of the reported progress; a cancel there throws Cancelled.
  if (opt.progress && keep >= n) est_opt.progress = [&](double f) { return opt.progress(0.1 * f); };
  if (opt.viewpoint) {
    est_opt.orientation = normal_orientation::viewpoint;
    est_opt.viewpoint = vec3d(*opt.viewpoint - points.origin).template cast<float>();
  }
  if constexpr (In.normal) {
    copy(work.normals, points.normals);
    parallel_for(n, threads, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = lo; i < hi; ++i) {
        vec3f& v = work.normals[i];
        const float len = v.norm();
        if (len > 0 && std::isfinite(len)) v /= len;
      }
    });
    // A zero or non-finite normal is no normal: estimated from the positions, oriented by the
    // given ones around it (all of them when none is given, as for a bare cloud).
    const normal_repair r = fill_missing_normals(work.positions, work.normals, opt.knn, threads);
    st.normals_filled = r.missing;
    if (r.all_estimated) st.estimated_normals = true;
  } else if constexpr (!In.ellipse) {
    // Neither: both from one k-NN search.
    auto est = estimate_normals_and_ellipses(work.positions, est_opt);
    work.normals = std::move(est.normals);
    work.axis_u = std::move(est.axes.u);
    work.axis_v = std::move(est.axes.v);
    st.estimated_normals = st.estimated_ellipses = true;
  } else {
    work.normals = estimate_normals(work.positions, est_opt);
    st.estimated_normals = true;
  }
  if constexpr (In.ellipse) {
    copy(work.axis_u, points.axis_u);
    copy(work.axis_v, points.axis_v);
  } else if constexpr (In.normal) {
    auto axes = estimate_splat_ellipses(work.positions, work.normals, opt.knn_ellipses, threads);
    work.axis_u = std::move(axes.u);
    work.axis_v = std::move(axes.v);
    st.estimated_ellipses = true;
  }
  if (keep < n) {
    work.positions.resize(keep);
    work.normals.resize(keep);
    work.axis_u.resize(keep);
    work.axis_v.resize(keep);
    if constexpr (A.colour) work.colours.resize(keep);
  }
  return work;
}

template <attributes A>
template <attributes In>
point_octree<A> point_octree_builder<A>::run(const point_set<In>& points,
                                             const point_octree_options& opt) {
  using clock = std::chrono::steady_clock;
  const auto t0 = clock::now();
  if (points.empty()) throw InvalidArgument("build_point_octree: the input has no points");
  if (points.size() > std::numeric_limits<std::uint32_t>::max() / 2)
    throw InvalidArgument("build_point_octree: more than 2^31 points");
  if (opt.leaf_size < 1) throw InvalidArgument("build_point_octree: leaf_size must be at least 1");
  if (opt.knn < 3 || opt.knn_ellipses < 3)
    throw InvalidArgument("build_point_octree: knn and knn_ellipses must be at least 3");
  if (opt.normal_bits != 0 && (opt.normal_bits < 6 || opt.normal_bits > 24))
    throw InvalidArgument("build_point_octree: normal_bits must be 0 or 6..24");
  if (!all_finite(points.origin)) throw InvalidArgument("build_point_octree: origin is not finite");
  const unsigned threads = resolve_threads(opt.threads);
  const std::size_t n = points.size();
  {
    std::atomic<std::size_t> bad{n};  // the first non-finite position
    parallel_for(n, threads, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = lo; i < hi && i < bad.load(std::memory_order_relaxed); ++i)
        if (!all_finite(points.positions[i])) {
          std::size_t b = bad.load();
          while (i < b && !bad.compare_exchange_weak(b, i)) {
          }
          break;
        }
    });
    if (bad.load() < n)
      throw InvalidArgument("build_point_octree: position " + std::to_string(bad.load()) +
                            " is not finite");
  }

  point_octree<A> out;
  auto& st = out.stats_;
  st.input_points = points.size();
  const auto progress = [&](double f) {
    if (opt.progress && !opt.progress(f)) throw Cancelled("build_point_octree: cancelled");
  };
  progress(0);

  point_set<A> work = prepare_samples<A>(points, opt, threads, st);
  st.estimation_seconds = std::chrono::duration<double>(clock::now() - t0).count();
  progress(0.1);

  std::shared_ptr<const normal_quantizer> quant;
  std::vector<typename point_octree<A>::orientation_code> work_codes;
  if (opt.normal_bits > 0) {
    quant = normal_quantizer::shared(opt.normal_bits);
    quantize_samples(work, *quant, work_codes, threads);
  }
  out.normal_bits_ = opt.normal_bits;

  const auto t1 = clock::now();
  point_octree_builder<A> b(work, quant ? &work_codes : nullptr, opt, quant.get(), threads);
  local L;
  // A point-octree has ≈ 0.4 nodes per sample at leaf size 8 (paper, Table 2); reserving avoids
  // re-copying the node array while it grows.
  b.reserve(L, b.node_estimate(work.size()));
  L.nodes.resize(1);
  if constexpr (A.colour) L.colours.resize(1);
  if (quant) L.codes.resize(1);
  const bool parallel = threads > 1 && work.size() > 20000;
  b.build(L, 0, b.root_input(work, parallel ? threads : 1), parallel);
  if (b.cancel.load()) throw Cancelled("build_point_octree: cancelled");

  out.nodes_ = std::move(L.nodes);
  if constexpr (A.colour) out.node_colours_ = std::move(L.colours);
  out.node_codes_ = std::move(L.codes);
  // The build left the samples in leaf order.
  out.samples_ = std::move(work);
  out.sample_codes_ = std::move(work_codes);
  out.derive_selection(threads);
  st.tree_seconds = std::chrono::duration<double>(clock::now() - t1).count();
  st.circle_fallbacks = out.count_circles();
  st.nodes = out.nodes_.size();
  for (const auto& nd : out.nodes_) {
    st.leaves += nd.leaf;
    st.max_depth = std::max<std::size_t>(st.max_depth, nd.depth);
  }
  st.seconds = std::chrono::duration<double>(clock::now() - t0).count();
  st.has_timings = true;
  progress(1);
  return out;
}

}  // namespace detail

template <attributes In>
point_octree<point_octree_attributes(In)> build_point_octree(const point_set<In>& points,
                                                             const point_octree_options& opt) {
  return detail::point_octree_builder<point_octree_attributes(In)>::run(points, opt);
}

template <attributes A>
std::size_t point_octree<A>::memory_bytes() const {
  return nodes_.size() * sizeof(node) + (A.colour ? nodes_.size() * sizeof(rgb8) : 0) +
         samples_.size() * point_set<A>::bytes_per_point() +
         (node_codes_.size() + sample_codes_.size()) * sizeof(orientation_code) +
         selection_.size() * sizeof(selection_record);
}

template <attributes A>
bool point_octree<A>::equal(const point_octree& o) const {
  if (nodes_ != o.nodes_ || normal_bits_ != o.normal_bits_) return false;
  bool same = samples_.origin == o.samples_.origin && samples_.positions == o.samples_.positions &&
              samples_.normals == o.samples_.normals && samples_.axis_u == o.samples_.axis_u &&
              samples_.axis_v == o.samples_.axis_v && node_codes_ == o.node_codes_ &&
              sample_codes_ == o.sample_codes_;
  if constexpr (A.colour)
    same = same && samples_.colours == o.samples_.colours && node_colours_ == o.node_colours_;
  return same;
}

}  // namespace pbr_lod
