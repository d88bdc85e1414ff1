// pbr_lod — the PCA octree's classification and quantisation.
//
// This work is based on:
//   A. Kalaiah, A. Varshney. Statistical Point Geometry. SGP 2003.
// What this file implements:
//   §3.1, Fig. 5  k-means over the nodes' σ_p, σ_n and σ_c (kmeans(): k-means++ seeding on a
//                 seeded sample, Lloyd iterations with an exact nearest-centre search (a k-d
//                 tree over the codebook), then every node's nearest entry), 12/12/6-bit
//                 indices; μ_p in 32 bits (10-11-11 over the node's octree cell), f_p and f_n as an
//                 axis (16-bit normal code, core/normal_quantization) and a rotation about it (8
//                 bits), μ_c 5-6-5, f_c as a 7-bit axis and a 3-bit rotation: 13 bytes a node, 17
//                 with colour (pca_quantise(), encode_node(), pca_decode_node()). The classes also
//                 hold the extents that bound generation (pca_feature), so the record keeps its
//                 13 bytes.
// Deviations (docs/pca-octree.md): σ_p is classified as log₂(σ_p / cell edge), so that one
// codebook serves every octree level with a bounded relative error (the paper clusters raw
// σ_p); the 10-bit axis of μ_p is the world axis least aligned with f_p³ (our cells are cubes,
// so "the direction of minimum width" is read as the direction where an error shows least).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <numeric>

#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/parallel.hpp"
#include "pca_octree_internal.hpp"

