// pbr_lod — the ρ-grid's §4.1 traversal state and tests, written once over the arithmetic
// (detail/rho_grid_arith.hpp): the per-depth displacement and bounds tables, the splat condition
// and frustum tests on H = (X, Y, W), the screen rectangles of screen_draw. rho_grid_policy
// (builders/rho_grid_policy.hpp) is its face to traverse(); the map of the paper is in
// builders/rho_grid_hierarchy.hpp.
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

#include "pbr_lod/builders/detail/rho_grid_arith.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/builders/rho_grid_hierarchy.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod::detail {

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

}  // namespace pbr_lod::detail
