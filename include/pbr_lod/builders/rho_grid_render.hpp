// pbr_lod — flexible rendering of ρ-grids (Duguet & Drettakis 2004, §4, §4.1, §4.2, §5.1).
//
// The traversal is the paper's Render(cell, centre, level), with Botsch et al.'s transformation
// factorisation: the homogeneous screen position H = (X, Y, W) of a cell centre is its parent's
// plus an entry of a per-level displacement table (one vec add per cell, no matrix product), and
// the conservative screen bounds of a cell come from a per-level bounds table:
//   A_x = max over the cube's corners of |ΔX|, A_y likewise, B = max |ΔW|.
// With E_x = A_x·W + B·|X|, every corner's x = X'/W' lies within E_x / (W·(W − B)) of X/W
// (while W − B > 0: the cell is wholly in front of the eye). So, all in homogeneous coordinates
// without a division (§4.1, Eq. 6):
//   splat condition   2·E_x ≤ s·W·(W − B)  and  2·E_y ≤ s·W·(W − B)
//   frustum culling   X·(W − B) + E_x < −c_x·W·(W − B)  (left of the screen; likewise right,
//                     top, bottom), W − B > z_far (beyond), W + B < z_near (behind the viewer)
// A cell meeting the splat condition is drawn as a square splat of s pixels (an inner cell's
// intermediate sample) or a point (a leaf); a leaf is drawn as a point in any case; a cell that
// straddles the near plane is refined. X is measured from the principal point, so |X| is small
// near the screen centre. The traversal emits into any Sink: the shared rasteriser draws.
//
// §5.1 fixed point: the same traversal with H, the displacement and bounds tables in 64-bit
// fixed point (F fractional bits chosen per view so every |value| < 2^40) and the tests in
// 128-bit products. Cells where the two disagree are those whose test is within rounding of
// equality (measured in docs/rho-grid.md; the tests bound it).
//
// §4.2 one-pass shadows for a directional light: the ρ³ children are visited in a fixed
// per-light order (decreasing projection of the child centre offsets on the direction to the
// light), so the traversal is front to back from the light; each drawn sample looks up and then
// writes an orthographic light map as it is drawn, and is shaded lit or in shadow at once.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <numeric>
#include <vector>

#include "pbr_lod/builders/rho_grid.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {

enum class rho_grid_arithmetic { floating, fixed };

struct rho_grid_render_options {
  /// s, the splat size in pixels (§4.1; the paper uses 1). Larger: fewer, bigger splats.
  float splat_px = 1;
  bool frustum_cull = true;
  /// Float or the §5.1 fixed-point traversal.
  rho_grid_arithmetic arithmetic = rho_grid_arithmetic::floating;
  /// Shading, shadows (two-pass map of the shared rasteriser), background, light.
  render_options raster{};
};

struct rho_grid_traverse_stats {
  std::size_t visited = 0;            ///< cells tested
  std::size_t culled = 0;             ///< subtrees rejected by the frustum tests
  std::size_t splats = 0;             ///< inner cells drawn as splats (splat condition met)
  std::size_t points = 0;             ///< leaves drawn as points
  std::size_t lit = 0, shadowed = 0;  ///< one-pass shadows: samples classified
};

/// One drawn cell.
struct rho_grid_cell_ref {
  std::uint32_t cell;
  int level;
  std::array<std::uint32_t, 3> pos;  ///< integer position in [0, ρ^level)³
  bool leaf;
};

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
};

template <int Rho, class Arith>
struct rho_traversal {
  static constexpr int R3 = Rho * Rho * Rho;
  using value = typename Arith::value;
  struct hom {
    value x, y, w;
  };
  struct level_tables {
    std::array<hom, R3> disp;  ///< H offset of child j's centre from its parent's
    value ax, ay, b;           ///< bounds table: max |ΔX|, |ΔY|, |ΔW| over the cell's corners
  };
  Arith arith;
  hom root{};
  std::vector<level_tables> levels;
  value cx{}, cy{}, znear{}, zfar{};