namespace pbr_lod::detail {

namespace {

std::uint64_t splitmix(std::uint64_t& s) {
  std::uint64_t z = (s += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}
double uniform01(std::uint64_t& s) {
  return static_cast<double>(splitmix(s) >> 11) * 0x1p-53;
}

using feature_d = Eigen::Matrix<double, pca_feature::RowsAtCompileTime, 1>;

const normal_quantizer& axis_quantizer() {
  static const auto q = normal_quantizer::shared(pca_layout::axis_bits);
  return *q;
}
const normal_quantizer& colour_axis_quantizer() {
  static const auto q = normal_quantizer::shared(pca_layout::colour_axis_bits);
  return *q;
}

/// The angle of x about axis z (unit) against the canonical tangent pair of z, in [0, π): the
/// sign of x does not matter (the Gaussians are symmetric).
std::uint32_t encode_angle(const vec3f& z, const vec3f& x, int bits) {
  const vec3f t1 = any_orthogonal(z), t2 = z.cross(t1);
  double a = std::atan2(static_cast<double>(x.dot(t2)), static_cast<double>(x.dot(t1)));
  if (a < 0) a += std::numbers::pi;
  if (a >= std::numbers::pi) a -= std::numbers::pi;
  const double steps = std::ldexp(1.0, bits);
  return static_cast<std::uint32_t>(std::lround(a / std::numbers::pi * steps)) &
         static_cast<std::uint32_t>(steps - 1);
}
/// The frame [x, z×x, z] from a decoded axis z and an angle code.
mat3f decode_frame(const vec3f& z, std::uint32_t code, int bits) {
  const vec3f t1 = any_orthogonal(z), t2 = z.cross(t1);
  const float a =
      static_cast<float>(static_cast<double>(code) * std::numbers::pi / std::ldexp(1.0, bits));
  const vec3f x = (std::cos(a) * t1 + std::sin(a) * t2).normalized();
  mat3f f;
  f.col(0) = x;
  f.col(1) = z.cross(x);
  f.col(2) = z;
  return f;
}

/// Exact nearest codebook entry of a point: the least squared distance (in float, summed over
/// the coordinates in order), ties to the lowest entry, through a k-d tree over the entries (median
/// splits on the widest axis, leaves of up to 8). A far side is skipped only when its slab distance
/// exceeds the best distance, which float rounding keeps exact (rounding is monotone), so the
/// answer is brute force's and does not depend on the tree's shape. Replaces a general k-NN index:
/// the codebooks are small and the queries many (every node of the tree).
class nearest_entry {
 public:
  explicit nearest_entry(const std::vector<pca_feature>& centres) : c_(centres) {
    order_.resize(centres.size());
    std::iota(order_.begin(), order_.end(), 0u);
    if (!centres.empty()) build(0, static_cast<std::uint32_t>(centres.size()));
  }
  [[nodiscard]] std::uint32_t operator()(const pca_feature& q) const {
    float best = std::numeric_limits<float>::infinity();
    std::uint32_t at = 0;
    if (!nodes_.empty()) search(0, q, best, at);
    return at;
  }

 private:
  static constexpr std::uint32_t leaf_entries = 8;
  struct kd_node {
    std::uint32_t begin, end;  // entries order_[begin, end) (leaf)
    int axis = -1;             // -1: leaf
    float split = 0;
    std::uint32_t left = 0, right = 0;
  };
  std::uint32_t build(std::uint32_t b, std::uint32_t e) {
    const auto id = static_cast<std::uint32_t>(nodes_.size());
    nodes_.push_back({b, e});
    if (e - b <= leaf_entries) return id;
    pca_feature lo = c_[order_[b]], hi = lo;
    for (std::uint32_t i = b; i < e; ++i) {
      lo = lo.cwiseMin(c_[order_[i]]);
      hi = hi.cwiseMax(c_[order_[i]]);
    }
    Eigen::Index axis = 0;
    if (!((hi - lo).maxCoeff(&axis) > 0)) return id;  // all equal
    const std::uint32_t m = b + (e - b) / 2;
    std::nth_element(order_.begin() + b, order_.begin() + m, order_.begin() + e,
                     [&](std::uint32_t u, std::uint32_t v) {
                       return c_[u][axis] < c_[v][axis] || (c_[u][axis] == c_[v][axis] && u < v);
                     });
    const float split = c_[order_[m]][axis];
    const std::uint32_t left = build(b, m), right = build(m, e);
    kd_node& nd = nodes_[id];
    nd.axis = static_cast<int>(axis);
    nd.split = split;
    nd.left = left;
    nd.right = right;
    return id;
  }
  void search(std::uint32_t n, const pca_feature& q, float& best, std::uint32_t& at) const {
    const kd_node& nd = nodes_[n];
    if (nd.axis < 0) {
      for (std::uint32_t i = nd.begin; i < nd.end; ++i) {
        const std::uint32_t k = order_[i];
        float d = 0;
        for (int j = 0; j < pca_feature::RowsAtCompileTime; ++j) {
          const float dj = q[j] - c_[k][j];
          d += dj * dj;
        }
        if (d < best || (d == best && k < at)) {
          best = d;
          at = k;
        }
      }
      return;
    }
    const float diff = q[nd.axis] - nd.split;
    search(diff < 0 ? nd.left : nd.right, q, best, at);
    if (diff * diff <= best) search(diff < 0 ? nd.right : nd.left, q, best, at);
  }

  const std::vector<pca_feature>& c_;
  std::vector<std::uint32_t> order_;
  std::vector<kd_node> nodes_;
};

/// k-means++ seeding (Arthur & Vassilvitskii 2007) of up to k centres from the sample xs: each
/// new centre drawn with probability proportional to the squared distance to the nearest
/// chosen one. The distances are kept in blocks of a fixed size whose sums are taken in block
/// order, so the draws do not depend on the number of threads.
std::vector<pca_feature> seed_centres(const std::vector<pca_feature>& xs, std::uint32_t k,
                                      std::uint64_t& rng, unsigned threads) {
  const std::size_t s = xs.size();
  constexpr std::size_t block = 2048;
  const std::size_t blocks = (s + block - 1) / block;
  std::vector<double> block_sum(blocks);
  std::vector<feature_d> x(s);
  for (std::size_t i = 0; i < s; ++i) x[i] = xs[i].cast<double>();
  std::vector<pca_feature> centres;
  centres.reserve(k);
  std::vector<double> d2(s, std::numeric_limits<double>::infinity());
  std::size_t next =
      std::min(s - 1, static_cast<std::size_t>(uniform01(rng) * static_cast<double>(s)));
  while (true) {
    centres.push_back(xs[next]);
    const feature_d cx = x[next];
    parallel_tasks(blocks, threads, [&](std::size_t b, unsigned) {
      double sum = 0;
      for (std::size_t i = b * block; i < std::min(s, (b + 1) * block); ++i) {
        d2[i] = std::min(d2[i], (x[i] - cx).squaredNorm());
        sum += d2[i];
      }
      block_sum[b] = sum;
    });
    if (centres.size() >= k) break;
    double total = 0;
    for (const double v : block_sum) total += v;
    if (!(total > 0)) break;  // every sample is a centre already
    const double r = uniform01(rng) * total;
    // The block holding the draw, then the sample within it (or, after rounding, later on).
    double acc = 0;
    std::size_t b = 0;
    while (b + 1 < blocks && acc + block_sum[b] <= r) acc += block_sum[b++];
    next = s;
    for (std::size_t i = b * block; i < s; ++i) {
      acc += d2[i];
      if (acc > r && d2[i] > 0) {
        next = i;
        break;
      }
    }
    if (next == s)  // rounding at the end of the scan: the last sample not yet a centre
      for (std::size_t i = s; i-- > 0;)
        if (d2[i] > 0) {
          next = i;
          break;
        }
  }
  return centres;
}

/// §3.1 classification: k-means of x into at most k entries (fewer when x has fewer distinct
/// values). Writes every point's entry to assign. Deterministic for a given seed, whatever the
/// thread count: assignments are computed per point in parallel, sums sequentially.
double angle_deg(const vec3f& a, const vec3f& b) {
  return std::acos(std::clamp(static_cast<double>(a.normalized().dot(b.normalized())), -1.0, 1.0)) *
         180 / std::numbers::pi;
}
/// Angle between two axes whose sign does not matter.
double axis_angle_deg(const vec3f& a, const vec3f& b) {
  return std::acos(
             std::min(std::abs(static_cast<double>(a.normalized().dot(b.normalized()))), 1.0)) *
         180 / std::numbers::pi;
}

/// What quantisation changed in a run of nodes (maxima, and sums for the means).
struct quantise_errors {
  double max_mean_cell = 0, max_axis_deg = 0, max_normal_axis_deg = 0;
  double sum_sigma_p = 0, sum_sigma_n = 0;
  void add(const pca_node& a, const pca_node& b) {
    max_mean_cell = std::max(
        max_mean_cell, static_cast<double>((a.mean - b.mean).cwiseAbs().maxCoeff()) / a.cell_size);
    for (int k = 0; k < 3; ++k)
      max_axis_deg = std::max(max_axis_deg, axis_angle_deg(a.frame.col(k), b.frame.col(k)));
    max_normal_axis_deg =
        std::max(max_normal_axis_deg, angle_deg(a.normal_frame.col(2), b.normal_frame.col(2)));
    sum_sigma_p += static_cast<double>((a.sigma - b.sigma).cwiseAbs().maxCoeff() / a.sigma.x());
    sum_sigma_n += static_cast<double>((a.normal_sigma - b.normal_sigma).cwiseAbs().maxCoeff());
  }
  void add(const quantise_errors& o) {
    max_mean_cell = std::max(max_mean_cell, o.max_mean_cell);
    max_axis_deg = std::max(max_axis_deg, o.max_axis_deg);
    max_normal_axis_deg = std::max(max_normal_axis_deg, o.max_normal_axis_deg);
    sum_sigma_p += o.sum_sigma_p;
    sum_sigma_n += o.sum_sigma_n;
  }
};

}  // namespace

std::vector<std::uint32_t> pca_kmeans_picks(std::size_t n, const pca_octree_options& o,
                                            std::uint64_t stream, std::uint64_t& rng) {
  rng = o.kmeans_seed * 0x2545F4914F6CDD1Dull + stream;
  std::vector<std::uint32_t> pick(n);
  std::iota(pick.begin(), pick.end(), 0u);
  const std::size_t s = std::min<std::size_t>(n, o.kmeans_sample);
  if (s < n) {
    for (std::size_t i = 0; i < s; ++i) {
      const std::size_t j =
          i + static_cast<std::size_t>(uniform01(rng) * static_cast<double>(n - i));
      std::swap(pick[i], pick[std::min(j, n - 1)]);
    }
    pick.resize(s);
    std::sort(pick.begin(), pick.end());
  }
  return pick;
}

std::vector<pca_feature> pca_kmeans_train(const std::vector<pca_feature>& xs, std::uint32_t k,
                                          const pca_octree_options& o, std::uint64_t& rng,
                                          unsigned threads) {
  const std::size_t s = xs.size();
  std::vector<pca_feature> centres = seed_centres(xs, k, rng, threads);
  std::vector<std::uint32_t> a, prev;
  for (std::uint32_t it = 0; it < o.kmeans_iterations; ++it) {
    const nearest_entry index(centres);
    a.resize(s);
    parallel_pieces(s, threads, 8 * threads, 2048, [&](std::size_t lo, std::size_t hi) {
      for (std::size_t i = lo; i < hi; ++i) a[i] = index(xs[i]);
    });
    if (a == prev) break;
    std::vector<feature_d> sum(centres.size(), feature_d::Zero());
    std::vector<std::size_t> cnt(centres.size(), 0);
    for (std::size_t i = 0; i < s; ++i) {
      sum[a[i]] += xs[i].cast<double>();
      ++cnt[a[i]];
    }
    for (std::size_t c = 0; c < centres.size(); ++c)
      if (cnt[c] > 0) centres[c] = (sum[c] / static_cast<double>(cnt[c])).cast<float>();
    prev.swap(a);
  }
  return centres;
}

void pca_features(const pca_data& d, std::size_t i, pca_feature& fp, pca_feature& fn,
                  pca_feature* fc) {
  const pca_node& nd = d.nodes[i];
  const auto octaves = [&](float v) {
    return static_cast<float>(std::log2(std::max(static_cast<double>(v) / nd.cell_size, 0x1p-60)));
  };
  for (int k = 0; k < 3; ++k) {
    fp[k] = octaves(nd.sigma[k]);
    fp[3 + k] = octaves(nd.extent[k]);
  }
  fn.setZero();
  fn.head<2>() = nd.normal_sigma;
  fn[2] = nd.normal_extent;
  if (fc != nullptr) {
    fc->setZero();
    fc->head<3>() = d.colours[i].sigma;
    (*fc)[3] = d.colours[i].extent;
  }
}

std::array<unsigned, 3> pca_mean_bits(const vec3f& f3) {
  Eigen::Index least = 0;
  f3.cwiseAbs().minCoeff(&least);
  std::array<unsigned, 3> b{11, 11, 11};
  b[static_cast<std::size_t>(least)] = 10;
  return b;
}

void pca_decode_node(const pca_data& d, std::uint32_t i, pca_node& nd, pca_colour* colour) {
  const auto& r = d.records[i];
  using L = pca_layout;
  const normal_quantizer& q = axis_quantizer();
  const vec3f f3 = q.decode(get_bits(r, L::fp_axis, L::axis_bits));
  nd.frame = decode_frame(f3, get_bits(r, L::fp_angle, L::angle_bits), L::angle_bits);
  const vec3f z = q.decode(get_bits(r, L::fn_axis, L::axis_bits));
  nd.normal_frame = decode_frame(z, get_bits(r, L::fn_angle, L::angle_bits), L::angle_bits);
  // σ_p from its class: cell edge · 2^feature, floored (§3).
  const pca_feature& fp = d.codebook_p[get_bits(r, L::sp, 12)];
  const auto length = [&](float octaves) {
    return static_cast<float>(
        std::max(nd.cell_size * std::exp2(static_cast<double>(octaves)), 1e-15));
  };
  for (int k = 0; k < 3; ++k) {
    nd.sigma[k] = length(fp[k]);
    nd.extent[k] = length(fp[3 + k]);
  }
  const pca_feature& fn = d.codebook_n[get_bits(r, L::sn, 12)];
  nd.normal_sigma = fn.head<2>().cwiseMax(0.0f);
  nd.normal_extent = std::max(0.0f, fn[2]);
  // μ_p over the cell, the 10-bit axis from the decoded f_p³.
  const auto bits = pca_mean_bits(f3);
  unsigned pos = L::mu;
  for (int k = 0; k < 3; ++k) {
    const unsigned b = bits[static_cast<std::size_t>(k)];
    const std::uint32_t v = get_bits(r, pos, b);
    pos += b;
    nd.mean[k] = static_cast<float>(nd.cell_min[k] + (static_cast<double>(v) + 0.5) * nd.cell_size /
                                                         std::ldexp(1.0, b));
  }
  if (colour == nullptr) return;
  const std::uint32_t c = d.colour_records[i];
  const auto field = [&](unsigned at, unsigned bits_) { return (c >> at) & ((1u << bits_) - 1); };
  const pca_feature& fc = d.codebook_c[field(L::sc, 6)];
  colour->sigma = fc.head<3>().cwiseMax(0.0f);
  colour->extent = std::max(0.0f, fc[3]);
  const std::uint32_t m = field(L::muc, 16);
  colour->mean =
      vec3f(static_cast<float>(m >> 11) / 31.0f, static_cast<float>((m >> 5) & 63u) / 63.0f,
            static_cast<float>(m & 31u) / 31.0f);
  const vec3f cz = colour_axis_quantizer().decode(field(L::fc_axis, L::colour_axis_bits));
  colour->frame = decode_frame(cz, field(L::fc_angle, L::colour_angle_bits), L::colour_angle_bits);
}

namespace {

void encode_node(pca_data& d, std::uint32_t i, std::uint32_t sp, std::uint32_t sn) {
  using L = pca_layout;
  const pca_node& nd = d.nodes[i];
  std::array<std::uint8_t, 13> r{};
  const normal_quantizer& q = axis_quantizer();
  put_bits(r, L::sp, sp, 12);
  put_bits(r, L::sn, sn, 12);
  const std::uint32_t c3 = q.encode(nd.frame.col(2));
  const vec3f f3 = q.decode(c3);
  put_bits(r, L::fp_axis, c3, L::axis_bits);
  put_bits(r, L::fp_angle, encode_angle(f3, nd.frame.col(0), L::angle_bits), L::angle_bits);
  const std::uint32_t cz = q.encode(nd.normal_frame.col(2));
  put_bits(r, L::fn_axis, cz, L::axis_bits);
  put_bits(r, L::fn_angle, encode_angle(q.decode(cz), nd.normal_frame.col(0), L::angle_bits),
           L::angle_bits);
  const auto bits = pca_mean_bits(f3);
  unsigned pos = L::mu;
  for (int k = 0; k < 3; ++k) {
    const unsigned b = bits[static_cast<std::size_t>(k)];
    const double steps = std::ldexp(1.0, b);
    const double t = (static_cast<double>(nd.mean[k]) - nd.cell_min[k]) / nd.cell_size * steps;
    const auto v = static_cast<std::uint32_t>(std::clamp(std::floor(t), 0.0, steps - 1));
    put_bits(r, pos, v, b);
    pos += b;
  }
  d.records[i] = r;
}

std::uint32_t encode_colour(const pca_colour& c, std::uint32_t sc) {
  using L = pca_layout;
  const auto level = [](float v, int max) {
    return static_cast<std::uint32_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * max));
  };
  const std::uint32_t m =
      level(c.mean.x(), 31) << 11 | level(c.mean.y(), 63) << 5 | level(c.mean.z(), 31);
  const normal_quantizer& q = colour_axis_quantizer();
  const std::uint32_t axis = q.encode(c.frame.col(2));
  const std::uint32_t angle = encode_angle(q.decode(axis), c.frame.col(0), L::colour_angle_bits);
  return sc << L::sc | m << L::muc | axis << L::fc_axis | angle << L::fc_angle;
}

}  // namespace

