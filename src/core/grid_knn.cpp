// pbr_lod — all-points k-NN on a uniform grid (grid_knn.hpp).
#include "pbr_lod/core/grid_knn.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include <string>

#include "knn_order.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace {

constexpr int axis_bits = 21;  // a cell key: three 21-bit coordinates
constexpr std::int64_t axis_cells = std::int64_t{1} << axis_bits;

std::uint64_t cell_key(std::int64_t x, std::int64_t y, std::int64_t z) {
  return std::uint64_t(x) | std::uint64_t(y) << axis_bits | std::uint64_t(z) << (2 * axis_bits);
}

/// The cell of coordinate v along an axis of `cells` cells of size h from lo.
std::int64_t cell_index(double v, double lo, double h, std::int64_t cells) {
  return std::clamp<std::int64_t>(static_cast<std::int64_t>(std::floor((v - lo) / h)), 0,
                                  cells - 1);
}

/// The cells: points grouped by cell, and an open-addressing table from a cell's key to its
/// range of `order`.
struct grid {
  vec3d lo;
  double h = 1;
  std::array<std::int64_t, 3> dims{};
  std::vector<std::uint32_t> order;  // point indices, grouped by cell
  struct slot {
    std::uint64_t key = ~std::uint64_t{0};
    std::uint32_t begin = 0, end = 0;
  };
  std::vector<slot> table;
  std::uint64_t mask = 0;
  int shift = 60;  // 64 − log2(table size)

  /// A key's first slot: the top bits of a multiplicative (Fibonacci) hash; the low bits of the
  /// product would depend on x alone.
  [[nodiscard]] std::uint64_t home(std::uint64_t key) const {
    return (key * 0x9e3779b97f4a7c15ull) >> shift;
  }

  [[nodiscard]] std::array<std::int64_t, 3> cell_of(const vec3f& p) const {
    std::array<std::int64_t, 3> c{};
    for (int a = 0; a < 3; ++a) c[a] = cell_index(p[a], lo[a], h, dims[a]);
    return c;
  }
  [[nodiscard]] const slot* find(std::uint64_t key) const {
    for (std::uint64_t i = home(key);; i = (i + 1) & mask) {
      const slot& s = table[i];
      if (s.key == key) return &s;
      if (s.key == ~std::uint64_t{0}) return nullptr;
    }
  }
};

/// Occupied cells of a cell size h over a sample of the points (every step-th).
std::size_t occupied(std::span<const vec3f> pts, const vec3d& lo, double h, std::size_t step) {
  std::vector<std::uint64_t> keys;
  keys.reserve(pts.size() / step + 1);
  for (std::size_t i = 0; i < pts.size(); i += step) {
    std::int64_t c[3];
    for (int a = 0; a < 3; ++a) c[a] = cell_index(pts[i][a], lo[a], h, axis_cells);
    keys.push_back(cell_key(c[0], c[1], c[2]));
  }
  std::sort(keys.begin(), keys.end());
  return static_cast<std::size_t>(std::unique(keys.begin(), keys.end()) - keys.begin());
}

/// A cell size giving about `per_cell` points per occupied cell. Scans are surfaces, where the
/// points per cell go as h², so the size is corrected twice from a sample's occupancy.
double cell_size(std::span<const vec3f> pts, const vec3d& lo, const vec3d& ext, double per_cell) {
  const std::size_t n = pts.size();
  const double largest = std::max({ext.x(), ext.y(), ext.z()});
  if (!(largest > 0)) return 1;  // one point, or all coincident
  // Never so small that an axis needs more than 2^21 cells.
  const double floor_h = largest / double(axis_cells - 2);
  const std::size_t sample = std::min<std::size_t>(n, 65536);
  const std::size_t step = std::max<std::size_t>(1, n / sample);
  const double m = double((n + step - 1) / step);
  // Start from a volume filled evenly, then correct for the surface.
  const double vol =
      std::max(ext.x(), floor_h) * std::max(ext.y(), floor_h) * std::max(ext.z(), floor_h);
  double h = std::max(floor_h, std::cbrt(vol * per_cell / double(n)));
  // The size giving the sample `per_cell` points per cell, then scaled to the whole set's
  // density (on a surface, spacing goes as 1/√points).
  for (int it = 0; it < 3; ++it) {
    const double have = m / double(occupied(pts, lo, h, step));  // sample points per cell
    h = std::max(floor_h, h * std::sqrt(per_cell / have));
  }
  return std::max(floor_h, h * std::sqrt(m / double(n)));
}