  rho_traversal(const rho_grid<Rho>& g, const view& v, bool fixed) {
    // Rows of the map p ↦ (X, Y, W) in pixels × depth, relative to the principal point.
    const vec3d r = v.right.cast<double>() * double(v.focal_px);
    const vec3d u = -v.up.cast<double>() * double(v.focal_px);
    const vec3d f = v.forward.cast<double>();
    const vec3d c0 = vec3d::Constant(0.5 * g.cube_side()) - v.eye.cast<double>();
    const std::array<double, 3> h0{r.dot(c0), u.dot(c0), f.dot(c0)};
    struct dl {
      std::array<std::array<double, 3>, R3> d;
      double ax, ay, b;
    };
    std::vector<dl> dt(std::size_t(g.depth()) + 1);
    double bound = std::max({std::abs(h0[0]), std::abs(h0[1]), std::abs(h0[2])});
    for (int l = 0; l <= g.depth(); ++l) {
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
    bound = std::max({bound, double(v.z_far), 0.5 * double(v.width), 0.5 * double(v.height)});
    if (fixed) {
      // F fractional bits so that every value stays below 2^40 (products below 2^81 in int128).
      const int f_bits = std::clamp(40 - int(std::ceil(std::log2(std::max(bound, 1e-300)))), 0, 40);
      arith.scale = std::ldexp(1.0, f_bits);
    }
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
    }
    cx = arith.from(0.5 * v.width);
    cy = arith.from(0.5 * v.height);
    znear = arith.from(double(v.z_near));
    zfar = arith.from(double(v.z_far));
  }

  enum class verdict { cull, draw, refine };

