// pbr_lod — the ρ-grid as a Hierarchy, and its §4.1 traversal as a policy of the common traverse
// (Duguet & Drettakis 2004, §4, §4.1, §4.2 child order, §5.1).
//
// rho_grid_hierarchy<ρ, A> models Hierarchy (traverse/hierarchy.hpp) over a built rho_grid<ρ>:
// a node is a cell with its depth and integer position (positions are implicit in the path),
// A ⊆ {normal, colour} is the compile-time attribute set of the primitives (normal = the decoded
// σ-bit normal, colour = the decoded colour when the grid stores colours, else the material's
// palette colour), and emit() sends one point_prim at the cell centre. Any traversal policy can
// drive it; rho_grid_policy is the paper's.
//
// rho_grid_policy is the paper's Render(cell, centre, level) with Botsch et al.'s transformation
// factorisation: the homogeneous screen position H = (X, Y, W) of a cell centre is its parent's
// plus an entry of a per-depth displacement table (one vec add per cell, no matrix product) —
// the traversal's per-entry state — and the conservative screen bounds of a cell come from a
// per-depth bounds table:
//   A_x = max over the cube's corners of |ΔX|, A_y likewise, B = max |ΔW|.
// With E_x = A_x·W + B·|X|, every corner's x = X'/W' lies within E_x / (W·(W − B)) of X/W
// (while W − B > 0: the cell is wholly in front of the eye). So, all in homogeneous coordinates
// without a division (§4.1, Eq. 6):
//   splat condition   2·E_x ≤ s·W·(W − B)  and  2·E_y ≤ s·W·(W − B)
//   frustum culling   X·(W − B) + E_x < −c_x·W·(W − B)  (left of the screen; likewise right,
//                     top, bottom), W − B > z_far (beyond), W + B < z_near (behind the viewer)
// s is traverse_options::tolerance_px. A cell meeting the splat condition is emitted as a square
// splat of s pixels (an inner cell's intermediate sample); a leaf is emitted in any case, as a
// square of its own conservative projected width (§4.1's bounds of the cell), or a one-pixel
// point when that is at most a pixel — so that leaves larger than a pixel in close views leave
// no holes (rho_grid_policy::leaf_splats); a cell that straddles the near plane is refined. X is
// measured from the principal point, so |X| is small near the screen centre.
//
// §5.1 fixed point: rho_grid_policy<ρ, rho_grid_arithmetic::fixed> runs the same tests with H,
// the displacement and bounds tables in 64-bit fixed point (F fractional bits chosen per view so
// every |value| < 2^40) and 128-bit products. rho_grid_arithmetic::fixed32 is §5.1 as the paper
// has it, for a 32-bit CPU: H and the tables in int32 (F chosen so every |value| ≤ 2^30), no
// product wider than int32 × int32 → int64, and the tests divided by W through a reciprocal
// look-up table (detail::rho_reciprocal): on the projected centre x = X/W, y = Y/W
//   splat condition   2·(A_x + B·|x|) ≤ s·(W − B)  (and y)
//   frustum culling   x·(W − B) + A_x + B·|x| < −c_x·(W − B)  (left; likewise the others)
// which are the tests above divided by W > 0. Cells where the arithmetics disagree are those
// whose test is within rounding (or, for fixed32, the table's 2^-13) of equality (measured in
// docs/rho-grid.md; the tests bound it).
//
// Drawing (rho_grid_policy::screen_draw, §5.1 and §4.1): by default a drawn cell is a point_prim
// at its centre, which the sink projects itself (the rasteriser in float). With screen_draw, a
// sink that takes screen rectangles (ScreenRectSink) gets a screen_rect_prim placed from the
// traversal's own H divided by W — float a float division, int64 an integer division, fixed32
// the reciprocal table of its tests, then pixel indices by a shift (§5.1's last paragraph) —
// and, with the per-corner bounds, an inner cell covers the rectangle of its sampled children
// that its test measured (§4.1's rectangular splat) instead of an s × s square.
//
// §4.2: the policy visits children in any fixed order; rho_grid_light_order() gives the one that
// is front to back from a directional light, which raster/one_pass_shadows.hpp needs.
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

#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/light_map_frame.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/traverse.hpp"

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

/// A node of a ρ-grid hierarchy: the cell index (rho_grid numbering), its depth below the root
/// cube (the paper's level + 1, see rho_grid) and its integer position in [0, ρ^depth)³ — the
/// path the implicit positions need.
struct rho_grid_cell {
  std::uint32_t cell;
  int depth;
  std::array<std::uint32_t, 3> pos;
};

/// Where rho_grid_policy::screen_draw puts a drawn cell: screen_rect_prim's pixel rectangle
/// (pixels × 2^8 from the image's top-left corner, y down) and depth.
struct rho_grid_screen_rect {
  std::int32_t x0, y0, x1, y1;
  float depth;
};

/// The colour of material m (8-entry palette, repeated).
[[nodiscard]] inline rgb8 rho_grid_material_colour(std::uint32_t m) {
  static constexpr std::array<rgb8, 8> palette{
      rgb8{200, 200, 200}, rgb8{220, 80, 60},  rgb8{80, 180, 90},  rgb8{70, 110, 210},
      rgb8{230, 200, 70},  rgb8{170, 90, 200}, rgb8{70, 200, 200}, rgb8{240, 140, 60}};
  return palette[m % 8];
}

/// A built rho_grid<Rho> seen as a Hierarchy whose primitives carry the attributes A (normals
/// decoded from the σ-bit attribute; colours decoded from it when the grid stores colours, else
/// from the material palette). Holds a pointer to the grid, which must outlive it. Const member
/// functions are safe for concurrent readers.
template <int Rho, attributes A>
class rho_grid_hierarchy {
  static_assert(attributes{.normal = true, .colour = true}.contains(A),
                "a ρ-grid has normals and colours (or materials, drawn as colours) only");

 public:
  static constexpr attributes attrs = A;
  static constexpr int children_per_cell = Rho * Rho * Rho;
  using node_id = rho_grid_cell;

  /// Throws InvalidArgument when A asks for normals or colours the grid does not store.
  explicit rho_grid_hierarchy(const rho_grid<Rho>& g) : g_(&g) {
    if (A.normal && !g.has_normals())
      throw InvalidArgument("rho-grid: normals requested, the grid stores none");
    if (A.colour && !g.has_colours() && !g.has_materials())
      throw InvalidArgument("rho-grid: colours requested, the grid stores no colours or materials");
    if constexpr (A.normal) q_ = normal_quantizer::shared(g.normal_bits());  // one per process
    // cell_side() takes a pow(); a frame asks for it once per drawn cell.
    for (int d = 0; d <= g.leaf_depth(); ++d) side_.push_back(g.cell_side(d));
  }

  [[nodiscard]] const rho_grid<Rho>& grid() const { return *g_; }
  [[nodiscard]] vec3d origin() const { return g_->origin(); }
  [[nodiscard]] bool empty() const { return g_->empty(); }
  [[nodiscard]] node_id root() const { return {0, 0, {0, 0, 0}}; }
  [[nodiscard]] bool is_leaf(const node_id& n) const { return g_->is_leaf(n.cell); }

