// pbr_lod — one-pass shadows for a directional light (Duguet & Drettakis 2004, §4.2), as a Sink
// adapter any hierarchy can draw through.
//
// When a traversal emits front to back from the light, every occluder of a sample is emitted
// before it. So one orthographic light map, looked up and then written as each sample arrives,
// says at once whether the sample is lit: no second pass over the frame. one_pass_shadow_sink
// does that between a traversal and the rasteriser: it shades each primitive it receives (albedo
// × two-sided Lambert when lit, × ambient in shadow, what the rasteriser's two-pass shadows
// compose) and forwards it with that colour. render_one_pass_shadows() wires it up for any
// Hierarchy and a policy that visits front to back from the light (for the ρ-grid:
// rho_grid_policy with rho_grid_light_order, builders/rho_grid_policy.hpp).
//
// The map stores each occluder's far extent (the depth of its node's centre + the node's
// bounding radius r) over its footprint (a disk of r/√3 — half the side of a cube whose
// circumsphere has radius r — plus half a texel), and a sample is shadowed only when that is
// nearer than its own near extent (centre − r − the bias). Comparing extents, not centres, keeps
// a coarse node from shadowing the finer nodes of the surface it lies on (docs/rho-grid.md).
//
// Slope-scaled bias (the acne rule): a receiver whose normal makes an angle α with the light
// also allows k·(r/√3 + one texel)·tan α (k = one_pass_slope_bias = 2, tan α capped at
// one_pass_slope_cap = 5): on a surface tilted against the light, the neighbours whose
// footprints reach the receiver's texel lie up to that much nearer the light along the same
// surface. Against a ray-cast reference (RhoGridShadows.SlopeScaledBiasRemovesMostAcne, bunny,
// every light-facing leaf weighted by n·L, i.e. by how much lit and shadowed differ): acne
// 8.5 % → 1.9 %, missed shadows 1.2 % → 2.1 %; a larger cap trades the one for the other.
#pragma once

#include <algorithm>
#include <cmath>
#include <concepts>
#include <cstddef>
#include <limits>
#include <vector>

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/light_map_frame.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/traverse/hierarchy.hpp"
#include "pbr_lod/traverse/traverse.hpp"

namespace pbr_lod {

struct one_pass_shadow_stats {
  std::size_t lit = 0, shadowed = 0;  ///< primitives classified
};

/// The slope-scaled bias factor k of the one-pass light map, and the largest tan α it is
/// applied with (see the top of this file).
inline constexpr float one_pass_slope_bias = 2.0f;
inline constexpr float one_pass_slope_cap = 5.0f;

/// The orthographic light map over a bounding sphere, n × n texels across its diameter.
class one_pass_light_map {
 public:
  /// `to_light` unit; `bounds` contains everything drawn; bias in texels; slope: the factor k
  /// of the slope-scaled bias (0: none).
  one_pass_light_map(const vec3f& to_light, const sphere& bounds, int texels, float bias_texels,
                     float slope = one_pass_slope_bias)
      : f_(to_light, bounds, texels),
        n_(f_.texels),
        bias_(bias_texels * f_.texel),
        slope_(std::isfinite(slope) ? std::max(slope, 0.0f) : 0.0f),
        depth_(std::size_t(n_) * std::size_t(n_), std::numeric_limits<float>::infinity()) {}

  [[nodiscard]] const light_map_frame& frame() const { return f_; }

  /// True when a sample at p whose node has bounding radius r and unit normal n (either sign;
  /// zero: unknown, no slope bias) is shadowed by what was written before; then writes the
  /// sample's own footprint.
  bool shadowed_then_write(const vec3f& p, float r, const vec3f& n = vec3f::Zero()) {
    return shadowed_then_write_at(f_.coords(p), r, n);
  }
  /// shadowed_then_write() for a sample whose frame().coords() are `c` (u, v, z), computed by
  /// the caller.
  bool shadowed_then_write_at(const vec3f& c, float r, const vec3f& n = vec3f::Zero()) {
    const float tu = c.x(), tv = c.y(), z = c.z();
    // Non-finite coordinates (a NaN position) land in texel 0, as int() of a clamped NaN would.
    const int ix = std::isfinite(tu) ? int(std::clamp(tu, 0.0f, float(n_ - 1))) : 0;
    const int iy = std::isfinite(tv) ? int(std::clamp(tv, 0.0f, float(n_ - 1))) : 0;
    const float footprint = r / std::sqrt(3.0f);
    const bool shadowed = at(ix, iy) < z - r - bias_ - slope_bias(n, footprint);
    const float fr = footprint / f_.texel + 0.5f;
    const int rr = int(std::ceil(fr));
    for (int y = std::max(0, iy - rr); y <= std::min(n_ - 1, iy + rr); ++y)
      for (int x = std::max(0, ix - rr); x <= std::min(n_ - 1, ix + rr); ++x) {
        const float dx = float(x) + 0.5f - tu, dy = float(y) + 0.5f - tv;
        if (dx * dx + dy * dy > fr * fr) continue;
        float& t = at(x, y);
        t = std::min(t, z + r);
      }
    return shadowed;
  }

