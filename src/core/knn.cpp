// pbr_lod — k-nearest neighbours through FLANN's exact single k-d tree (Muja & Lowe 2009,
// flann::KDTreeSingleIndex: median-free "middle split" tree, exact search with eps = 0 and
// unlimited checks). FLANN's C++ API is header-only; its headers call LZ4, hence the private
// PkgConfig::LZ4 link of the library (DEPENDENCIES.md gotcha 3).
#include "pbr_lod/core/knn.hpp"

#include <flann/flann.hpp>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <thread>

#include "knn_order.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {

namespace {

// Points per leaf of FLANN's k-d tree. Measured on a 1 M-point surface, k = 16, queries in
// Morton order, one core: 4 → 1.07 µs a query, 10 → 1.03, 20 → 1.00 (docs/estimation.md); small
// leaves cost a deeper tree and more index memory for nothing.
constexpr int leaf_size = 16;

/// Keeps the k best (distance, index) pairs in caller-owned arrays in knn_less order
/// (knn_order.hpp): ties decided by where the points are, the same in any subset that holds them
/// (the chunked build searches a chunk and its halo for the neighbours the whole input gives:
/// chunked_point_octree.hpp).
class sorted_result final : public flann::ResultSet<float> {
 public:
  sorted_result(std::size_t capacity, std::uint32_t* idx, float* dist, const float* coords)
      : capacity_(capacity), idx_(idx), dist_(dist), coords_(coords) {}
  sorted_result(const sorted_result&) = delete;
  sorted_result& operator=(const sorted_result&) = delete;
  ~sorted_result() override = default;

  [[nodiscard]] bool full() const override { return count_ == capacity_; }
  // FLANN only offers points with dist < worstDist(): one ulp more lets an equal distance with a
  // smaller key in, so ties are decided by the key, not by the tree's visiting order. Cached:
  // the tree asks for it at every node it visits.
  [[nodiscard]] float worstDist() const override { return worst_; }
  void addPoint(float dist, std::size_t index) override {
    if (detail::knn_insert(count_, capacity_, idx_, dist_, dist, static_cast<std::uint32_t>(index),
                           coords_) &&
        full())
      worst_ = std::nextafter(dist_[capacity_ - 1], std::numeric_limits<float>::infinity());
  }
  [[nodiscard]] std::size_t size() const { return count_; }

 private:
  std::size_t capacity_;
  std::size_t count_ = 0;
  std::uint32_t* idx_;
  float* dist_;
  const float* coords_;
  float worst_ = std::numeric_limits<float>::max();
};

}  // namespace

struct knn_index::impl {
  using index_type = flann::KDTreeSingleIndex<flann::L2_Simple<float>>;
  std::vector<float> coords;  // #P × 3, owned: FLANN's Matrix only points at it
  std::size_t n = 0;
  std::unique_ptr<index_type> index;
  // Exact search: unlimited checks, eps = 0. Ties resolved by sorted_result.
  flann::SearchParams params{flann::FLANN_CHECKS_UNLIMITED, 0.0f, true};

  /// The `want` nearest points to q into idx[0..want), dist2[0..want); returns how many.
  std::size_t query_into(const vec3f& q, std::size_t want, std::uint32_t* idx, float* dist2) const {
    sorted_result rs(want, idx, dist2, coords.data());
    const float qv[3] = {q.x(), q.y(), q.z()};
    index->findNeighbors(rs, qv, params);
    return rs.size();
  }
};

knn_index::knn_index(std::span<const vec3f> pts) : impl_(std::make_unique<impl>()) {
  if (pts.size() > std::numeric_limits<std::uint32_t>::max())
    throw InvalidArgument("knn_index: more than 2^32 - 1 points");
  impl_->n = pts.size();
  impl_->coords.resize(pts.size() * 3);
  for (std::size_t i = 0; i < pts.size(); ++i) {
    if (!all_finite(pts[i]))
      throw InvalidArgument("knn_index: point " + std::to_string(i) + " is not finite");
    for (int c = 0; c < 3; ++c) impl_->coords[3 * i + static_cast<std::size_t>(c)] = pts[i][c];
  }
  if (impl_->n == 0) return;
  const flann::Matrix<float> data(impl_->coords.data(), impl_->n, 3);
  impl_->index =
      std::make_unique<impl::index_type>(data, flann::KDTreeSingleIndexParams(leaf_size));
  impl_->index->buildIndex();
}