void pca_quantise(pca_data& d, const pca_octree_options& o, unsigned threads) {
  const auto t0 = std::chrono::steady_clock::now();
  const std::size_t n = d.nodes.size();
  const bool colour = !d.colours.empty();
  std::vector<pca_feature> fp(n), fn(n), fc(colour ? n : 0);
  for (std::size_t i = 0; i < n; ++i) pca_features(d, i, fp[i], fn[i], colour ? &fc[i] : nullptr);
  // k-means on a sample of each feature (its own random stream per codebook).
  const auto codebook = [&](const std::vector<pca_feature>& x, std::uint32_t k,
                            std::uint64_t stream) {
    std::uint64_t rng = 0;
    const std::vector<std::uint32_t> pick = pca_kmeans_picks(n, o, stream, rng);
    std::vector<pca_feature> xs(pick.size());
    for (std::size_t i = 0; i < pick.size(); ++i) xs[i] = x[pick[i]];
    return pca_kmeans_train(xs, k, o, rng, threads);
  };
  d.codebook_p = codebook(fp, o.position_codebook, 1);
  d.codebook_n = codebook(fn, o.normal_codebook, 2);
  if (colour) d.codebook_c = codebook(fc, o.colour_codebook, 3);
  d.stats.kmeans_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  pca_encode(d, threads);
}