  /// Child j (digit j = x + ρ·y + ρ²·z, set in n's code) of inner cell n.
  [[nodiscard]] node_id child(const node_id& n, int j) const {
    return child(n, j, g_->first_child(n.cell) + std::uint32_t(g_->code(n.cell).rank(j)));
  }
  /// Child j of n when its cell index is already known (a traversal counting set bits).
  [[nodiscard]] static node_id child(const node_id& n, int j, std::uint32_t cell) {
    return {
        cell,
        n.depth + 1,
        {n.pos[0] * Rho + std::uint32_t(j % Rho), n.pos[1] * Rho + std::uint32_t((j / Rho) % Rho),
         n.pos[2] * Rho + std::uint32_t(j / (Rho * Rho))}};
  }
  [[nodiscard]] auto children(const node_id& n) const {
    const int count = is_leaf(n) ? 0 : children_per_cell;
    return std::views::iota(0, count) |
           std::views::filter([this, c = n.cell](int j) { return g_->code(c).test(j); }) |
           std::views::transform([this, n](int j) { return child(n, j); });
  }

  /// Centre of cell n relative to origin().
  [[nodiscard]] vec3f centre(const node_id& n) const {
    const double s = side_[std::size_t(n.depth)];
    return vec3f(float((double(n.pos[0]) + 0.5) * s), float((double(n.pos[1]) + 0.5) * s),
                 float((double(n.pos[2]) + 0.5) * s));
  }
  /// The cell's circumscribed sphere: the surface it samples lies in the cell.
  [[nodiscard]] sphere bounding_sphere(const node_id& n) const {
    return {centre(n), 0.5f * std::sqrt(3.0f) * float(side_[std::size_t(n.depth)])};
  }

  /// The cell's sample as a square of size_px pixels at the cell centre.
  template <class S>
  void emit_sample(const node_id& n, float size_px, S& sink) const {
    point_prim<A> p{centre(n), size_px};
    set_attributes(n, p);
    sink.point(p);
  }
  /// The cell's sample as the screen rectangle r (its pixels and depth, computed by the caller:
  /// rho_grid_policy::screen_draw).
  template <ScreenRectSink<A> S>
  void emit_rect(const node_id& n, const rho_grid_screen_rect& r, S& sink) const {
    screen_rect_prim<A> p{r.x0, r.y0, r.x1, r.y1, r.depth, centre(n)};
    set_attributes(n, p);
    sink.screen_rect(p);
  }
  /// A leaf as a one-pixel point, an inner cell as a square covering its projected cell (the
  /// projected diameter of its bounding sphere). rho_grid_policy emits inner cells at its splat
  /// size s instead, as the paper does.
  template <class S>
  void emit(const node_id& n, const view& v, S& sink) const {
    emit_sample(
        n, is_leaf(n) ? 1.0f : std::max(1.0f, 2 * projected_radius_exact(v, bounding_sphere(n))),
        sink);
  }

 private:
  template <class P>
  void set_attributes([[maybe_unused]] const node_id& n, [[maybe_unused]] P& p) const {
    if constexpr (A.normal) p.normal = q_->decode(g_->normal_code(n.cell));
    if constexpr (A.colour)
      p.colour =
          g_->has_colours() ? g_->colour(n.cell) : rho_grid_material_colour(g_->material(n.cell));
  }

  const rho_grid<Rho>* g_;
  std::shared_ptr<const normal_quantizer> q_;
  std::vector<double> side_;  // cell side per depth
};

/// Calls f(rho_grid_hierarchy<Rho, A>(g)) with A the attributes g stores (normals when it has
/// normals, colours when it has colours or materials): the ρ-grid's run-time σ split, made
/// compile time.
template <int Rho, class F>
decltype(auto) with_rho_grid_hierarchy(const rho_grid<Rho>& g, F&& f) {
  constexpr attributes N{.normal = true}, C{.colour = true};
  const bool colour = g.has_colours() || g.has_materials();
  if (g.has_normals() && colour) return f(rho_grid_hierarchy<Rho, N | C>(g));
  if (g.has_normals()) return f(rho_grid_hierarchy<Rho, N>(g));
  if (colour) return f(rho_grid_hierarchy<Rho, C>(g));
  return f(rho_grid_hierarchy<Rho, positions_only>(g));
}

namespace detail {

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

template <int Rho, class Arith>
struct rho_traversal {
  static constexpr int R3 = Rho * Rho * Rho;
  using value = typename Arith::value;
  struct hom {
    value x, y, w;
  };
  /// Min and max of (ΔX, ΔY, ΔW) over the corners of a box, from the centre of its cell.
  struct corner_box {
    std::array<value, 3> mn, mx;
  };
  struct level_tables {
    std::array<hom, R3> disp;  ///< H offset of child j's centre from its parent's
    value ax, ay, b;           ///< bounds table: max |ΔX|, |ΔY|, |ΔW| over the cell's corners
    /// per-corner bounds table, split by axis (the box's corners are sums of one offset per
    /// axis): span[a][i0·ρ + i1] = min and max of (ΔX, ΔY, ΔW) over the offsets along axis a
    /// of the faces of child slabs i0 … i1 from the cell centre. Summed over the axes for the
    /// occupied children's span, they bound the corners of the box of the sampled children.
    std::array<std::array<corner_box, Rho * Rho>, 3> span;
  };
  /// fixed32 tests on the projected centre (X/W, Y/W) instead of in homogeneous coordinates.
  static constexpr bool projective = std::is_same_v<Arith, rho_fixed32_arith>;
  Arith arith;
  int screen_g = 0;  ///< fixed32: fractional bits of the screen positions (and of cx, cy)
  hom root{};
  std::vector<level_tables> levels;  // indexed by cell depth (0 = root cube)
  value cx{}, cy{}, znear{}, zfar{};
  value unit{};  ///< 1 in the arithmetic (2^F): lifts a value to a product's scale
  /// The principal point in screen_rect_prim's fixed point (pixels × 2^8 from the top-left).
  std::int64_t cx8 = 0, cy8 = 0;
  /// Shadow casters (§4.2 with frustum culling): which planes of the view volume may still cull
  /// a cell — those the cell cannot cross by moving away from the light — and from which depth
  /// a cell kept only as a caster is fine enough to emit. All true / unused when not casting.
  struct caster_planes {
    bool left = true, right = true, top = true, bottom = true, far = true, near = true;
  } may_cull;
  bool casters = false;
  int caster_depth = 0;

  /// Rows of the linear map p ↦ (X, Y, W) in pixels × depth, relative to the principal point.
  [[nodiscard]] static std::array<vec3d, 3> rows(const view& v) {
    return {v.right.cast<double>() * double(v.focal_px), -v.up.cast<double>() * double(v.focal_px),
            v.forward.cast<double>()};
  }