knn_index::~knn_index() = default;
knn_index::knn_index(knn_index&&) noexcept = default;
knn_index& knn_index::operator=(knn_index&&) noexcept = default;

std::size_t knn_index::size() const {
  return impl_ ? impl_->n : 0;
}

void knn_index::query(const vec3f& q, int k, std::vector<std::uint32_t>& idx,
                      std::vector<float>& dist2) const {
  const std::size_t want =
      (k <= 0 || !impl_ || !impl_->index) ? 0 : std::min<std::size_t>(std::size_t(k), impl_->n);
  idx.resize(want);
  dist2.resize(want);
  if (want == 0) return;
  const std::size_t found = impl_->query_into(q, want, idx.data(), dist2.data());
  idx.erase(idx.begin() + static_cast<std::ptrdiff_t>(found), idx.end());
  dist2.erase(dist2.begin() + static_cast<std::ptrdiff_t>(found), dist2.end());
}

std::size_t knn_index::query(const vec3f& q, std::size_t want, std::uint32_t* idx,
                             float* dist2) const {
  if (!impl_ || !impl_->index || want == 0) return 0;
  return impl_->query_into(q, std::min(want, impl_->n), idx, dist2);
}

float knn_index::nearest_distance(const vec3f& q) const {
  if (!impl_ || !impl_->index) return std::numeric_limits<float>::infinity();
  std::uint32_t i = 0;
  float d2 = std::numeric_limits<float>::infinity();
  sorted_result rs(1, &i, &d2, impl_->coords.data());
  const float qv[3] = {q.x(), q.y(), q.z()};
  impl_->index->findNeighbors(rs, qv, impl_->params);
  return rs.size() == 0 ? std::numeric_limits<float>::infinity() : std::sqrt(d2);
}

namespace {

/// Spreads the low 10 bits of v to every third bit (bit b → bit 3b).
std::uint32_t spread3(std::uint32_t v) {
  v &= 0x3ffu;
  v = (v | (v << 16)) & 0x030000ffu;
  v = (v | (v << 8)) & 0x0300f00fu;
  v = (v | (v << 4)) & 0x030c30c3u;
  v = (v | (v << 2)) & 0x09249249u;
  return v;
}

}  // namespace

std::vector<std::uint32_t> morton_order(std::span<const vec3f> pts) {
  if (pts.size() > std::numeric_limits<std::uint32_t>::max())
    throw InvalidArgument("morton_order: more than 2^32 - 1 points");
  const std::size_t n = pts.size();
  vec3f lo = vec3f::Constant(std::numeric_limits<float>::infinity()), hi = -lo;
  for (const auto& p : pts)
    if (all_finite(p)) {
      lo = lo.cwiseMin(p);
      hi = hi.cwiseMax(p);
    }
  const float extent = (hi - lo).maxCoeff();
  const float scale = extent > 0 && std::isfinite(extent) ? 1023.0f / extent : 0.0f;
  // 30-bit keys; non-finite points get 2^30, after every finite one.
  std::vector<std::uint32_t> key(n);
  for (std::size_t i = 0; i < n; ++i) {
    if (!all_finite(pts[i])) {
      key[i] = 1u << 30;
      continue;
    }
    std::uint32_t code = 0;
    for (int c = 0; c < 3; ++c) {
      const float t = std::clamp((pts[i][c] - lo[c]) * scale, 0.0f, 1023.0f);
      code |= spread3(static_cast<std::uint32_t>(t)) << c;
    }
    key[i] = code;
  }
  // LSD radix sort on 31 bits, three passes of 11 bits: stable, so ties stay in index order.
  std::vector<std::uint32_t> order(n), tmp(n);
  for (std::size_t i = 0; i < n; ++i) order[i] = static_cast<std::uint32_t>(i);
  for (int shift = 0; shift < 33; shift += 11) {
    std::vector<std::size_t> count((1u << 11) + 1, 0);
    for (const auto i : order) ++count[((key[i] >> shift) & 0x7ffu) + 1];
    for (std::size_t b = 1; b < count.size(); ++b) count[b] += count[b - 1];
    for (const auto i : order) tmp[count[(key[i] >> shift) & 0x7ffu]++] = i;
    order.swap(tmp);
  }
  return order;
}