void pca_encode(pca_data& d, unsigned threads) {
  const auto t1 = std::chrono::steady_clock::now();
  const std::size_t n = d.nodes.size();
  const bool colour = !d.colours.empty();
  const nearest_entry near_p(d.codebook_p), near_n(d.codebook_n), near_c(d.codebook_c);
  d.records.assign(n, {});
  if (colour) d.colour_records.assign(n, 0);
  constexpr std::size_t block = 4096;
  std::vector<quantise_errors> errors((n + block - 1) / block);
  parallel_tasks(errors.size(), threads, [&](std::size_t b, unsigned) {
    for (std::size_t i = b * block; i < std::min(n, (b + 1) * block); ++i) {
      const auto id = static_cast<std::uint32_t>(i);
      const pca_node before = d.nodes[i];
      pca_feature fp, fn, fc;
      pca_features(d, i, fp, fn, colour ? &fc : nullptr);
      encode_node(d, id, near_p(fp), near_n(fn));
      if (colour) d.colour_records[i] = encode_colour(d.colours[i], near_c(fc));
      pca_decode_node(d, id, d.nodes[i], colour ? &d.colours[i] : nullptr);
      errors[b].add(before, d.nodes[i]);
    }
  });
  quantise_errors e;
  for (const auto& b : errors) e.add(b);
  auto& st = d.stats;
  st.max_mean_error_cell = e.max_mean_cell;
  st.max_axis_error_deg = e.max_axis_deg;
  st.max_normal_axis_error_deg = e.max_normal_axis_deg;
  st.mean_sigma_p_error = e.sum_sigma_p / static_cast<double>(n);
  st.mean_sigma_n_error_deg = e.sum_sigma_n / static_cast<double>(n) * 180 / std::numbers::pi;
  st.quantise_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
}

}  // namespace pbr_lod::detail
