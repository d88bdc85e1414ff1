// pbr_lod — quantised normals (Pajarola 2003, §5 and Fig. 9). Layout and error bound are
// described in include/pbr_lod/core/normal_quantization.hpp and docs/normal-quantization.md.
#include "pbr_lod/core/normal_quantization.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <mutex>
#include <numbers>
#include <string>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod {

namespace {

constexpr double half_pi = std::numbers::pi / 2;
// Float rounding moves a table direction by at most ~1e-7 rad off its exact (θ, φ); the row
// pruning bound and max_error_degrees() allow ten times that.
constexpr double table_slack = 1e-6;

/// Upper edge b(i) of latitude band i: 1 − cos b = (i+1)(i+2)/(k(k+1)), written as
/// 2·asin(sqrt(x/2)) because acos(1 − x) loses half the digits for small x.
double band_edge(int i, int k) {
  if (i < 0) return 0.0;
  const double x = double(i + 1) * double(i + 2) / (double(k) * double(k + 1));
  return 2.0 * std::asin(std::min(1.0, std::sqrt(x / 2.0)));
}

vec3d direction(double theta, double phi) {
  return {std::sin(theta) * std::cos(phi), std::sin(theta) * std::sin(phi), std::cos(theta)};
}

/// atan2(y, x) for x, y ≥ 0 (not both zero), within 1.7e-6 rad: a minimax polynomial of the
/// arctangent on [0, 1] and the reflection atan(t) = π/2 − atan(1/t).
double fast_atan2_first_quadrant(double y, double x) {
  const bool swap = y > x;
  const double t = swap ? x / y : (x > 0 ? y / x : 0.0);  // in [0, 1]; 0 for the pole
  const double t2 = t * t, t4 = t2 * t2;
  // The polynomial in t² by Estrin's scheme (pairs, then powers t⁴): half the dependent steps of
  // Horner's, on the encoder's critical path.
  const double a =
      t * ((0.99997726 - 0.33262347 * t2) +
           t4 * ((0.19354346 - 0.11643287 * t2) + t4 * (0.05265332 - 0.01172120 * t2)));
  return swap ? half_pi - a : a;
}

/// A point of the first octant's octahedral triangle u, v ≥ 0, u + v ≤ 1, which stands for the
/// direction (u, v, 1 − u − v)/‖·‖.
struct pt2 {
  double u, v;
};

/// Clips the convex polygon `poly` to a·u + b·v + c ≥ 0 (Sutherland–Hodgman; keeps the order).
void clip(std::vector<pt2>& poly, std::vector<pt2>& tmp, double a, double b, double c) {
  tmp.clear();
  pt2 p = poly.back();
  double fp = a * p.u + b * p.v + c;
  for (const pt2 q : poly) {  // edge p → q
    const double fq = a * q.u + b * q.v + c;
    if ((fp >= 0) != (fq >= 0)) {
      const double t = fp / (fp - fq);
      tmp.push_back({p.u + t * (q.u - p.u), p.v + t * (q.v - p.v)});
    }
    if (fq >= 0) tmp.push_back(q);
    p = q;
    fp = fq;
  }
  poly.swap(tmp);
}

/// Angle between two unit vectors, accurate also for tiny angles.
double angle(const vec3d& a, const vec3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

}  // namespace

normal_quantizer::normal_quantizer(int q_bits) {
  if (q_bits < min_bits || q_bits > max_bits)
    throw InvalidArgument("normal_quantizer: q_bits = " + std::to_string(q_bits) + " is outside [" +
                          std::to_string(min_bits) + ", " + std::to_string(max_bits) + "]");
  bits_ = q_bits;
  const std::uint64_t budget = std::uint64_t{1} << (q_bits - 3);
  while (std::uint64_t(k_ + 1) * std::uint64_t(k_ + 2) / 2 <= budget) ++k_;
  per_octant_ = static_cast<std::uint32_t>(std::uint64_t(k_) * std::uint64_t(k_ + 1) / 2);
  index_mask_ = static_cast<std::uint32_t>(budget - 1);

  dirs_.reserve(per_octant_);
  row_cos_.resize(std::size_t(k_));
  row_sin_.resize(std::size_t(k_));
  row_margin_.resize(std::size_t(k_));
  double bound = 0;
  for (int i = 0; i < k_; ++i) {
    const double lo = band_edge(i - 1, k_), hi = band_edge(i, k_);
    const double theta = 0.5 * (lo + hi);
    row_cos_[std::size_t(i)] = std::cos(theta);
    row_sin_[std::size_t(i)] = std::sin(theta);
    // search_row()'s neighbour margin, in cells: a cell edge is where the two neighbours' exact
    // dot products tie; off the edge by f cells they differ by ≈ f·w² for a cell of angular
    // width w (w = sin θ·(π/2)/(i + 1)), and the float table moves each dot product by up to
    // ≈ 2.5e-7. Ten times that error, plus the 1.7e-6 rad of the fast arctangent. Beyond 5 % of a
    // cell (fine tables, q ≳ 19) the branch costs more than it saves: both neighbours always.
    const double w = std::sin(theta) * half_pi / double(i + 1);
    const double margin = 1e-4 + 2.5e-6 / (w * w) + 2e-6 * double(i + 1) / half_pi;
    row_margin_[std::size_t(i)] = margin < 0.05 ? margin : 1.0;
    const double cell = half_pi / double(i + 1);
    for (int j = 0; j <= i; ++j)
      dirs_.push_back(direction(theta, cell * (double(j) + 0.5)).cast<float>());
    // Every direction of band i is within half a cell in longitude of a sample of row i; over
    // the band the distance to that sample is largest at one of the band's edges (cos of the
    // distance is a single-peaked sinusoid in the polar angle).
    const vec3d sample = direction(theta, 0.5 * cell);
    bound = std::max({bound, angle(direction(lo, 0), sample), angle(direction(hi, 0), sample)});
  }
  max_error_deg_ = (bound + table_slack) * 180.0 / std::numbers::pi;
  build_cells();
}

// The candidate grid. Central projection onto the octant's face u + v + w = 1 maps great circles
// to straight lines, so the set of folded normals whose largest dot product is with entry c,
// {p : p·(d_c − d_m) ≥ 0 for every entry m}, is a convex polygon in (u, v). Clipping the
// triangle by the half-planes of c's neighbours (its row's next columns, and the three columns
// nearest its longitude in the rows above and below) gives a polygon that contains it (fewer
// half-planes can only enlarge it; two columns to either side give the same candidate counts in
// every cell at q = 6 … 16); c goes into every cell that polygon meets. So a cell lists every entry
// that is the nearest anywhere in it, and the largest dot product over its list is the largest over
// the table. The half-planes are widened by 1e-13 (the encoder's double dot products round by ≈
// 1e-16) and the cells by 1e-9 (the rounding of the cell coordinates), so rounding cannot lose a
// candidate.
void normal_quantizer::build_cells() {
  if (bits_ > 16) return;  // 2^(q−3) entries must fit 16 bits, and finer tables need finer grids
  grid_ = 8;
  while (grid_ < 2 * std::uint32_t(k_)) grid_ *= 2;
  const std::size_t n_cells = std::size_t(grid_) * grid_;
  // While filling, a cell's slots fill in order (0xFFFF = free) and 0xFFFE in the first slot
  // marks a fifth candidate: no side array.
  constexpr std::uint64_t free_slot = 0xFFFF, overflow = 0xFFFE;
  cells_.assign(n_cells, ~std::uint64_t{0});
  constexpr double eps = 1e-13, m = 1e-9;
  const double g = grid_, inv_g = 1.0 / g;  // exact: a power of two
  std::vector<pt2> poly, tmp;
  std::vector<std::array<double, 4>> edges;  // start u, v and direction du, dv
  for (int i = 0; i < k_; ++i)
    for (int j = 0; j <= i; ++j) {
      const std::uint32_t c = std::uint32_t(i) * std::uint32_t(i + 1) / 2 + std::uint32_t(j);
      const vec3d dc = dirs_[c].cast<double>();
      poly.assign({{0, 0}, {1, 0}, {0, 1}});
      // Nearest first (the polygon shrinks early, so later clips are cheap): the columns at c's
      // longitude, then one column to either side.
      for (int spread = 0; spread <= 1 && !poly.empty(); ++spread)
        for (int r = std::max(0, i - 1); r <= std::min(k_ - 1, i + 1) && !poly.empty(); ++r) {
          const int centre = r == i ? j : int(std::lround((j + 0.5) * (r + 1) / (i + 1) - 0.5));
          const std::array<int, 2> cols = {centre - spread, centre + spread};
          for (int t = 0; t < (spread == 0 ? 1 : 2) && !poly.empty(); ++t) {
            const int cj = cols[std::size_t(t)];
            if (cj < 0 || cj > r) continue;
            const std::uint32_t o = std::uint32_t(r) * std::uint32_t(r + 1) / 2 + std::uint32_t(cj);
            if (o == c) continue;
            // p·(d_c − d_o) with p = (u, v, 1 − u − v)
            const vec3d dd = dc - dirs_[o].cast<double>();
            clip(poly, tmp, dd.x() - dd.z(), dd.y() - dd.z(), dd.z() + eps);
          }
        }
      if (poly.empty()) continue;
      // The polygon's edges, for the separating-axis test below.
      edges.clear();
      for (std::size_t e = 0; e < poly.size(); ++e) {
        const pt2 a = poly[e], b = poly[e + 1 < poly.size() ? e + 1 : 0];
        edges.push_back({a.u, a.v, b.u - a.u, b.v - a.v});
      }
      double u0 = 2, u1 = -1, v0 = 2, v1 = -1;
      for (const auto& p : poly) {
        u0 = std::min(u0, p.u);
        u1 = std::max(u1, p.u);
        v0 = std::min(v0, p.v);
        v1 = std::max(v1, p.v);
      }
      const auto cell_of = [&](double x) {
        return std::uint32_t(std::clamp(std::floor(x * g), 0.0, g - 1));
      };
      const std::uint32_t iu0 = cell_of(u0 - m), iu1 = cell_of(u1 + m), iv0 = cell_of(v0 - m),
                          iv1 = cell_of(v1 + m);
      for (std::uint32_t iu = iu0; iu <= iu1; ++iu)
        for (std::uint32_t iv = iv0; iv <= iv1; ++iv) {
          // Separating axis: the polygon is counter-clockwise, so a cell lies wholly outside
          // it when all four corners are strictly right of one of its edges; the corner
          // farthest to the left decides (the test is linear in the corner). The bounding-box
          // axes need no test: the loops visit only cells that overlap the polygon's box.
          const double cu0 = iu * inv_g - m, cu1 = (iu + 1) * inv_g + m, cv0 = iv * inv_g - m,
                       cv1 = (iv + 1) * inv_g + m;
          bool apart = false;
          for (const auto& e : edges) {
            const double x = e[3] < 0 ? cu1 : cu0, y = e[2] > 0 ? cv1 : cv0;
            if (e[2] * (y - e[1]) - e[3] * (x - e[0]) < 0) {
              apart = true;
              break;
            }
          }
          if (apart) continue;
          std::uint64_t& cell = cells_[std::size_t(iu) * grid_ + iv];
          if ((cell & 0xFFFF) == overflow) continue;
          int used = 0;
          while (used < 4 && (cell >> (16 * used) & 0xFFFF) != free_slot) ++used;
          if (used == 4)
            cell = (cell & ~std::uint64_t{0xFFFF}) | overflow;
          else
            cell = (cell & ~(free_slot << (16 * used))) | (std::uint64_t{c} << (16 * used));
        }
    }
  // Unused slots repeat the first candidate (the encoder then tests four without branching on
  // the count); cells with more than four candidates, or none, get 0xFFFF in every slot.
  for (auto& cell : cells_) {
    const std::uint64_t first = cell & 0xFFFF;
    if (first == free_slot || first == overflow) {
      cell = ~std::uint64_t{0};
      continue;
    }
    for (int k = 1; k < 4; ++k)
      if ((cell >> (16 * k) & 0xFFFF) == free_slot)
        cell = (cell & ~(free_slot << (16 * k))) | (first << (16 * k));
  }
}

std::shared_ptr<const normal_quantizer> normal_quantizer::shared(int q_bits) {
  if (q_bits < min_bits || q_bits > max_shared_bits)
    return std::make_shared<normal_quantizer>(q_bits);
  constexpr auto n = std::size_t(max_shared_bits - min_bits + 1);
  static std::array<std::once_flag, n> once;
  static std::array<std::shared_ptr<const normal_quantizer>, n> built;
  const auto i = std::size_t(q_bits - min_bits);
  std::call_once(once[i], [&] { built[i] = std::make_shared<normal_quantizer>(q_bits); });
  return built[i];
}

void normal_quantizer::throw_invalid_code(std::uint32_t code) const {
  throw InvalidArgument("normal_quantizer: code " + std::to_string(code) + " is not a valid " +
                        std::to_string(bits_) + "-bit code (" + std::to_string(per_octant_) +
                        " directions per octant)");
}

// Inlined into encode(), its only caller (three call sites: a third of encode's time was calls).
[[gnu::always_inline]] inline void normal_quantizer::search_row(int row, double ax, double ay,
                                                                double az, double phi_cells,
                                                                double& best_dot,
                                                                std::uint32_t& best) const {
  // Within a row the distance grows with the longitude difference, so the nearest sample is in
  // the cell containing φ. Its neighbour on the nearer side can still win the comparison when φ
  // lies within row_margin_ cells of the cell edge: the float table entries are neither exactly
  // at the cell centres nor exactly unit length (≈ 1e-7 off), which at fine tables is worth a
  // noticeable fraction of a cell in the double dot product. Elsewhere one candidate suffices.
  // φ_cells = φ / (π/2) ≥ 0, so truncation is the floor.
  const double pos = phi_cells * double(row + 1);
  const int j0 = std::min(static_cast<int>(pos), row);
  const double frac = pos - double(j0);
  const double margin = row_margin_[std::size_t(row)];
  const std::uint32_t first = std::uint32_t(row) * std::uint32_t(row + 1) / 2;
  const auto test = [&](int j) {
    const std::uint32_t t = first + std::uint32_t(j);
    const vec3f& d = dirs_[t];
    const double dot = ax * double(d.x()) + ay * double(d.y()) + az * double(d.z());
    if (dot > best_dot) {
      best_dot = dot;
      best = t;
    }
  };
  // Candidates in ascending j, as the exhaustive j0 − 1 … j0 + 1 scan visited them (ties keep the
  // first).
  if (frac < margin && j0 > 0) test(j0 - 1);
  test(j0);
  if (frac > 1 - margin && j0 < row) test(j0 + 1);
}

// The candidate-grid cell of n: its four candidates, or no_cell (no grid, or n is zero or not
// finite). Split from encode_in() so that encode() over many normals can load the cells of a
// run of them first: a cell is a likely cache miss (q = 16: 512 kB of cells).
[[gnu::always_inline]] inline std::uint64_t normal_quantizer::cell_of(const vec3f& n) const {
  const double x = n.x(), y = n.y(), z = n.z();
  const double len2 = x * x + y * y + z * z;
  if (cells_.empty() || !(len2 > 0) || !std::isfinite(len2)) return no_cell;
  // The cell of the octahedral coordinates (fx, fy)/(fx + fy + fz) ∈ [0, 1] (the sum is at least
  // the largest |component| of a nonzero float vector, so the scale is finite).
  const double fx = std::abs(x), fy = std::abs(y), fz = std::abs(z);
  const double scale = double(grid_) / (fx + fy + fz);
  const auto iu = std::min(static_cast<std::uint32_t>(fx * scale), grid_ - 1);
  const auto iv = std::min(static_cast<std::uint32_t>(fy * scale), grid_ - 1);
  return cells_[std::size_t(iu) * grid_ + iv];
}

[[gnu::always_inline]] inline std::uint32_t normal_quantizer::encode_in(const vec3f& n,
                                                                        std::uint64_t cell) const {
  const double x = n.x(), y = n.y(), z = n.z();
  const double len2 = x * x + y * y + z * z;
  if (!(len2 > 0) || !std::isfinite(len2)) return 0;  // NaN, Inf or zero: as +z
  const double len = std::sqrt(len2), inv = 1.0 / len;
  const std::uint32_t octant = (x < 0 ? 1u : 0u) | (y < 0 ? 2u : 0u) | (z < 0 ? 4u : 0u);
  // Fold into the first octant: the table is symmetric under sign flips, so the nearest
  // direction of the folded normal in the first octant's table is the nearest overall (mirroring
  // a direction of another octant into this one never moves it away from n).
  const double fx = std::abs(x), fy = std::abs(y), fz = std::abs(z);
  const double ax = fx * inv, ay = fy * inv, az = fz * inv;
  if ((cell & 0xFFFF) != 0xFFFF) {
    double best_dot = -std::numeric_limits<double>::infinity();
    std::uint32_t best = 0;
    for (int k = 0; k < 4; ++k) {  // ascending index, repeats at the end: ties keep the first
      const auto t = static_cast<std::uint32_t>(cell >> (16 * k)) & 0xFFFFu;
      const vec3f& d = dirs_[t];
      const double dot = ax * double(d.x()) + ay * double(d.y()) + az * double(d.z());
      best = dot > best_dot ? t : best;
      best_dot = std::max(dot, best_dot);
    }
    return (octant << (bits_ - 3)) | best;
  }
  const double rho2 = ax * ax + ay * ay;
  const double sin_theta = std::sqrt(rho2);
  // φ only picks the longitude cell of a row, whose neighbours are searched too, so an error far
  // below the narrowest cell (π/2 / k ≥ 7.7e-4 rad at q = 24) cannot change the result. It is
  // taken from the unnormalised |x|, |y| (the ratio is the same up to rounding), so it does not
  // wait for the normalisation: the encoder's time is mostly its dependency chain.
  const double phi_cells = fast_atan2_first_quadrant(fy, fx) * (1.0 / half_pi);
  // The band containing θ: i(i+1) ≤ (1 − cos θ)·k(k+1) < (i+1)(i+2); 1 − cos θ = ρ²/(1 + cos θ)
  // = (x² + y²)/(|n|² + |z|·|n|), again without waiting for the division. Only the first row
  // searched depends on it: the walk below visits every row that can hold the nearest entry.
  const double u = (fx * fx + fy * fy) / (len2 + fz * len) * double(k_) * double(k_ + 1);
  const int row0 = std::clamp(static_cast<int>(std::floor(std::sqrt(u + 0.25) - 0.5)), 0, k_ - 1);

  double best_dot = -std::numeric_limits<double>::infinity();
  std::uint32_t best = 0;
  search_row(row0, ax, ay, az, phi_cells, best_dot, best);
  // Any direction of row r is at least |θ − θ_r| away from n: walk outwards from row0 and stop
  // once that bound exceeds the best distance found (first row on each side that is past θ).
  // With g = |θ − θ_r| and the table slack s: cos g = cos θ·cos θ_r + sin θ·sin θ_r and
  // sin g = |sin θ·cos θ_r − cos θ·sin θ_r| need no trigonometry, and
  // cos(g − s) ≤ cos g + s·sin g. The dot product is against a float entry, whose length is 1
  // only to ≈ 6e-8, so it can exceed the cosine by that much: + 2.5e-7 (as in search_row()'s
  // margin). Without it, directions where two rows' best entries tie to within 1e-7 got the
  // worse one (2 of 2.4 M random normals at q = 16, 2.5e-9 apart in the dot product).
  const auto worth = [&](int r) {
    const auto i = std::size_t(r);
    const double cos_g = az * row_cos_[i] + sin_theta * row_sin_[i];
    const double sin_g = std::abs(sin_theta * row_cos_[i] - az * row_sin_[i]);
    return cos_g + table_slack * sin_g + 2.5e-7 >= best_dot;
  };
  for (int r = row0 - 1; r >= 0; --r) {
    if (!worth(r)) {
      if (row_cos_[std::size_t(r)] >= az) break;  // θ_r ≤ θ
      continue;
    }
    search_row(r, ax, ay, az, phi_cells, best_dot, best);
  }
  for (int r = row0 + 1; r < k_; ++r) {
    if (!worth(r)) {
      if (row_cos_[std::size_t(r)] <= az) break;  // θ_r ≥ θ
      continue;
    }
    search_row(r, ax, ay, az, phi_cells, best_dot, best);
  }
  return (octant << (bits_ - 3)) | best;
}

std::uint32_t normal_quantizer::encode(const vec3f& n) const {
  return encode_in(n, cell_of(n));
}

void normal_quantizer::encode(std::span<const vec3f> in, std::span<std::uint32_t> out) const {
  if (in.size() != out.size())
    throw InvalidArgument("normal_quantizer::encode: " + std::to_string(in.size()) +
                          " normals but room for " + std::to_string(out.size()) + " codes");
  constexpr std::size_t run = 32;
  std::array<std::uint64_t, run> cell;
  for (std::size_t lo = 0; lo < in.size(); lo += run) {
    const std::size_t m = std::min(run, in.size() - lo);
    for (std::size_t k = 0; k < m; ++k) cell[k] = cell_of(in[lo + k]);
    for (std::size_t k = 0; k < m; ++k) out[lo + k] = encode_in(in[lo + k], cell[k]);
  }
}

}  // namespace pbr_lod