  rho_traversal(const rho_grid<Rho>& g, const view& v) {
    const auto [r, u, f] = rows(v);
    const vec3d c0 = vec3d::Constant(0.5 * g.cube_side()) - v.eye.cast<double>();
    const std::array<double, 3> h0{r.dot(c0), u.dot(c0), f.dot(c0)};
    struct dl {
      std::array<std::array<double, 3>, R3> d;
      double ax, ay, b;
    };
    std::vector<dl> dt(std::size_t(g.leaf_depth()) + 1);
    double bound = std::max({std::abs(h0[0]), std::abs(h0[1]), std::abs(h0[2])});
    for (int l = 0; l <= g.leaf_depth(); ++l) {
      const double s = g.cell_side(l), hs = 0.5 * s;
      auto& e = dt[std::size_t(l)];
      e.ax = hs * r.cwiseAbs().sum();
      e.ay = hs * u.cwiseAbs().sum();
      e.b = hs * f.cwiseAbs().sum();
      double dmax = 0;
      for (int j = 0; j < R3; ++j) {
        const vec3d o =
            s * vec3d(double(j % Rho) + 0.5 - 0.5 * Rho, double((j / Rho) % Rho) + 0.5 - 0.5 * Rho,
                      double(j / (Rho * Rho)) + 0.5 - 0.5 * Rho);
        e.d[std::size_t(j)] = {r.dot(o), u.dot(o), f.dot(o)};
        dmax = std::max({dmax, std::abs(r.dot(o)), std::abs(u.dot(o)), std::abs(f.dot(o))});
      }
      bound += dmax + std::max({e.ax, e.ay, e.b});
    }
    arith.scale = Arith::choose_scale(bound, v);
    root = {arith.from(h0[0]), arith.from(h0[1]), arith.from(h0[2])};
    levels.resize(dt.size());
    for (std::size_t l = 0; l < dt.size(); ++l) {
      for (int j = 0; j < R3; ++j) {
        const auto& d = dt[l].d[std::size_t(j)];
        levels[l].disp[std::size_t(j)] = {arith.from(d[0]), arith.from(d[1]), arith.from(d[2])};
      }
      levels[l].ax = arith.from(dt[l].ax);
      levels[l].ay = arith.from(dt[l].ay);
      levels[l].b = arith.from(dt[l].b);
      span_table(r, u, f, g.cell_side(int(l)), levels[l].span);
    }
    unit = arith.from(1.0);
    cx8 = std::int64_t(v.width) << (rect_bits - 1);
    cy8 = std::int64_t(v.height) << (rect_bits - 1);
    if constexpr (projective) {
      screen_g = Arith::screen_bits(v);
      cx = value(std::llround(std::ldexp(0.5 * v.width, screen_g)));  // ≤ 2^24
      cy = value(std::llround(std::ldexp(0.5 * v.height, screen_g)));
    } else {
      cx = arith.from(0.5 * v.width);
      cy = arith.from(0.5 * v.height);
    }
    znear = arith.from(double(v.z_near));
    zfar = arith.from(double(v.z_far));
    // fixed32: W − B > z_near ≥ 0 then gives W ≥ 1, what the reciprocal table takes.
    if constexpr (projective) znear = std::max(znear, value(0));
  }

  /// The per-corner table of one depth (cells of side `side`): for each axis a and slab span
  /// i0 ≤ i1, the min and max of (ΔX, ΔY, ΔW) = rows · e_a·o over the two face offsets
  /// o = −side/2 + i0·side/ρ and −side/2 + (i1 + 1)·side/ρ.
  void span_table(const vec3d& r, const vec3d& u, const vec3d& f, double side,
                  std::array<std::array<corner_box, Rho * Rho>, 3>& out) const {
    const double cs = side / Rho;
    for (int a = 0; a < 3; ++a)
      for (int i0 = 0; i0 < Rho; ++i0)
        for (int i1 = i0; i1 < Rho; ++i1) {
          const double lo = -0.5 * side + i0 * cs, hi = -0.5 * side + (i1 + 1) * cs;
          auto& e = out[std::size_t(a)][std::size_t(i0 * Rho + i1)];
          const std::array<double, 3> row{r[a], u[a], f[a]};
          for (std::size_t k = 0; k < 3; ++k) {
            e.mn[k] = arith.from(std::min(row[k] * lo, row[k] * hi));
            e.mx[k] = arith.from(std::max(row[k] * lo, row[k] * hi));
          }
        }
  }

  /// The span i0·ρ + i1 per axis of the children set in `code`; a leaf (empty code) spans
  /// the whole cell.
  [[nodiscard]] static std::array<int, 3> spans(const child_code<Rho>& code) {
    static const auto slabs = [] {  // slabs[a][i]: the bits of the children with digit_a = i
      std::array<std::array<child_code<Rho>, Rho>, 3> m{};
      for (int j = 0; j < R3; ++j) {
        m[0][std::size_t(j % Rho)].set(j);
        m[1][std::size_t((j / Rho) % Rho)].set(j);
        m[2][std::size_t(j / (Rho * Rho))].set(j);
      }
      return m;
    }();
    std::array<int, 3> out{};
    for (std::size_t a = 0; a < 3; ++a) {
      unsigned occ = 0;
      for (std::size_t i = 0; i < std::size_t(Rho); ++i) {
        bool any = false;
        for (std::size_t k = 0; k < code.w.size(); ++k) any |= (code.w[k] & slabs[a][i].w[k]) != 0;
        occ |= unsigned(any) << i;
      }
      out[a] = occ == 0 ? Rho - 1 : std::countr_zero(occ) * Rho + std::bit_width(occ) - 1;
    }
    return out;
  }

  /// The corner box of the sampled children of a cell at depth l with those spans.
  [[nodiscard]] corner_box children_box(int l, const std::array<int, 3>& sp) const {
    const auto& t = levels[std::size_t(l)].span;
    corner_box b{};
    for (std::size_t k = 0; k < 3; ++k) {
      b.mn[k] = t[0][std::size_t(sp[0])].mn[k] + t[1][std::size_t(sp[1])].mn[k] +
                t[2][std::size_t(sp[2])].mn[k];
      b.mx[k] = t[0][std::size_t(sp[0])].mx[k] + t[1][std::size_t(sp[1])].mx[k] +
                t[2][std::size_t(sp[2])].mx[k];
    }
    return b;
  }

  /// Keeps the cells that can shadow the view volume from a directional light (`to_light`, in
  /// the view's frame): a plane of the volume culls only when moving away from the light never
  /// brings a point back inside it (its inward function does not grow along −to_light), so every
  /// occluder of a visible point survives. Cells kept only as casters are emitted once their side
  /// is at most `caster_side` (a light-map texel) or they pass the splat condition.
  void cast_shadows(const rho_grid<Rho>& g, const view& v, const vec3f& to_light,
                    double caster_side) {
    const vec3d d = -to_light.cast<double>();  // the direction shadows fall
    const auto [r, u, f] = rows(v);
    const double dx = r.dot(d), dy = u.dot(d), dw = f.dot(d);
    const double hx = 0.5 * v.width, hy = 0.5 * v.height;
    may_cull = {.left = dx + hx * dw <= 0,
                .right = hx * dw - dx <= 0,
                .top = dy + hy * dw <= 0,
                .bottom = hy * dw - dy <= 0,
                .far = -dw <= 0,
                .near = dw <= 0};
    casters = true;
    caster_depth = g.leaf_depth();
    while (caster_depth > 0 && g.cell_side(caster_depth - 1) <= caster_side) --caster_depth;
  }

  enum class verdict { cull, draw, refine };

  /// The §4.1 tests for a cell at depth l with homogeneous centre h.
  [[nodiscard]] verdict test(const hom& h, int l, bool leaf, float s, bool cull) const {
    if constexpr (projective)
      return test_projected(h, l, leaf, s, cull);
    else
      return test_homogeneous(h, l, leaf, s, cull);
  }

  /// fixed32: the centre projected through the reciprocal table, x = X/W and y = Y/W with
  /// screen_g fractional bits, and A + B·|x|, A + B·|y| (the cell's projected half extents times
  /// W − B) in units of 2^(F + screen_g). W ≥ 1 unit: only called when W − B > z_near ≥ 0.
  struct projection {
    std::int32_t x, y;
    std::int64_t ex, ey;
    bool saturated = false;  ///< |x| or |y| reached 2^30 units (≥ 64 half screens off-centre)
  };
  [[nodiscard]] projection project(const hom& h, const level_tables& t) const {
    projection p{};
    const auto r = rho_reciprocal::of(std::uint32_t(h.w));
    p.x = rho_reciprocal::divide(std::int64_t(h.x) << screen_g, r, p.saturated);
    p.y = rho_reciprocal::divide(std::int64_t(h.y) << screen_g, r, p.saturated);
    p.ex = (std::int64_t(t.ax) << screen_g) + Arith::mul(t.b, p.x < 0 ? -p.x : p.x);
    p.ey = (std::int64_t(t.ay) << screen_g) + Arith::mul(t.b, p.y < 0 ? -p.y : p.y);
    return p;
  }