 private:
  float& at(int x, int y) { return depth_[std::size_t(y) * std::size_t(n_) + std::size_t(x)]; }
  /// k·(footprint + texel)·tan α, α the angle between n and the light (tan α capped at
  /// one_pass_slope_cap).
  [[nodiscard]] float slope_bias(const vec3f& n, float footprint) const {
    if (!(slope_ > 0)) return 0;
    const float c = std::abs(n.dot(f_.to_light));
    if (!(c > 0)) return 0;
    const float s2 = std::max(0.0f, n.squaredNorm() - c * c);
    return slope_ * (footprint + f_.texel) * std::min(std::sqrt(s2) / c, one_pass_slope_cap);
  }
  light_map_frame f_;
  int n_;
  float bias_, slope_;
  std::vector<float> depth_;
};

/// Sink<A> (A with normals) that shades what it receives lit or in shadow and forwards it as
/// primitives of colours only to `Inner`. The bounding radius of the next primitives is set with
/// node_radius() (render_one_pass_shadows does it per emitted node), and the light-map
/// coordinates of the next one, when the traversal carries them, with node_light().
template <attributes A, class Inner>
class one_pass_shadow_sink {
  static_assert(A.normal, "one-pass shadows shade: the primitives need normals");
  static constexpr attributes out_attrs{.colour = true};

 public:
  one_pass_shadow_sink(const view& v, const render_options& o, const vec3f& to_light,
                       const sphere& bounds, Inner& inner)
      : map_(to_light, bounds, o.shadow_map_size, o.shadow_bias_texels),
        l_(to_light),
        eye_(v.eye),
        flat_(o.flat_colour),
        ambient_(std::isfinite(o.sun.ambient) ? std::clamp(o.sun.ambient, 0.0f, 1.0f) : 0.0f),
        inner_(inner) {}

  void node_radius(float r) { r_ = r; }
  /// The next primitive's position in light_map_frame::coords (its point's or splat's centre,
  /// a triangle's centroid), computed by the traversal — the ρ-grid's light displacement table
  /// (§4.2) — and used instead of projecting that position; for that one primitive only.
  void node_light(const vec3f& coords) {
    light_ = coords;
    has_light_ = true;
  }
  [[nodiscard]] const one_pass_shadow_stats& stats() const { return st_; }

  void point(const point_prim<A>& p) {
    point_prim<out_attrs> q{p.position, p.size_px};
    q.colour = shade(p.position, p.normal, albedo(p), classify(p.position, p.normal));
    inner_.point(q);
  }
  void splat(const splat_prim<A>& s) {
    splat_prim<out_attrs> q{s.centre, s.u, s.v};
    q.colour = shade(s.centre, s.normal, albedo(s), classify(s.centre, s.normal));
    inner_.splat(q);
  }
  void triangle(const triangle_prim<A>& t) {
    const vec3f c = (t.p[0] + t.p[1] + t.p[2]) / 3;
    const vec3f fn = (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]);
    const float len = fn.norm();
    const bool dark = classify(c, len > 0 && std::isfinite(len) ? vec3f(fn / len) : vec3f::Zero());
    triangle_prim<out_attrs> q{t.p};
    for (std::size_t k = 0; k < 3; ++k) {
      rgb8 a = flat_;
      if constexpr (A.colour) a = t.colour[k];
      q.colour[k] = shade(t.p[k], t.normal[k], a, dark);
    }
    inner_.triangle(q);
  }

 private:
  bool classify(const vec3f& p, const vec3f& n) {
    const bool dark = has_light_ ? map_.shadowed_then_write_at(light_, r_, n)
                                 : map_.shadowed_then_write(p, r_, n);
    has_light_ = false;
    ++(dark ? st_.shadowed : st_.lit);
    return dark;
  }
  template <class P>
  [[nodiscard]] rgb8 albedo(const P& p) const {
    if constexpr (A.colour) return p.colour;
    return flat_;
  }
  [[nodiscard]] rgb8 shade(const vec3f& p, vec3f n, rgb8 albedo, bool dark) const {
    if (n.dot(p - eye_) > 0) n = -n;  // two-sided, as the rasteriser
    return detail::scale_colour(albedo, dark ? ambient_ : detail::lambert(n, l_, ambient_));
  }