grid make_grid(std::span<const vec3f> pts, int k) {
  grid g;
  vec3d lo = vec3d::Constant(std::numeric_limits<double>::max()), hi = -lo;
  for (const vec3f& p : pts) {
    lo = lo.cwiseMin(p.cast<double>());
    hi = hi.cwiseMax(p.cast<double>());
  }
  g.lo = lo;
  const vec3d ext = hi - lo;
  g.h = cell_size(pts, lo, ext, std::max(2.0, k / 2.0));
  for (int a = 0; a < 3; ++a)
    g.dims[a] =
        std::clamp<std::int64_t>(static_cast<std::int64_t>(ext[a] / g.h) + 1, 1, axis_cells - 1);
  const std::size_t n = pts.size();
  std::vector<std::pair<std::uint64_t, std::uint32_t>> keyed(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto c = g.cell_of(pts[i]);
    keyed[i] = {cell_key(c[0], c[1], c[2]), static_cast<std::uint32_t>(i)};
  }
  std::sort(keyed.begin(), keyed.end());
  g.order.resize(n);
  std::size_t cells = 0;
  for (std::size_t i = 0; i < n; ++i) {
    g.order[i] = keyed[i].second;
    cells += i == 0 || keyed[i].first != keyed[i - 1].first;
  }
  std::size_t cap = 16;
  int bits = 4;
  for (; cap < 2 * cells; cap *= 2) ++bits;
  g.table.assign(cap, {});
  g.mask = cap - 1;
  g.shift = 64 - bits;
  for (std::size_t i = 0; i < n;) {
    std::size_t j = i;
    while (j < n && keyed[j].first == keyed[i].first) ++j;
    const std::uint64_t key = keyed[i].first;
    std::uint64_t s = g.home(key);
    while (g.table[s].key != ~std::uint64_t{0}) s = (s + 1) & g.mask;
    g.table[s] = {key, static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j)};
    i = j;
  }
  return g;
}

/// The k best (distance, index) of one query, in the k-d tree's order (knn_order.hpp).
class best_k {
 public:
  best_k(std::size_t k, std::uint32_t* idx, const vec3f* pts)
      : k_(k), idx_(idx), coords_(reinterpret_cast<const float*>(pts)) {
    static_assert(sizeof(vec3f) == 3 * sizeof(float));
    dist_.resize(k);
  }
  void reset() { count_ = 0; }
  void offer(float d, std::uint32_t id) {
    (void)detail::knn_insert(count_, k_, idx_, dist_.data(), d, id, coords_);
  }
  [[nodiscard]] bool full() const { return count_ == k_; }
  [[nodiscard]] float worst() const { return dist_[k_ - 1]; }
  void retarget(std::uint32_t* idx) { idx_ = idx; }

 private:
  std::size_t k_, count_ = 0;
  std::uint32_t* idx_;
  const float* coords_;
  std::vector<float> dist_;
};

/// FLANN's L2_Simple: (q − p)² summed in float, x then y then z.
float distance2(const vec3f& q, const vec3f& p) {
  float r = 0;
  for (int a = 0; a < 3; ++a) {
    const float d = q[a] - p[a];
    r += d * d;
  }
  return r;
}

/// Shells of cells a query searches before it hands over to the k-d tree: a point whose k
/// nearest lie beyond 3 cells (an outlier, a sparse cluster) is not what the grid is for.
constexpr std::int64_t max_shells = 3;