  /// Where a drawn cell goes on screen (§5.1): its centre x = X/W, y = Y/W in screen_rect_prim's
  /// fixed point (pixels × 2^8 from the image's top-left corner, y down) and its depth W in world
  /// units, each arithmetic dividing in its own numbers — float a float division, int64 an
  /// integer division rounded to nearest, fixed32 the reciprocal table of its tests (x with
  /// screen_g fractional bits, then a rounding shift to 8). Empty when W is not beyond z_near,
  /// or the centre lies ≥ 2^22 pixels off-centre (fixed32: saturated, ≥ 64 half screens): such
  /// a cell has no usable screen position and is drawn from its 3-D position instead.
  static constexpr int rect_bits = screen_rect_prim<positions_only>::fraction_bits;
  static constexpr std::int64_t rect_limit = std::int64_t(1) << 30;  // 2^22 pixels
  struct screen_point {
    std::int64_t x, y;
    float depth;
  };
  [[nodiscard]] std::optional<screen_point> screen_position(const hom& h) const {
    if (!(h.w > znear)) return std::nullopt;
    std::int64_t x, y;
    if constexpr (projective) {
      bool sat = false;
      const auto r = rho_reciprocal::of(std::uint32_t(h.w));  // W ≥ 1: W > z_near ≥ 0
      const int sh = screen_g - rect_bits;
      const auto to_rect = [sh](std::int32_t q) {
        return sh > 0 ? (std::int64_t(q) + (std::int64_t(1) << (sh - 1))) >> sh
                      : std::int64_t(q) * (std::int64_t(1) << -sh);
      };
      x = to_rect(rho_reciprocal::divide(std::int64_t(h.x) << screen_g, r, sat));
      y = to_rect(rho_reciprocal::divide(std::int64_t(h.y) << screen_g, r, sat));
      if (sat) return std::nullopt;
    } else if constexpr (std::is_same_v<value, float>) {
      constexpr float lim = float(rect_limit);
      const float fx = h.x / h.w * float(1 << rect_bits), fy = h.y / h.w * float(1 << rect_bits);
      if (!(std::abs(fx) < lim && std::abs(fy) < lim)) return std::nullopt;
      x = std::int64_t(fx + (fx < 0 ? -0.5f : 0.5f));
      y = std::int64_t(fy + (fy < 0 ? -0.5f : 0.5f));
    } else {
      // |X| < 2^40 by choose_scale, unless a huge scene clamped F at 0: up to 2^52, X·2^9 + W
      // fits in int64. Rounded to nearest: floor((2·X·2^8 + W) / 2W).
      constexpr std::int64_t big = std::int64_t(1) << 52;
      const auto fits = [](std::int64_t q) { return q > -big && big > q; };
      if (!(fits(h.x) && fits(h.y) && fits(h.w))) return std::nullopt;
      const auto div = [w = std::int64_t(h.w)](std::int64_t n) {
        const std::int64_t a = 2 * (n << rect_bits) + w, b = 2 * w;
        const std::int64_t q = a / b;
        return q - (a % b != 0 && a < 0 ? 1 : 0);
      };
      x = div(h.x);
      y = div(h.y);
      if (!(std::abs(x) < rect_limit && std::abs(y) < rect_limit)) return std::nullopt;
    }
    const float depth =
        std::is_same_v<value, float> ? float(h.w) : float(double(h.w) / arith.scale);
    return screen_point{x + cx8, y + cy8, depth};
  }

  /// test() in 32-bit fixed point: the homogeneous tests divided by W (see the file comment).
  /// A saturated centre is never a splat (refined instead) and is culled only when its clamped
  /// position is: the culling test grows monotonically towards the exact one when W − 2B > 0 and
  /// never culls otherwise, so saturation only keeps cells the exact tests might drop.
  [[nodiscard]] verdict test_projected(const hom& h, int l, bool leaf, float s, bool cull) const {
    const auto& t = levels[std::size_t(l)];
    if (h.w + t.b < znear) return may_cull.near ? verdict::cull : caster(l, leaf);
    const value den = h.w - t.b;
    if (!(den > znear)) return leaf ? verdict::draw : verdict::refine;
    const projection p = project(h, t);
    const auto small = [&] {  // s·2^G inline (s > 0; ldexp and llround are library calls)
      const double sg = std::min(double(s) * double(1 << screen_g), 0x1p30);
      const std::int64_t rhs = Arith::mul(den, value(sg + 0.5));
      return !p.saturated && 2 * p.ex <= rhs && 2 * p.ey <= rhs;
    };
    if (cull) {
      const std::int64_t xd = Arith::mul(p.x, den), yd = Arith::mul(p.y, den);
      const std::int64_t cxd = Arith::mul(cx, den), cyd = Arith::mul(cy, den);
      const bool far = den > zfar, left = (xd + p.ex < -cxd), right = (xd - p.ex > cxd),
                 top = (yd + p.ey < -cyd), bottom = (yd - p.ey > cyd);
      return decide({far, left, right, top, bottom}, l, leaf, small);
    }
    return decide({}, l, leaf, small);
  }

  /// test() in float or int64: products of two and three values, no division.
  [[nodiscard]] verdict test_homogeneous(const hom& h, int l, bool leaf, float s, bool cull) const {
    const auto& t = levels[std::size_t(l)];
    if (h.w + t.b < znear)  // wholly behind the viewer
      return may_cull.near ? verdict::cull : caster(l, leaf);
    const value den = h.w - t.b;
    if (!(den > znear)) return leaf ? verdict::draw : verdict::refine;  // straddles the eye plane
    const auto ex = Arith::mul(t.ax, h.w) + Arith::mul(t.b, h.x < 0 ? value(-h.x) : h.x);
    const auto ey = Arith::mul(t.ay, h.w) + Arith::mul(t.b, h.y < 0 ? value(-h.y) : h.y);
    const auto small = [&] {  // the splat condition (Eq. 6)
      const auto rhs = Arith::splat_scale(s) * Arith::mul(h.w, den);
      return Arith::lhs(ex) <= rhs && Arith::lhs(ey) <= rhs;
    };
    if (cull) {
      const auto wd = Arith::mul(h.w, den);
      // X·den ± E compared with ∓c·W·den: products of three values, taken in two steps so the
      // fixed-point path stays exact in 128 bits (c_x·W·den = c_x·(W·den)/scale).
      const auto xd = Arith::mul(h.x, den), yd = Arith::mul(h.y, den);
      const auto cxwd = scaled(cx, wd), cywd = scaled(cy, wd);
      const bool far = den > zfar, left = xd + ex<-cxwd, right = xd - ex> cxwd,
                 top = yd + ey<-cywd, bottom = yd - ey> cywd;
      return decide({far, left, right, top, bottom}, l, leaf, small);
    }
    return decide({}, l, leaf, small);
  }

  /// One screen axis of a cell's per-corner rectangle as fractions: every corner's
  /// x = (X + ΔX_k)/(W + ΔW_k) has its numerator in [X + mn, X + mx] and its denominator in
  /// [W + mnw, W + mxw] (positive: the cell is in front of the eye), so by interval division
  /// x ≤ (X + mx)/(W + mnw) when that numerator is ≥ 0, else ≤ (X + mx)/(W + mxw); likewise
  /// the minimum. With mn = −A, mnw = −B this is never wider than the symmetric bound, and
  /// narrower on the side away from the screen centre (its denominator W + B, not W − B).
  struct fraction {
    value n, d;
  };
  struct interval {
    fraction lo, hi;
  };
  [[nodiscard]] static interval corner_interval(value c, value mn, value mx, value dlo, value dhi) {
    const value lo = c + mn, hi = c + mx;
    return {{lo, lo >= value(0) ? dhi : dlo}, {hi, hi >= value(0) ? dlo : dhi}};
  }

