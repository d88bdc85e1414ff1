// pbr_lod — the first pass of the two-pass directional shadow map (Williams 1978).
//
// The primitives of a frame are buffered once (buffer_sink), their bounds fix an orthographic
// light view that just contains them, and they are rasterised depth-only from the light. The
// camera pass then marks a pixel as shadowed when its surface point lies farther from the light
// than the nearest caster in its shadow-map texel, plus a bias of a few texels' world size
// (resolve_shadows in src/raster/postprocess.cpp).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <span>
#include <vector>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/raster/detail/raster_core.hpp"
#include "pbr_lod/raster/effects.hpp"
#include "pbr_lod/traverse/sink.hpp"

namespace pbr_lod::detail {

struct shadow_map {
  ortho_projection proj;  ///< the light view: width = height = texels per side
  std::vector<float> key;  ///< per texel: −(depth along proj.forward) of the nearest caster; −inf
  float bias = 0;          ///< world units a receiver must lie behind a caster to be shadowed
  [[nodiscard]] bool empty() const { return key.empty(); }
};

/// Composes the final colours of a frame rendered with shadows: for every covered pixel
/// colour = albedo × (ambient when shadowed, else lit[i], or 1 when `lit` is empty). A null or
/// empty map shadows nothing.
void resolve_shadows(const view& v, const shadow_map* sm, float ambient, std::span<const float> key,
                     float key_far, std::span<rgb8> colour, std::span<const float> lit);

/// Builds the shadow map of the primitives in `prims` for `opt.sun`; empty when there is no light
/// direction, no (finite) primitive, or a shadow_map_size below 2.
template <attributes A>
[[nodiscard]] shadow_map build_shadow_map(const buffer_sink<A>& prims, const view& v,
                                          const render_options& opt) {
  shadow_map sm;
  const vec3f dir = opt.sun.direction;
  if (!all_finite(dir) || !(dir.squaredNorm() > 0) || opt.shadow_map_size < 2) return sm;
  const persp_projection cam(v);
  // World size of a point_prim: its square covers size_px camera pixels at its camera depth.
  const auto point_radius = [&](const point_prim<A>& p) {
    const float z = std::max(std::abs(cam.frame(p.position).z()), cam.w_near);
    return 0.5f * std::max(p.size_px, 1.0f) * z / cam.focal;
  };

  // Bounds of everything that can cast a shadow (non-finite primitives are skipped: they draw
  // nothing either).
  box3 b;
  // Screen rectangles cast as the squares about their 3-D positions a sink without them draws.
  const auto each_point = [&](const auto& f) {
    for (const auto& p : prims.points) f(p);
    for (const auto& r : prims.screen_rects) f(as_point_prim(r));
  };
  each_point([&](const point_prim<A>& p) {
    const float r = point_radius(p);
    if (!all_finite(p.position) || !std::isfinite(r)) return;
    b.extend(p.position - vec3f::Constant(r));
    b.extend(p.position + vec3f::Constant(r));
  });
  for (const auto& s : prims.splats) {
    const vec3f e = s.u.cwiseAbs() + s.v.cwiseAbs();
    if (!all_finite(s.centre) || !all_finite(e)) continue;
    b.extend(s.centre - e);
    b.extend(s.centre + e);
  }
  const auto triangle_bounds = [&b](const auto& t) {
    if (!all_finite(t.p[0]) || !all_finite(t.p[1]) || !all_finite(t.p[2])) return;
    for (const auto& p : t.p) b.extend(p);
  };
  for (const auto& t : prims.triangles) triangle_bounds(t);
  for (const auto& t : prims.textured_triangles) triangle_bounds(t.triangle);
  if (b.empty()) return sm;

  // Light frame: forward points away from the light; right = forward × up as in `view`.
  ortho_projection& lp = sm.proj;
  lp.forward = -dir.normalized();
  const vec3f up0 = any_orthogonal(lp.forward);
  lp.right = lp.forward.cross(up0).normalized();
  lp.up = lp.right.cross(lp.forward);
  lp.origin = b.centre();
  float ext = 0;
  for (int c = 0; c < 8; ++c) {
    const vec3f corner((c & 1) ? b.max.x() : b.min.x(), (c & 2) ? b.max.y() : b.min.y(),
                       (c & 4) ? b.max.z() : b.min.z());
    const vec3f e = lp.frame(corner);
    ext = std::max({ext, std::abs(e.x()), std::abs(e.y())});
  }
  ext = std::max(ext, 1e-6f * (1 + lp.origin.norm()));  // a single point still gets a map
  const int n = std::min(opt.shadow_map_size, 16384);
  lp.width = lp.height = n;
  lp.cx = lp.cy = 0.5f * static_cast<float>(n);
  lp.scale = (0.5f * static_cast<float>(n) - 1) / ext;  // one texel of margin on every side
  lp.update();
  sm.bias = std::max(opt.shadow_bias_texels, 0.0f) / lp.scale;
  sm.key.assign(static_cast<std::size_t>(n) * static_cast<std::size_t>(n),
                -std::numeric_limits<float>::infinity());

  float* kb = sm.key.data();
  const auto depth_only = [kb](std::size_t i, float key) {
    if (key > kb[i]) kb[i] = key;
  };
  each_point([&](const point_prim<A>& p) {
    const vec3f e = lp.frame(p.position);
    const float sx = lp.cx + lp.scale * e.x(), sy = lp.cy - lp.scale * e.y();
    raster_square(n, n, sx, sy, 2 * point_radius(p) * lp.scale, -e.z(), depth_only);
  });
  const span_target<false, false> depth_target{kb};
  for (const auto& s : prims.splats) raster_ellipse(lp, s.centre, s.u, s.v, depth_target);
  const auto test = [kb](std::size_t i, float key) { return key > kb[i]; };
  const auto write = [kb](std::size_t i, float key, const std::array<float, 0>&, bool) {
    kb[i] = key;
  };
  const auto depth_triangle = [&](const auto& t) {
    std::array<tri_vertex<0>, 3> tv;
    for (std::size_t k = 0; k < 3; ++k) tv[k].h = lp.point(t.p[k]);
    raster_triangle<false>(lp, tv, test, write);
  };
  for (const auto& t : prims.triangles) depth_triangle(t);
  for (const auto& t : prims.textured_triangles) depth_triangle(t.triangle);
  return sm;
}

}  // namespace pbr_lod::detail