/// Whether the grid found the k nearest of pts[i] (false: hand over, best then holds garbage).
bool query(const grid& g, std::span<const vec3f> pts, std::size_t i, best_k& best) {
  const vec3f& q = pts[i];
  const auto c = g.cell_of(q);
  const auto visit = [&](std::int64_t x, std::int64_t y, std::int64_t z) {
    if (x < 0 || y < 0 || z < 0 || x >= g.dims[0] || y >= g.dims[1] || z >= g.dims[2]) return;
    const grid::slot* s = g.find(cell_key(x, y, z));
    if (s == nullptr) return;
    for (std::uint32_t o = s->begin; o < s->end; ++o) {
      const std::uint32_t j = g.order[o];
      best.offer(distance2(q, pts[j]), j);
    }
  };
  // A point outside the block of cells within r of c is at least this far from q; the margin
  // covers rounding in the cells' bounds and in the float distances.
  const double slack = 1e-5 * g.h;
  const std::int64_t most = std::max({g.dims[0], g.dims[1], g.dims[2]});
  for (std::int64_t r = 0;; ++r) {
    for (std::int64_t z = c[2] - r; z <= c[2] + r; ++z)
      for (std::int64_t y = c[1] - r; y <= c[1] + r; ++y) {
        const bool face = z == c[2] - r || z == c[2] + r || y == c[1] - r || y == c[1] + r;
        if (face) {
          for (std::int64_t x = c[0] - r; x <= c[0] + r; ++x) visit(x, y, z);
        } else {
          visit(c[0] - r, y, z);
          if (r > 0) visit(c[0] + r, y, z);
        }
      }
    if (r >= most) return true;  // every cell visited
    if (best.full()) {
      double gap = std::numeric_limits<double>::infinity();
      for (int a = 0; a < 3; ++a) {
        const double lo = g.lo[a] + double(c[a] - r) * g.h;
        const double hi = g.lo[a] + double(c[a] + r + 1) * g.h;
        gap = std::min({gap, double(q[a]) - lo, hi - double(q[a])});
      }
      gap -= slack;
      if (gap > 0 && double(best.worst()) * (1 + 1e-6) < gap * gap) return true;
    }
    if (r >= max_shells) return false;
  }
}

}  // namespace

std::vector<std::uint32_t> grid_knn_table(std::span<const vec3f> pts, int k, unsigned threads) {
  const std::size_t n = pts.size(), kk = static_cast<std::size_t>(k);
  if (k < 1 || kk > n)
    throw InvalidArgument("grid_knn_table: k = " + std::to_string(k) + " outside 1.." +
                          std::to_string(n));
  if (n > std::numeric_limits<std::uint32_t>::max())
    throw InvalidArgument("grid_knn_table: more than 2^32 - 1 points");
  for (std::size_t i = 0; i < n; ++i)
    if (!all_finite(pts[i]))
      throw InvalidArgument("grid_knn_table: point " + std::to_string(i) + " is not finite");
  std::vector<std::uint32_t> table(n * kk);
  const grid g = make_grid(pts, k);
  threads = resolve_threads(threads);
  // The queries the grid hands over, answered afterwards by FLANN's tree (built only if any).
  std::vector<std::vector<std::uint32_t>> handed(threads);
  const std::size_t pieces = detail::piece_count(n, threads, 4 * std::size_t{threads}, 4096);
  detail::parallel_tasks(pieces, threads, [&](std::size_t t, unsigned worker) {
    const auto [begin, end] = detail::piece_range(n, pieces, t);
    best_k best(kk, nullptr, pts.data());
    for (std::size_t i = begin; i < end; ++i) {
      best.reset();
      best.retarget(&table[i * kk]);
      if (!query(g, pts, i, best)) handed[worker].push_back(static_cast<std::uint32_t>(i));
    }
  });
  std::vector<std::uint32_t> rest;
  for (const auto& h : handed) rest.insert(rest.end(), h.begin(), h.end());
  if (!rest.empty()) {
    const knn_index index(pts);
    detail::parallel_pieces(rest.size(), threads, 4 * std::size_t{threads}, 256,
                            [&](std::size_t begin, std::size_t end) {
                              std::vector<float> d2(kk);
                              for (std::size_t r = begin; r < end; ++r)
                                (void)index.query(pts[rest[r]], kk, &table[rest[r] * kk],
                                                  d2.data());
                            });
  }
  return table;
}

}  // namespace pbr_lod