  /// fixed32's per-corner rectangle: the four fractions of corner_interval() divided through
  /// the reciprocal table, two look-ups (min and max z/w, the only denominators), x and y with
  /// screen_g fractional bits from the principal point. Only called when W + min ΔW > z_near
  /// ≥ 0, so both denominators are ≥ 1 unit. The numerators X + ΔX are within 2^30 (choose_scale
  /// bounds |H| plus a cell's offsets), so they and the box sums stay in int32.
  struct projected_rectangle {
    std::int32_t x0, x1, y0, y1;
    bool saturated = false;  ///< a side reached ±2^30 units: clamped towards the screen
    interval ix, iy;         ///< the fractions divided
    value dlo;
    rho_reciprocal::value rlo, rhi;  ///< of the min and the max z/w
    [[nodiscard]] const rho_reciprocal::value& reciprocal(value d) const {
      return d == dlo ? rlo : rhi;
    }
  };
  [[nodiscard]] projected_rectangle project_corners(const hom& h, const corner_box& b) const {
    const value dlo = h.w + b.mn[2], dhi = h.w + b.mx[2];
    projected_rectangle r{};
    r.dlo = dlo;
    r.rlo = rho_reciprocal::of(std::uint32_t(dlo));
    r.rhi = rho_reciprocal::of(std::uint32_t(dhi));
    r.ix = corner_interval(h.x, b.mn[0], b.mx[0], dlo, dhi);
    r.iy = corner_interval(h.y, b.mn[1], b.mx[1], dlo, dhi);
    const auto q = [&](const fraction& f) {
      return rho_reciprocal::divide(std::int64_t(f.n) << screen_g, r.reciprocal(f.d), r.saturated);
    };
    r.x0 = q(r.ix.lo);
    r.x1 = q(r.ix.hi);
    r.y0 = q(r.iy.lo);
    r.y1 = q(r.iy.hi);
    return r;
  }

  /// test() with the per-corner bounds table. Float and int64 cross-multiply, no division:
  ///   splat condition   hi.n·lo.d − lo.n·hi.d ≤ s·hi.d·lo.d  (x and y; Eq. 6 on max x − min x)
  ///   frustum culling   hi.n < −c_x·hi.d (left), lo.n > c_x·lo.d (right), likewise y;
  ///                     W + min ΔW > z_far (beyond), W + max ΔW < z_near (behind)
  /// fixed32 divides through the reciprocal table instead (project_corners) and compares the
  /// rectangle's sides: x1 − x0 ≤ s, x1 < −c_x, x0 > c_x, likewise y. As in test_projected(), a
  /// saturated rectangle is never a splat; its clamped sides still lie beyond the screen's
  /// edges (2^30 units ≥ 64 half screens), so culling decides as without the clamp.
  [[nodiscard]] verdict test_per_corner(const hom& h, int l, bool leaf, float s, bool cull,
                                        const corner_box& b) const {
    const value dlo = h.w + b.mn[2], dhi = h.w + b.mx[2];  // the minimum and maximum z/w
    if (dhi < znear) return may_cull.near ? verdict::cull : caster(l, leaf);
    if (!(dlo > znear)) return leaf ? verdict::draw : verdict::refine;
    if constexpr (projective)
      return corners_projected(h, l, leaf, s, cull, b, dlo);
    else
      return corners_homogeneous(h, l, leaf, s, cull, b, dlo, dhi);
  }
  [[nodiscard]] verdict corners_projected(const hom& h, int l, bool leaf, float s, bool cull,
                                          const corner_box& b, value dlo) const {
    const projected_rectangle r = project_corners(h, b);
    const auto small = [&] {
      return !r.saturated && narrow_projected(r.ix, s, r.reciprocal(r.ix.hi.d)) &&
             narrow_projected(r.iy, s, r.reciprocal(r.iy.hi.d));
    };
    if (cull) {
      const bool far = dlo > zfar, left = (r.x1 < -cx), right = (r.x0 > cx), top = (r.y1 < -cy),
                 bottom = (r.y0 > cy);
      return decide({far, left, right, top, bottom}, l, leaf, small);
    }
    return decide({}, l, leaf, small);
  }
  /// fixed32's splat condition on one axis, hi.n/hi.d − lo.n/lo.d ≤ s, without the cancellation
  /// of subtracting the two divided sides (whose 2^-13 error is relative to their distance from
  /// the centre, not to the width): the exact int64 numerator N = hi.n·lo.d − lo.n·hi.d ≥ 0
  /// (products of two int32), then N/hi.d ≤ s·lo.d through hi.d's reciprocal `r`, both sides
  /// shifted by k bits so that the right one fits 29 bits (a left side that saturates is > 2×
  /// the right).
  [[nodiscard]] static bool narrow_projected(const interval& i, float s,
                                             const rho_reciprocal::value& r) {
    const std::int64_t n = std::int64_t(i.hi.n) * i.lo.d - std::int64_t(i.lo.n) * i.hi.d;
    const double rhs = std::min(double(s), 0x1p20) * double(i.lo.d);  // < 2^52
    const int k = std::max(0, int(std::bit_width(std::uint64_t(rhs))) - 29);
    bool sat = false;
    const std::int32_t lhs = rho_reciprocal::divide(n >> k, r, sat);
    return !sat && double(std::int64_t(lhs) << k) <= rhs;  // < 2^53: exact
  }
  [[nodiscard]] verdict corners_homogeneous(const hom& h, int l, bool leaf, float s, bool cull,
                                            const corner_box& b, value dlo, value dhi) const {
    const interval ix = corner_interval(h.x, b.mn[0], b.mx[0], dlo, dhi);
    const interval iy = corner_interval(h.y, b.mn[1], b.mx[1], dlo, dhi);
    const auto narrow = [&](const interval& i) {
      const auto spread = Arith::mul(i.hi.n, i.lo.d) - Arith::mul(i.lo.n, i.hi.d);
      return Arith::lhs(spread) <= 2 * Arith::splat_scale(s) * Arith::mul(i.hi.d, i.lo.d);
    };
    const auto small = [&] { return narrow(ix) && narrow(iy); };
    if (cull) {
      const bool far = dlo > zfar;
      const bool left = Arith::mul(ix.hi.n, unit) < -Arith::mul(cx, ix.hi.d);
      const bool right = Arith::mul(ix.lo.n, unit) > Arith::mul(cx, ix.lo.d);
      const bool top = Arith::mul(iy.hi.n, unit) < -Arith::mul(cy, iy.hi.d);
      const bool bottom = Arith::mul(iy.lo.n, unit) > Arith::mul(cy, iy.lo.d);
      return decide({far, left, right, top, bottom}, l, leaf, small);
    }
    return decide({}, l, leaf, small);
  }

