// pbr_lod — the frame of the one-pass light map (Duguet & Drettakis 2004, §4.2): shared by the
// map (raster/one_pass_shadows.hpp) and the traversals that carry light-space positions down a
// tree (the ρ-grid's light displacement table, builders/rho_grid_policy.hpp), so that both
// compute the same coordinates.
#pragma once

#include <algorithm>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// The frame of a one-pass light map: an orthographic projection along the light onto n × n
/// texels across a bounding sphere's diameter. coords(p) = (u, v, z): p's texel coordinates
/// (texel (i, j) spans [i, i + 1) × [j, j + 1)) and its distance from the light up to a
/// constant. The map is affine, so a traversal can carry a node's coordinates down its tree by
/// adding offset(child centre − parent centre): the ρ-grid's light displacement table (§4.2,
/// rho_grid_light_policy).
struct light_map_frame {
  vec3f to_light, u, v, centre;
  float half = 0, texel = 0;
  int texels = 0;

  /// `to_light` unit; `bounds` contains everything drawn; texels per side (at least 2).
  light_map_frame(const vec3f& l, const sphere& bounds, int n)
      : to_light(l),
        u(any_orthogonal(l)),
        v(l.cross(u)),
        centre(bounds.centre),
        half(bounds.radius),
        texel(2 * bounds.radius / float(std::max(2, n))),
        texels(std::max(2, n)) {}

  [[nodiscard]] vec3f coords(const vec3f& p) const {
    const vec3f d = p - centre;
    return {(d.dot(u) + half) / texel, (d.dot(v) + half) / texel, -d.dot(to_light)};
  }
  /// The change of coords() when a point moves by `o` (double: table entries are exact to
  /// float rounding once).
  [[nodiscard]] vec3f offset(const vec3d& o) const {
    return vec3f(float(o.dot(u.cast<double>()) / double(texel)),
                 float(o.dot(v.cast<double>()) / double(texel)),
                 float(-o.dot(to_light.cast<double>())));
  }
  [[nodiscard]] bool operator==(const light_map_frame&) const = default;
};

}  // namespace pbr_lod