knn_graph nearest_neighbour_graph(std::span<const vec3f> pts, int k, unsigned threads) {
  if (k < 1) throw InvalidArgument("nearest_neighbour_graph: k = " + std::to_string(k) + " < 1");
  for (std::size_t i = 0; i < pts.size(); ++i)
    if (!all_finite(pts[i]))
      throw InvalidArgument("nearest_neighbour_graph: point " + std::to_string(i) +
                            " is not finite");
  knn_graph g;
  const std::size_t n = pts.size();
  g.k = std::min<std::size_t>(std::size_t(k), n);
  if (n == 0) return g;
  threads = resolve_threads(threads);
  // The index is built over a Morton-sorted copy and queried in that order, rows written in
  // order: the tree's leaves, the queries and the rows then all walk memory forwards (on a 1 M-
  // point surface, 1.1 µs a query against 1.9 µs over the caller's order).
  const std::vector<std::uint32_t> order = morton_order(pts);
  std::vector<vec3f> sorted(n);
  for (std::size_t r = 0; r < n; ++r) sorted[r] = pts[order[r]];
  const knn_index index(sorted);
  std::vector<std::uint32_t> rows(n * g.k);
  std::vector<float> d2(n * g.k);
  // Pieces of ≥ 4096 queries: long enough to stay on one branch of the tree, many enough that a
  // slow core (a busy neighbour on a VM) does not hold the others up.
  detail::parallel_pieces(n, threads, 4 * threads, 4096, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t r = lo; r < hi; ++r) index.query(sorted[r], g.k, &rows[r * g.k], &d2[r * g.k]);
  });
  g.index.resize(n * g.k);
  g.dist2.resize(n * g.k);
  detail::parallel_pieces(n, threads, 4 * threads, 4096, [&](std::size_t lo, std::size_t hi) {
    for (std::size_t r = lo; r < hi; ++r) {
      const std::size_t i = order[r];
      for (std::size_t j = 0; j < g.k; ++j) {
        g.index[i * g.k + j] = order[rows[r * g.k + j]];
        g.dist2[i * g.k + j] = d2[r * g.k + j];
      }
    }
  });
  return g;
}

std::vector<float> knn_spacing(std::span<const vec3f> pts, int k, unsigned threads) {
  std::vector<float> out(pts.size(), 0.0f);
  if (pts.size() < 2 || k <= 0) return out;
  // k + 1 neighbours: the first is the point itself (or a duplicate at distance 0, which is
  // the same thing for a spacing). Only the last distance is kept, so no k-NN table is built:
  // the queries run in Morton order over a sorted copy, as nearest_neighbour_graph's do.
  const std::size_t want = std::min<std::size_t>(std::size_t(k) + 1, pts.size());
  const std::vector<std::uint32_t> order = morton_order(pts);
  std::vector<vec3f> sorted(pts.size());
  for (std::size_t r = 0; r < pts.size(); ++r) sorted[r] = pts[order[r]];
  const knn_index index(sorted);
  threads = resolve_threads(threads);
  detail::parallel_pieces(
      pts.size(), threads, 4 * threads, 4096, [&](std::size_t lo, std::size_t hi) {
        std::vector<std::uint32_t> idx(want);
        std::vector<float> d2(want);
        for (std::size_t r = lo; r < hi; ++r) {
          const std::size_t found = index.query(sorted[r], want, idx.data(), d2.data());
          out[order[r]] = found ? std::sqrt(d2[found - 1]) : 0.0f;
        }
      });
  return out;
}

}  // namespace pbr_lod