  /// The per-corner rectangle of a cell in pixels from the principal point (y down), what
  /// test_per_corner() compares: empty (all NaN) when the cell reaches behind the near plane
  /// (fixed32: or its rectangle saturated).
  struct rectangle {
    double x0, x1, y0, y1;
  };
  [[nodiscard]] rectangle corner_rectangle(const hom& h, const corner_box& b) const {
    const value dlo = h.w + b.mn[2], dhi = h.w + b.mx[2];
    if (!(dlo > znear)) {
      constexpr double nan = std::numeric_limits<double>::quiet_NaN();
      return {nan, nan, nan, nan};
    }
    if constexpr (projective) {  // the tests' rectangle, rounded outwards
      const projected_rectangle r = project_corners(h, b);
      if (r.saturated) {
        constexpr double nan = std::numeric_limits<double>::quiet_NaN();
        return {nan, nan, nan, nan};
      }
      // Widened by twice the divisions' error bound (2^-13 of the distance from the principal
      // point) and two units, so the rectangle still contains every corner it bounds.
      const auto slack = [](std::int32_t q) {
        return double((std::int64_t(q < 0 ? -q : q) >> 12) + 2);
      };
      const double unit_px = std::ldexp(1.0, -screen_g);
      return {(r.x0 - slack(r.x0)) * unit_px, (r.x1 + slack(r.x1)) * unit_px,
              (r.y0 - slack(r.y0)) * unit_px, (r.y1 + slack(r.y1)) * unit_px};
    }
    const auto q = [](const fraction& f) { return double(f.n) / double(f.d); };  // scale-free
    const interval ix = corner_interval(h.x, b.mn[0], b.mx[0], dlo, dhi);
    const interval iy = corner_interval(h.y, b.mn[1], b.mx[1], dlo, dhi);
    return {q(ix.lo), q(ix.hi), q(iy.lo), q(iy.hi)};
  }

  /// A cell kept only for the shadows it casts.
  [[nodiscard]] verdict caster(int l, bool leaf) const {
    return leaf || l >= caster_depth ? verdict::draw : verdict::refine;
  }

  /// Which view tests a cell fails: beyond the far plane, off each side of the screen.
  struct outside {
    bool far = false, left = false, right = false, top = false, bottom = false;
  };
  /// The verdict once the tests are known: culled when a test that may cull fails; out of view
  /// but kept as a shadow caster; else drawn when small enough (Eq. 6) or a leaf, refined if not.
  template <class Small>
  [[nodiscard]] verdict decide(const outside& o, int l, bool leaf, const Small& small) const {
    if ((o.far && may_cull.far) || (o.left && may_cull.left) || (o.right && may_cull.right) ||
        (o.top && may_cull.top) || (o.bottom && may_cull.bottom))
      return verdict::cull;
    if (o.far || o.left || o.right || o.top || o.bottom)
      return small() ? verdict::draw : caster(l, leaf);
    if (small()) return verdict::draw;
    return leaf ? verdict::draw : verdict::refine;
  }

  /// The cell's conservative projected widths in pixels along x and y (2·E_x / (W·(W − B)) and
  /// 2·E_y / (W·(W − B)), what the splat test compares with s); +inf when the cell straddles
  /// the eye plane. Both sides are products of two values, so the ratios are free of the
  /// fixed-point scale.
  [[nodiscard]] std::array<float, 2> widths_px(const hom& h, int l) const {
    const auto& t = levels[std::size_t(l)];
    const value den = h.w - t.b;
    constexpr float inf = std::numeric_limits<float>::infinity();
    if (!(den > znear)) return {inf, inf};
    if constexpr (projective) {  // 2·E/(W − B) through the table, screen_g fraction bits
      const projection p = project(h, t);
      const auto r = rho_reciprocal::of(std::uint32_t(den));
      const auto px = [&](std::int64_t e) {
        bool sat = p.saturated;
        const std::int32_t w = rho_reciprocal::divide(2 * e, r, sat);
        return std::ldexp(float(sat ? 1 << 30 : w), -screen_g);  // saturated: ≥ 64 half screens
      };
      return {px(p.ex), px(p.ey)};
    } else {
      const auto ex = Arith::mul(t.ax, h.w) + Arith::mul(t.b, h.x < 0 ? value(-h.x) : h.x);
      const auto ey = Arith::mul(t.ay, h.w) + Arith::mul(t.b, h.y < 0 ? value(-h.y) : h.y);
      const double wd = static_cast<double>(Arith::mul(h.w, den));
      return {static_cast<float>(2 * static_cast<double>(ex) / wd),
              static_cast<float>(2 * static_cast<double>(ey) / wd)};
    }
  }
  /// The larger of widths_px(): what a square of the cell's projection needs (fixed32: one
  /// division, of the larger extent).
  [[nodiscard]] float width_px(const hom& h, int l) const {
    if constexpr (projective) {
      const auto& t = levels[std::size_t(l)];
      const value den = h.w - t.b;
      if (!(den > znear)) return std::numeric_limits<float>::infinity();
      const projection p = project(h, t);
      bool sat = p.saturated;
      const std::int32_t w = rho_reciprocal::divide(2 * std::max(p.ex, p.ey),
                                                    rho_reciprocal::of(std::uint32_t(den)), sat);
      return std::ldexp(float(sat ? 1 << 30 : w), -screen_g);  // saturated: ≥ 64 half screens
    } else {
      const auto w = widths_px(h, l);
      return std::max(w[0], w[1]);
    }
  }

  /// c·p / scale for a wide product p (float: c·p).
  [[nodiscard]] auto scaled(value c, const typename Arith::wide& p) const {
    if constexpr (std::is_same_v<value, float>)
      return c * p;
    else
      return typename Arith::wide(c) * p /
             typename Arith::wide(static_cast<std::int64_t>(arith.scale));
  }
};

}  // namespace detail

/// The side of a light-map texel of render_one_pass_shadows over g with a map of `texels` per
/// side (render_options::shadow_map_size): the map spans the diameter of the root cube's
/// bounding sphere. What rho_grid_policy::cast_shadows refines off-screen casters to.
template <int Rho>
[[nodiscard]] double rho_grid_caster_side(const rho_grid<Rho>& g, int texels) {
  return std::sqrt(3.0) * g.cube_side() / double(std::max(2, texels));
}

/// The child visiting order that is front to back from a directional light (§4.2, Fig. 3):
/// children sorted by decreasing projection of their centre offsets on `to_light` (the direction
/// towards the light); ties keep digit order. For cubes of one grid, a child that occludes
/// another along the light has a strictly larger projection, so this order never draws an
/// occluder after what it shadows.
template <int Rho>
[[nodiscard]] std::array<int, Rho * Rho * Rho> rho_grid_light_order(const vec3f& to_light) {
  std::array<int, Rho * Rho * Rho> ord;
  std::iota(ord.begin(), ord.end(), 0);
  const vec3d l = to_light.cast<double>();
  const auto proj = [&](int j) { return l.dot(vec3d(j % Rho, (j / Rho) % Rho, j / (Rho * Rho))); };
  std::stable_sort(ord.begin(), ord.end(), [&](int a, int b) { return proj(a) > proj(b); });
  return ord;
}

/// The §4.1 traversal as a policy of traverse(): per-entry state H = (X, Y, W), visit() = the
/// bounds-table tests (they replace the bounding-sphere culling and size estimate), children in
/// a fixed order (digit order unless given), inner cells emitted as s-pixel squares with
/// s = traverse_options::tolerance_px. Built for one view: pass traverse() the same view.
///   rho_grid_hierarchy<3, with_normals> h(g);
///   const view v(cam, g.origin());
///   traverse(h, v, {.tolerance_px = s}, sink, rho_grid_policy<3>(g, v));
/// traverse_options: tolerance_px is s, frustum_cull switches the off-screen and far tests;
/// metric, cull_volume and backface_cull do not apply. Stats: emitted_nodes = inner cells drawn
/// as splats, emitted_leaves = leaves drawn as points, culled_frustum = subtrees culled.
/// Bounds picks the cell bound of the tests (rho_grid_bounds): per_corner visits and draws fewer
/// cells at the same s (docs/rho-grid.md measures it), in every arithmetic.
template <int Rho, rho_grid_arithmetic Arith = rho_grid_arithmetic::floating,
          rho_grid_bounds Bounds = rho_grid_bounds::symmetric>
