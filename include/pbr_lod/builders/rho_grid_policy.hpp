// pbr_lod — the ρ-grid's §4.1 traversal as a policy of the common traverse(), with §4.2's light
// order and light-space table (Duguet & Drettakis 2004). What the policy computes, paper section
// by section, is in builders/rho_grid_hierarchy.hpp's opening comment; the tests themselves in
// detail/rho_grid_traversal.hpp over the arithmetics of detail/rho_grid_arith.hpp.
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
#include "pbr_lod/builders/detail/rho_grid_traversal.hpp"
#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/builders/rho_grid_hierarchy.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/light_map_frame.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

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

}  // namespace pbr_lod
