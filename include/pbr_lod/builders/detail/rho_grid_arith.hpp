// pbr_lod — the number types of the ρ-grid's §4.1 tests (Duguet & Drettakis 2004, §5.1): float,
// int64 fixed point with int128 products, and the paper's 32-bit fixed point with a reciprocal
// table; and the two cell bounds the tests can use. rho_grid_policy (builders/rho_grid_policy.hpp)
// picks them; the traversal (detail/rho_grid_traversal.hpp) is written once over them.
#pragma once

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numeric>
#include <optional>
#include <ranges>
#include <type_traits>
#include <vector>

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// The number type of rho_grid_policy's tests (§5.1): float, int64 fixed point with int128
/// products, or the paper's 32-bit fixed point with a reciprocal table.
enum class rho_grid_arithmetic { floating, fixed, fixed32 };

/// The screen bound of a cell in rho_grid_policy's tests (§4.1). `symmetric`: a half extent
/// E/(W·(W − B)) about the projected centre from one max-|Δ| entry per axis (all arithmetics).
/// `per_corner`: the paper's bounds table — per depth the min and max over the cell's corners of
/// ΔX, ΔY, ΔW — giving the rectangle [min x, max x] × [min y, max y] with the minimum z/w, which
/// lies inside the symmetric one (every arithmetic; fixed32 divides through the reciprocal
/// table for the min and the max z/w, two look-ups per cell where the symmetric bound takes one).
enum class rho_grid_bounds { symmetric, per_corner };

namespace detail {

// ---- arithmetic policies: the same traversal in float and in fixed point (§5.1)
// ---- arithmetic policies: the same traversal in float and in fixed point (§5.1)
struct rho_float_arith {
  using value = float;
  using wide = float;
  double scale = 1;
  [[nodiscard]] value from(double x) const { return static_cast<float>(x); }
  [[nodiscard]] static wide mul(value a, value b) { return a * b; }
  [[nodiscard]] static wide splat_scale(float s) { return s; }
  static constexpr int splat_shift = 1;  // 2·E ≤ s·W·(W − B)
  [[nodiscard]] static wide lhs(wide e) { return 2 * e; }
  /// 2^F for a view whose values stay within ±bound (float: no scale).
  [[nodiscard]] static double choose_scale(double, const view&) { return 1; }
};

__extension__ using int128 = __int128;

struct rho_fixed_arith {
  using value = std::int64_t;
  using wide = int128;
  double scale = 1;  // 2^F
  [[nodiscard]] value from(double x) const {
    return static_cast<std::int64_t>(std::llround(x * scale));
  }
  [[nodiscard]] static wide mul(value a, value b) { return wide(a) * wide(b); }
  /// s in 1/256 pixels: 512·E ≤ s₂₅₆·W·(W − B).
  [[nodiscard]] static wide splat_scale(float s) { return wide(std::llround(double(s) * 256)); }
  [[nodiscard]] static wide lhs(wide e) { return 512 * e; }
  /// F fractional bits so that every value, the far plane and the half screen included, stays
  /// below 2^40 (products below 2^81 in int128).
  [[nodiscard]] static double choose_scale(double bound, const view& v) {
    bound = std::max({bound, double(v.z_far), 0.5 * double(v.width), 0.5 * double(v.height)});
    return std::ldexp(1.0,
                      std::clamp(40 - int(std::ceil(std::log2(std::max(bound, 1e-300)))), 0, 40));
  }
};

/// §5.1's reciprocal look-up table for a 32-bit CPU: 1/v for a positive int32 v as t·2^-shift.
/// v = m·2^(n−1) with m in [1, 2) (n = bit_width(v), one count-leading-zeros); the 12 bits of m
/// after its leading one index 4096 entries t ≈ 2^30/m (16 KiB), each the reciprocal of its
/// interval's midpoint, which minimises the worst relative error over the interval. Bound:
/// |t·2^-shift·v − 1| ≤ h/(2 + h) + 2^-30 < 2^-13 with h = 2^-12 (interval, then the entry's
/// rounding), whatever v's magnitude: the "shift on numbers" of §5.1 makes one table serve all.
struct rho_reciprocal {
  static constexpr int index_bits = 12;
  static constexpr int entry_bits = 30;
  static constexpr double max_relative_error = 0x1p-13;
  struct value {
    std::uint32_t t;  ///< ≈ 2^shift / v
    int shift;
  };
  /// v ≥ 1.
  [[nodiscard]] static value of(std::uint32_t v) {
    const int n = std::bit_width(v);
    constexpr std::uint32_t mask = (1u << index_bits) - 1;
    const std::uint32_t i = n - 1 >= index_bits ? (v >> (n - 1 - index_bits)) & mask
                                                : (v << (index_bits - (n - 1))) & mask;
    return {table()[i], entry_bits + n - 1};
  }
  /// round(num / v) with 1/v from the table, saturated at ±2^30 (`saturated` set). num is first
  /// cut to 31 significant bits so the product stays in 64 bits (a relative 2^-30 more).
  [[nodiscard]] static std::int32_t divide(std::int64_t num, value r, bool& saturated) {
    constexpr std::uint64_t sat = std::uint64_t(1) << 30;
    const std::uint64_t mag = num < 0 ? 0 - std::uint64_t(num) : std::uint64_t(num);
    const int k = std::max(0, int(std::bit_width(mag)) - 31);
    // sh < 1 needs k ≥ shift = 29 + bit_width(v), i.e. |num| ≥ 2^(30 + k): a quotient ≥ 2^59.
    const int sh = r.shift - k;
    const std::uint64_t p = (mag >> k) * r.t;
    std::uint64_t q = sh < 1 ? sat : (p + (std::uint64_t(1) << (sh - 1))) >> sh;
    if (q >= sat) {
      q = sat;
      saturated = true;
    }
    return num < 0 ? -std::int32_t(q) : std::int32_t(q);
  }