class rho_grid_policy {
  static constexpr int R3 = Rho * Rho * Rho;
  static constexpr bool per_corner = Bounds == rho_grid_bounds::per_corner;
  using arith =
      std::conditional_t<Arith == rho_grid_arithmetic::fixed, detail::rho_fixed_arith,
                         std::conditional_t<Arith == rho_grid_arithmetic::fixed32,
                                            detail::rho_fixed32_arith, detail::rho_float_arith>>;
  using tables = detail::rho_traversal<Rho, arith>;

 public:
  using state = typename tables::hom;

  /// Tables for grid g seen by v (relative to g.origin()); children visited in `order` (a
  /// permutation of 0..ρ³−1, e.g. rho_grid_light_order) or in digit order.
  rho_grid_policy(const rho_grid<Rho>& g, const view& v, const std::array<int, R3>* order = nullptr)
      : t_(g, v), digit_order_(order == nullptr) {
    if (order)
      order_ = *order;
    else
      std::iota(order_.begin(), order_.end(), 0);
  }

  template <class H>
  [[nodiscard]] state root_state(const H&, const view&, const traverse_options&) const {
    return t_.root;
  }

  /// For one-pass shadows (§4.2) with frustum culling: cells outside the view volume that may
  /// shadow a point inside it (the volume swept away from the light `to_light`, unit, world
  /// axes) are still traversed and emitted — down to a side of `caster_side`, one light-map
  /// texel (rho_grid_caster_side) — so that the light map holds them; the rasteriser clips them.
  /// Without this an occluder outside the frame casts no shadow into it. g and v as constructed.
  void cast_shadows(const rho_grid<Rho>& g, const view& v, const vec3f& to_light,
                    double caster_side) {
    t_.cast_shadows(g, v, to_light, caster_side);
  }

  /// The paper's non-flexible "Points" display (§5.3, Table 3): every leaf in view as a
  /// one-pixel point, inner cells refined whatever their size (no multi-level splats); the
  /// cells are still culled against the view volume on the way down.
  bool points_only = false;
  /// §4.1's close views without holes: a leaf drawn as a square of its cell's conservative
  /// projected width (with per-corner bounds and screen_draw: its cell's screen rectangle), or a
  /// one-pixel point when that is at most a pixel, so that leaves larger than a pixel still
  /// cover their cell. On by default; off, every leaf is a one-pixel point as the paper draws
  /// them, which leaves holes once leaves project larger than a pixel (docs/rho-grid.md).
  bool leaf_splats = true;
  /// §5.1 and §4.1 drawing: a drawn cell goes to a sink that takes screen rectangles
  /// (ScreenRectSink: the rasteriser, buffer_sink) as a screen_rect_prim placed from the
  /// traversal's H divided by W in the policy's arithmetic (fixed32: through the reciprocal table
  /// of its tests), not from the sink's float re-projection of the cell centre; with per-corner
  /// bounds an inner cell, and a leaf_splats leaf, covers its per-corner rectangle (the box of
  /// its sampled children; a leaf's cell) instead of a square at its centre. A cell without a
  /// screen position (W not beyond z_near, or saturated) and every cell sent to a sink without
  /// the hook go as the point_prim they get when this is off. Off by default (docs/rho-grid.md
  /// measures both).
  bool screen_draw = false;

  template <class H>
  [[nodiscard]] visit_result visit(const H& h, const rho_grid_cell& n, const state& hs, const view&,
                                   const traverse_options& o) const {
    using verdict = typename tables::verdict;
    const bool leaf = h.is_leaf(n);
    const float s = splat_size(o);
    const verdict vd = test(h, n, hs, leaf, s, o.frustum_cull);
    if (vd == verdict::cull) return {visit_result::verdict::cull, 0};
    if (points_only)
      return leaf ? visit_result{visit_result::verdict::emit, 1.0f}
                  : visit_result{visit_result::verdict::refine, s};
    if (leaf && leaf_splats) {
      const float w = leaf_width(h, n, hs);  // +inf: straddles the eye plane, a point
      return {visit_result::verdict::emit, std::isfinite(w) ? std::clamp(w, 1.0f, 1e4f) : 1.0f};
    }
    if (vd == verdict::draw) return {visit_result::verdict::emit, leaf ? 1.0f : s};
    return {visit_result::verdict::refine, s};
  }

  template <class H, class F>
  void for_each_child(const H& h, const rho_grid_cell& n, const state& hs, F&& f) const {
    for_each_child_digit(h, n, [&](int j, std::uint32_t cell) {
      f(H::child(n, j, cell), child_state(hs, n.depth, j));
    });
  }

  template <class H, class S>
  void emit(const H& h, const rho_grid_cell& n, const view&, float size_px, const traverse_options&,
            S& sink) const {
    h.emit_sample(n, size_px, sink);
  }
  /// emit() with the cell's H (traverse() calls this one): screen_draw's rectangle to a sink that
  /// takes it, else emit() above.
  template <class H, class S>
  void emit(const H& h, const rho_grid_cell& n, const state& hs, const view& v, float size_px,
            const traverse_options& o, S& sink) const {
    if constexpr (ScreenRectSink<S, H::attrs>) {
      if (screen_draw)
        if (const auto r = screen_rect(h, n, hs, size_px)) {
          h.emit_rect(n, *r, sink);
          return;
        }
    }
    emit(h, n, v, size_px, o, sink);
  }

  /// The pixels and depth of cell n drawn by screen_draw at visit()'s size_px: a square of
  /// size_px (≤ 1: the pixel containing the centre) about the centre from H; with per-corner
  /// bounds, an inner cell's or a leaf_splats leaf's per-corner rectangle. Empty when the cell
  /// has no screen position (then it is drawn from its 3-D position).
  template <class H>
  [[nodiscard]] std::optional<rho_grid_screen_rect> screen_rect(const H& h, const rho_grid_cell& n,
                                                                const state& hs,
                                                                float size_px) const {
    const auto c = t_.screen_position(hs);
    if (!c) return std::nullopt;
    constexpr std::int64_t lim = tables::rect_limit + (std::int64_t(1) << 29);
    const auto fix = [](std::int64_t q) {
      return std::int32_t(q < -lim ? -lim : q > lim ? lim : q);
    };
    rho_grid_screen_rect r{};
    r.depth = c->depth;
    if constexpr (per_corner) {
      const bool leaf = h.is_leaf(n);
      if (!points_only && (!leaf || leaf_splats)) {
        const auto b = t_.corner_rectangle(hs, box(h, n, leaf));
        if (!std::isnan(b.x0)) {  // pixels from the principal point: widened to 1/256 pixel
          constexpr double one = double(1 << tables::rect_bits), dlim = double(lim);
          const auto lo = [&](double q, std::int64_t c0) {
            return fix(std::int64_t(std::floor(std::clamp(q * one, -dlim, dlim))) + c0);
          };
          const auto hi = [&](double q, std::int64_t c0) {
            return fix(std::int64_t(std::ceil(std::clamp(q * one, -dlim, dlim))) + c0);
          };
          r.x0 = lo(b.x0, t_.cx8);
          r.x1 = hi(b.x1, t_.cx8);
          r.y0 = lo(b.y0, t_.cy8);
          r.y1 = hi(b.y1, t_.cy8);
          return r;
        }
      }
    }
    if constexpr (!per_corner) {
      // A leaf_splats leaf larger than a pixel: its symmetric bound as a rectangle (the two
      // half extents of the tests), no wider than the square of the larger one.
      if (size_px > 1 && leaf_splats && !points_only && h.is_leaf(n)) {
        const auto w = t_.widths_px(hs, n.depth);
        if (std::isfinite(w[0]) && std::isfinite(w[1])) {
          const auto half_of = [](float wp) {
            return std::int64_t(std::min(wp, 1e6f) * float(1 << (tables::rect_bits - 1)));
          };
          const std::int64_t hx = half_of(w[0]), hy = half_of(w[1]);
          r.x0 = fix(c->x - hx);
          r.x1 = fix(c->x + hx);
          r.y0 = fix(c->y - hy);
          r.y1 = fix(c->y + hy);
          return r;
        }
      }
    }
    // size_px ≤ 1: half = 0, the pixel containing the centre (point()'s one-pixel rule).
    const std::int64_t half =
        size_px > 1 ? std::int64_t(std::min(size_px, 1e6f) * float(1 << (tables::rect_bits - 1)))
                    : 0;
    r.x0 = fix(c->x - half);
    r.x1 = fix(c->x + half);
    r.y0 = fix(c->y - half);
    r.y1 = fix(c->y + half);
    return r;
  }