  one_pass_light_map map_;
  vec3f l_, eye_;
  rgb8 flat_;
  float ambient_;
  float r_ = 0;
  vec3f light_ = vec3f::Zero();
  bool has_light_ = false;
  Inner& inner_;
  one_pass_shadow_stats st_;
};

/// A traversal state that carries its node's light-map coordinates (light_map_frame::coords of
/// the node's emitted position): render_one_pass_shadows hands them to the shadow sink.
template <class State>
concept carries_light_coords = requires(const State& s) {
  { s.light_coords } -> std::convertible_to<vec3f>;
};

namespace detail {
/// Forwards to Policy and tells the shadow sink each emitted node's bounding radius first (and
/// its light-map coordinates when the policy's state carries them). The state-taking emit()
/// forwards to Policy's own when it has one, so that a policy drawing from its state (the
/// ρ-grid's screen_draw) keeps doing so under shadows.
template <class Policy, class ShadowSink>
struct node_radius_policy : Policy {
  ShadowSink* shadows;
  template <class H, class State, class S>
  void emit(const H& h, const typename H::node_id& n, const State& hs, const view& v, float size,
            const traverse_options& o, S& sink) const {
    shadows->node_radius(h.bounding_sphere(n).radius);
    if constexpr (carries_light_coords<State>) shadows->node_light(hs.light_coords);
    if constexpr (has_state_emit<Policy, H, State, S>)
      Policy::emit(h, n, hs, v, size, o, sink);
    else
      Policy::emit(h, n, v, size, o, sink);
  }
};
}  // namespace detail

/// The light map's frame render_one_pass_shadows(h, …, o, …) uses: over h's root bounding sphere,
/// o.shadow_map_size texels, light towards o.sun.direction (normalised; throws InvalidArgument
/// when it is zero or not finite). A policy with a light table (rho_grid_light_policy) is built
/// for it.
template <Hierarchy H>
[[nodiscard]] light_map_frame one_pass_light_frame(const H& h, const render_options& o) {
  const vec3f dir = o.sun.direction;
  if (!all_finite(dir) || !(dir.squaredNorm() > 0))
    throw InvalidArgument("one-pass shadows need a non-zero light direction");
  return light_map_frame(dir.normalized(), h.empty() ? sphere{} : h.bounding_sphere(h.root()),
                         o.shadow_map_size);
}

/// Renders h for view v (relative to h.origin()) with one-pass shadows from o.sun in one
/// traversal. `policy` must emit front to back from the light; the light map covers
/// h.bounding_sphere(h.root()) with o.shadow_map_size² texels. Shading is that of the
/// rasteriser's; the frame is drawn with colour only (and hole filling when o.fx asks for it).
/// Needs normals (static) and a non-zero light direction (throws InvalidArgument). With
/// o.supersample = k, h is traversed in v.supersampled(k) with k × t.tolerance_px (the cut of v);
/// a policy built for one view, as the ρ-grid's, must then be built for that view. A policy with
/// a light table (it has light_frame(): rho_grid_light_policy) must have been built for
/// one_pass_light_frame(h, o), else InvalidArgument.
template <Hierarchy H, class Policy>
[[nodiscard]] image render_one_pass_shadows(const H& h, const view& v, const render_options& o,
                                            const traverse_options& t, const Policy& policy,
                                            traverse_stats* tstats = nullptr,
                                            one_pass_shadow_stats* sstats = nullptr) {
  static_assert(H::attrs.normal, "one-pass shadows need normals");
  const light_map_frame frame = one_pass_light_frame(h, o);
  if constexpr (requires { policy.light_frame(); }) {
    if (!h.empty() && !(policy.light_frame() == frame))
      throw InvalidArgument(
          "one-pass shadows: the policy's light table was built for another light map (build it "
          "for one_pass_light_frame(h, o): the same light direction and shadow_map_size)");
  }
  constexpr attributes C{.colour = true};
  render_options ro = o;
  ro.fx = effects{.colour = true, .hole_filling = o.fx.hole_filling};
  traverse_stats ts;
  one_pass_shadow_stats ss;
  const traverse_options tk = supersampled_cut(v, t, o.supersample).options;  // v's cut
  image img = render<C>(v, ro, [&](auto& sink, const view& dv) {
    if (h.empty()) return;
    using sink_type = std::decay_t<decltype(sink)>;
    one_pass_shadow_sink<H::attrs, sink_type> shade(dv, o, frame.to_light,
                                                    h.bounding_sphere(h.root()), sink);
    const detail::node_radius_policy<Policy, decltype(shade)> p{policy, &shade};
    ts = traverse(h, dv, tk, shade, p);
    ss = shade.stats();
  });
  if (tstats) *tstats = ts;
  if (sstats) *sstats = ss;
  return img;
}

}  // namespace pbr_lod