 private:
  [[nodiscard]] static const std::array<std::uint32_t, 1u << index_bits>& table() {
    static const auto t = [] {
      std::array<std::uint32_t, 1u << index_bits> e{};
      const double h = std::ldexp(1.0, -index_bits);
      for (std::size_t i = 0; i < e.size(); ++i)  // 1 / midpoint of [1 + i·h, 1 + (i+1)·h)
        e[i] =
            std::uint32_t(std::llround(std::ldexp(1.0, entry_bits) / (1 + (double(i) + 0.5) * h)));
      return e;
    }();
    return t;
  }
};

/// §5.1 in 32 bits: values int32, products int64 (a 32-bit CPU's one-instruction multiply).
struct rho_fixed32_arith {
  using value = std::int32_t;
  using wide = std::int64_t;
  double scale = 1;  // 2^F
  /// Rounded and saturated at ±(2^31 − 1): only the view's near and far distances can reach it
  /// (H and the tables are ≤ 2^30 by choose_scale), and every W ± B they are compared with is
  /// within ±2^30 + a few units, so a saturated plane compares as the exact one.
  [[nodiscard]] value from(double x) const {
    constexpr double lim = std::numeric_limits<std::int32_t>::max();
    return static_cast<value>(std::llround(std::clamp(x * scale, -lim, lim)));
  }
  [[nodiscard]] static wide mul(value a, value b) { return wide(a) * wide(b); }
  /// F fractional bits so that |H| + B ≤ 2^30 anywhere in the tree (one bit of headroom for the
  /// rounding of ≤ 22 accumulated displacements); any F, negative for a huge scene.
  [[nodiscard]] static double choose_scale(double bound, const view&) {
    return std::ldexp(1.0, 30 - int(std::ceil(std::log2(std::max(bound, 1e-200)))));
  }
  /// Screen positions x = X/W carry G fractional bits of a pixel: 16, fewer for a half screen
  /// c > 256 px so that c·2^G ≤ 2^24, i.e. a saturated |x| (2^30 units) is ≥ 64·c off-centre.
  [[nodiscard]] static int screen_bits(const view& v) {
    const double c = std::max({1.0, 0.5 * double(v.width), 0.5 * double(v.height)});
    return std::clamp(24 - int(std::ceil(std::log2(c))), 0, 16);
  }
};

}  // namespace detail
}  // namespace pbr_lod