  template <class H>
  [[nodiscard]] auto test(const H& h, const rho_grid_cell& n, const state& hs, bool leaf, float s,
                          bool cull) const {
    if constexpr (per_corner)
      return t_.test_per_corner(hs, n.depth, leaf, s, cull, box(h, n, leaf));
    else
      return t_.test(hs, n.depth, leaf, s, cull);
  }
  /// The per-corner bound's box: the sampled children's, a leaf's whole cell.
  template <class H>
  [[nodiscard]] auto box(const H& h, const rho_grid_cell& n, bool leaf) const {
    const std::array<int, 3> whole{Rho - 1, Rho - 1, Rho - 1};
    return t_.children_box(n.depth, leaf ? whole : tables::spans(h.grid().code(n.cell)));
  }

  /// A leaf's projected width for leaf_splats: the larger side of the bound the tests use.
  template <class H>
  [[nodiscard]] float leaf_width(const H& h, const rho_grid_cell& n, const state& hs) const {
    if constexpr (per_corner) {
      const auto r = t_.corner_rectangle(hs, box(h, n, true));
      const double w = std::max(r.x1 - r.x0, r.y1 - r.y0);
      return std::isnan(w) ? std::numeric_limits<float>::infinity() : float(w);
    } else {
      return t_.width_px(hs, n.depth);
    }
  }

  /// s: the tolerance, or 1 when it is not a positive number.
  [[nodiscard]] static float splat_size(const traverse_options& o) {
    return std::isfinite(o.tolerance_px) && o.tolerance_px > 0 ? o.tolerance_px : 1.0f;
  }

 protected:
  /// Calls visit_child(j, cell) for inner cell n's children, digit j and cell index, in the
  /// policy's order.
  template <class H, class F>
  void for_each_child_digit(const H& h, const rho_grid_cell& n, F&& visit_child) const {
    const auto& code = h.grid().code(n.cell);
    std::uint32_t cell = h.grid().first_child(n.cell);
    if (digit_order_) {
      // Digit order is the child table's: walk the set bits, no rank per child.
      using word = typename rho_grid<Rho>::code_type::word;
      constexpr int word_bits = rho_grid<Rho>::code_type::word_bits;
      for (std::size_t i = 0; i < code.w.size(); ++i)
        for (word bits = code.w[i]; bits != 0; bits = word(bits & (bits - 1)))
          visit_child(int(i) * word_bits + std::countr_zero(bits), cell++);
      return;
    }
    for (const int j : order_)
      if (code.test(j)) visit_child(j, cell + std::uint32_t(code.rank(j)));
  }
  /// Child j's H from its parent's (depth: the parent's): one displacement-table addition.
  [[nodiscard]] state child_state(const state& hs, int depth, int j) const {
    const auto& d = t_.levels[std::size_t(depth) + 1].disp[std::size_t(j)];
    return state{hs.x + d.x, hs.y + d.y, hs.w + d.w};
  }

 private:
  tables t_;
  bool digit_order_;
  std::array<int, R3> order_;
};

/// §4.2's extra displacement table: rho_grid_policy whose per-entry state also carries the
/// cell centre's light-map coordinates (light_map_frame::coords: texel u, v and the distance
/// from the light), the root's projected once and each child's its parent's plus a per-depth
/// table entry — three more additions per visited cell, as H's. render_one_pass_shadows hands
/// them to the light map, which then projects nothing. Build it for the frame of the map it
/// draws into, one_pass_light_frame(h, o) (render_one_pass_shadows checks):
///   const auto order = rho_grid_light_order<3>(o.sun.direction.normalized());
///   rho_grid_light_policy<3> p(g, v, one_pass_light_frame(h, o), &order);
///   image img = render_one_pass_shadows(h, v, o, t, p);
/// The coordinates are float sums of ≤ leaf depth table entries: within 10⁻³ texel of a direct
/// projection of the centre (RhoGridShadows.LightTableMatchesProjection).
template <int Rho, rho_grid_arithmetic Arith = rho_grid_arithmetic::floating,
          rho_grid_bounds Bounds = rho_grid_bounds::symmetric>
class rho_grid_light_policy : public rho_grid_policy<Rho, Arith, Bounds> {
  using base = rho_grid_policy<Rho, Arith, Bounds>;
  static constexpr int R3 = Rho * Rho * Rho;

 public:
  struct state : base::state {
    vec3f light_coords;  ///< the cell centre's light_map_frame::coords
  };

  rho_grid_light_policy(const rho_grid<Rho>& g, const view& v, const light_map_frame& light,
                        const std::array<int, R3>* order = nullptr)
      : base(g, v, order), frame_(light) {
    const double root_half = 0.5 * g.cube_side();
    root_light_ = light.coords(vec3d::Constant(root_half).cast<float>());
    table_.resize(std::size_t(g.leaf_depth()) + 1);
    for (std::size_t d = 1; d < table_.size(); ++d) {
      const double side = g.cell_side(int(d));
      for (int j = 0; j < R3; ++j) {
        const vec3d o = side * vec3d(double(j % Rho) + 0.5 - 0.5 * Rho,
                                     double((j / Rho) % Rho) + 0.5 - 0.5 * Rho,
                                     double(j / (Rho * Rho)) + 0.5 - 0.5 * Rho);
        table_[d][std::size_t(j)] = light.offset(o);
      }
    }
  }

  [[nodiscard]] const light_map_frame& light_frame() const { return frame_; }

  template <class H>
  [[nodiscard]] state root_state(const H& h, const view& v, const traverse_options& o) const {
    return state{base::root_state(h, v, o), root_light_};
  }

  template <class H, class F>
  void for_each_child(const H& h, const rho_grid_cell& n, const state& hs, F&& f) const {
    const auto& tab = table_[std::size_t(n.depth) + 1];
    this->for_each_child_digit(h, n, [&](int j, std::uint32_t cell) {
      f(H::child(n, j, cell),
        state{this->child_state(hs, n.depth, j), hs.light_coords + tab[std::size_t(j)]});
    });
  }

 private:
  light_map_frame frame_;
  vec3f root_light_;
  std::vector<std::array<vec3f, R3>> table_;  // [depth][j]: child j's offset from its parent
};

static_assert(Hierarchy<rho_grid_hierarchy<3, positions_only>>);
static_assert(Hierarchy<rho_grid_hierarchy<2, attributes{.normal = true, .colour = true}>>);

}  // namespace pbr_lod