  /// The §4.1 tests for a cell at level l with homogeneous centre h.
  [[nodiscard]] verdict test(const hom& h, int l, bool leaf, float s, bool cull) const {
    const auto& t = levels[std::size_t(l)];
    if (h.w + t.b < znear) return verdict::cull;  // wholly behind the viewer
    const value den = h.w - t.b;
    if (!(den > znear)) return leaf ? verdict::draw : verdict::refine;  // straddles the eye plane
    const auto ex = Arith::mul(t.ax, h.w) + Arith::mul(t.b, h.x < 0 ? value(-h.x) : h.x);
    const auto ey = Arith::mul(t.ay, h.w) + Arith::mul(t.b, h.y < 0 ? value(-h.y) : h.y);
    if (cull) {
      if (den > zfar) return verdict::cull;
      const auto wd = Arith::mul(h.w, den);
      // X·den ± E compared with ∓c·W·den: products of three values, taken in two steps so the
      // fixed-point path stays exact in 128 bits (c_x·W·den = c_x·(W·den)/scale).
      const auto xd = Arith::mul(h.x, den), yd = Arith::mul(h.y, den);
      const auto cxwd = scaled(cx, wd), cywd = scaled(cy, wd);
      if (xd + ex < -cxwd || xd - ex > cxwd || yd + ey < -cywd || yd - ey > cywd)
        return verdict::cull;
    }
    const auto rhs = Arith::splat_scale(s) * Arith::mul(h.w, den);
    if (Arith::lhs(ex) <= rhs && Arith::lhs(ey) <= rhs) return verdict::draw;
    return leaf ? verdict::draw : verdict::refine;
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

/// The flexible traversal (§4): visits the cells of g seen by v (built relative to g.origin()),
/// calls draw(rho_grid_cell_ref, bool splat) for every cell drawn, children in `order` (a
/// permutation of 0..ρ³−1; null = digit order). Returns what it did.
template <int Rho, class Draw>
rho_grid_traverse_stats rho_grid_traverse(const rho_grid<Rho>& g, const view& v,
                                          const rho_grid_render_options& o, Draw&& draw,
                                          const std::array<int, Rho * Rho * Rho>* order = nullptr) {
  rho_grid_traverse_stats st;
  if (g.empty()) return st;
  const auto run = [&](auto arith_tag) {
    using A = decltype(arith_tag);
    const detail::rho_traversal<Rho, A> t(g, v, std::is_same_v<A, detail::rho_fixed_arith>);
    using hom = typename detail::rho_traversal<Rho, A>::hom;
    struct entry {
      std::uint32_t cell;
      int level;
      std::array<std::uint32_t, 3> pos;
      hom h;
    };
    std::vector<entry> stack;
    stack.reserve(256);
    stack.push_back({0, 0, {0, 0, 0}, t.root});
    const float s = std::isfinite(o.splat_px) && o.splat_px > 0 ? o.splat_px : 1.0f;
    while (!stack.empty()) {
      const entry e = stack.back();
      stack.pop_back();
      ++st.visited;
      const bool leaf = g.is_leaf(e.cell);
      const auto vd = t.test(e.h, e.level, leaf, s, o.frustum_cull);
      using verdict = typename detail::rho_traversal<Rho, A>::verdict;
      if (vd == verdict::cull) {
        ++st.culled;
        continue;
      }
      if (vd == verdict::draw) {
        if (leaf)
          ++st.points;
        else
          ++st.splats;
        draw(rho_grid_cell_ref{e.cell, e.level, e.pos, leaf}, !leaf);
        continue;
      }
      const auto& code = g.code(e.cell);
      const std::uint32_t first = g.first_child(e.cell);
      const auto& tab = t.levels[std::size_t(e.level) + 1];
      // Push in reverse visiting order so the stack pops children in `order`.
      for (int k = Rho * Rho * Rho; k-- > 0;) {
        const int j = order ? (*order)[std::size_t(k)] : k;
        if (!code.test(j)) continue;
        const auto& d = tab.disp[std::size_t(j)];
        const std::array<std::uint32_t, 3> p{e.pos[0] * Rho + std::uint32_t(j % Rho),
                                             e.pos[1] * Rho + std::uint32_t((j / Rho) % Rho),
                                             e.pos[2] * Rho + std::uint32_t(j / (Rho * Rho))};
        stack.push_back({first + std::uint32_t(code.rank(j)), e.level + 1, p,
                         hom{e.h.x + d.x, e.h.y + d.y, e.h.w + d.w}});
      }
    }
  };
  if (o.arithmetic == rho_grid_arithmetic::fixed)
    run(detail::rho_fixed_arith{});
  else
    run(detail::rho_float_arith{});
  return st;
}

/// Centre of a drawn cell relative to g.origin().
template <int Rho>
[[nodiscard]] vec3f rho_grid_cell_centre(const rho_grid<Rho>& g, const rho_grid_cell_ref& c) {
  const double s = g.cell_side(c.level);
  return vec3f(float((double(c.pos[0]) + 0.5) * s), float((double(c.pos[1]) + 0.5) * s),
               float((double(c.pos[2]) + 0.5) * s));
}

/// The colour of material m (8-entry palette, repeated).
[[nodiscard]] inline rgb8 rho_grid_material_colour(std::uint32_t m) {
  static constexpr std::array<rgb8, 8> palette{
      rgb8{200, 200, 200}, rgb8{220, 80, 60},  rgb8{80, 180, 90},  rgb8{70, 110, 210},
      rgb8{230, 200, 70},  rgb8{170, 90, 200}, rgb8{70, 200, 200}, rgb8{240, 140, 60}};
  return palette[m % 8];
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

namespace detail {
template <attributes A, int Rho, class S>
rho_grid_traverse_stats rho_grid_draw(const rho_grid<Rho>& g, const view& v,
                                      const rho_grid_render_options& o, const normal_quantizer* q,
                                      S& sink) {
  return rho_grid_traverse(g, v, o, [&](const rho_grid_cell_ref& c, bool splat) {
    point_prim<A> p{rho_grid_cell_centre(g, c), splat ? o.splat_px : 1.0f};
    if constexpr (A.normal) p.normal = q->decode(g.normal_code(c.cell));
    if constexpr (A.colour) p.colour = rho_grid_material_colour(g.material(c.cell));
    sink.point(p);
  });
}
}  // namespace detail

/// Renders g seen by the world camera cam with the shared rasteriser (shading and the two-pass
/// shadow map as requested in o.raster.fx). Primitives carry normals when g has them and
/// material colours when it has materials.
template <int Rho>
[[nodiscard]] image render_rho_grid(const rho_grid<Rho>& g, const camera& cam,
                                    const rho_grid_render_options& o,
                                    rho_grid_traverse_stats* stats = nullptr) {
  const view v(cam, g.origin());
  // One table per process (normal_quantizer::shared), not one per frame.
  std::shared_ptr<const normal_quantizer> q;
  if (g.has_normals()) q = normal_quantizer::shared(g.normal_bits());
  rho_grid_traverse_stats st;
  const auto go = [&]<attributes A>() {
    return render<A>(v, o.raster,
                     [&](auto& sink) { st = detail::rho_grid_draw<A>(g, v, o, q.get(), sink); });
  };
  image img;
  if (g.has_normals() && g.has_materials())
    img = go.template operator()<attributes{.normal = true, .colour = true}>();
  else if (g.has_normals())
    img = go.template operator()<attributes{.normal = true}>();
  else if (g.has_materials())
    img = go.template operator()<attributes{.colour = true}>();
  else
    img = go.template operator()<attributes{}>();
  if (stats) *stats = st;
  return img;
}

/// §4.2: shading and shadows from the directional light o.raster.sun in one traversal, front to
/// back from the light. Each drawn sample's light-space position picks a texel of an
/// orthographic light map of `o.raster.shadow_map_size`² texels over the cube; the sample is in
/// shadow when a sample drawn before it (hence nearer the light) wrote that texel with its
/// cell's far extent (centre depth + half its cell diagonal) nearer than the near extent of the
/// sample's own cell less shadow_bias_texels texels; it then writes its footprint (disk of half
/// its cell side) into the map. Comparing extents, not centres, keeps a coarse splat from
/// shadowing the finer cells of the surface it lies on (test APlaneCastsNoShadowOnItself). The
/// colour is the material (or flat) colour × Lambert (two-sided) when lit, × ambient in shadow —
/// what the rasteriser's two-pass shadows compose. Needs normals (throws InvalidArgument otherwise)
/// and a non-zero light direction.
template <int Rho>
[[nodiscard]] image render_rho_grid_one_pass_shadows(const rho_grid<Rho>& g, const camera& cam,
                                                     const rho_grid_render_options& o,
                                                     rho_grid_traverse_stats* stats = nullptr) {
  if (!g.has_normals())
    throw InvalidArgument("rho-grid: one-pass shadows need normals (the grid stores none)");
  const vec3f dir = o.raster.sun.direction;
  if (!all_finite(dir) || !(dir.squaredNorm() > 0))
    throw InvalidArgument("rho-grid: one-pass shadows need a non-zero light direction");
  const vec3f L = dir.normalized();
  const view v(cam, g.origin());
  const auto shared_q = normal_quantizer::shared(g.normal_bits());
  const normal_quantizer& q = *shared_q;
  // Orthographic light frame over the cube.
  const vec3f lu = any_orthogonal(L), lv = L.cross(lu);
  const float half = float(0.5 * std::sqrt(3.0) * g.cube_side());
  const vec3f c0 = vec3f::Constant(float(0.5 * g.cube_side()));
  const int n = std::max(2, o.raster.shadow_map_size);
  const float texel = 2 * half / float(n);
  std::vector<float> depth(std::size_t(n) * std::size_t(n), std::numeric_limits<float>::infinity());
  const float ambient =
      std::isfinite(o.raster.sun.ambient) ? std::clamp(o.raster.sun.ambient, 0.0f, 1.0f) : 0.0f;
  constexpr attributes A{.colour = true};
  render_options ro = o.raster;
  ro.fx = effects{.colour = true,
                  .backface_cull = false,
                  .shadows = false,
                  .hole_filling = o.raster.fx.hole_filling};
  const auto order = rho_grid_light_order<Rho>(L);
  rho_grid_traverse_stats st;
  std::size_t n_lit = 0, n_shadowed = 0;
  image img = render<A>(v, ro, [&](auto& sink) {
    st = rho_grid_traverse(
        g, v, o,
        [&](const rho_grid_cell_ref& c, bool splat) {
          const vec3f p = rho_grid_cell_centre(g, c);
          const vec3f d = p - c0;
          const float tu = (d.dot(lu) + half) / texel, tv = (d.dot(lv) + half) / texel;
          const float z = -d.dot(L);  // distance from the light, up to a constant
          const float side = float(g.cell_side(c.level));
          const int ix = std::clamp(int(tu), 0, n - 1), iy = std::clamp(int(tv), 0, n - 1);
          // The sample's surface lies within its cell, r = half the cell's diagonal from the
          // centre. The map holds each occluder's far extent (centre + its own r), so a sample
          // is shadowed only by a cell wholly nearer the light than the sample's cell: a coarse
          // splat beside a leaf (mixed levels, s ≥ 2) no longer shadows the surface it lies on.
          const float r = 0.5f * std::sqrt(3.0f) * side;
          const bool shadowed = depth[std::size_t(iy) * std::size_t(n) + std::size_t(ix)] <
                                z - r - o.raster.shadow_bias_texels * texel;
          // Footprint: the texels whose centres lie within half a cell (+ half a texel) of the
          // sample in the light plane.
          const float fr = (0.5f * side) / texel + 0.5f;
          const int rr = int(std::ceil(fr));
          for (int y = std::max(0, iy - rr); y <= std::min(n - 1, iy + rr); ++y)
            for (int x = std::max(0, ix - rr); x <= std::min(n - 1, ix + rr); ++x) {
              const float dx = float(x) + 0.5f - tu, dy = float(y) + 0.5f - tv;
              if (dx * dx + dy * dy > fr * fr) continue;
              float& t = depth[std::size_t(y) * std::size_t(n) + std::size_t(x)];
              t = std::min(t, z + r);
            }
          vec3f nrm = q.decode(g.normal_code(c.cell));
          if (nrm.dot(p - v.eye) > 0) nrm = -nrm;  // two-sided, as the rasteriser
          const float lit = shadowed ? ambient : detail::lambert(nrm, L, ambient);
          ++(shadowed ? n_shadowed : n_lit);
          const rgb8 albedo = g.has_materials() ? rho_grid_material_colour(g.material(c.cell))
                                                : o.raster.flat_colour;
          point_prim<A> pp{p, splat ? o.splat_px : 1.0f};
          pp.colour = detail::scale_colour(albedo, lit);
          sink.point(pp);
        },
        &order);
  });
  st.lit = n_lit;
  st.shadowed = n_shadowed;
  if (stats) *stats = st;
  return img;
}

}  // namespace pbr_lod
