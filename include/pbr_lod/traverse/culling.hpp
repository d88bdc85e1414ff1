// pbr_lod — view-frustum culling of bounding spheres, as the traversal applies it
// (traverse/traverse.hpp): the six planes of the view, or Pajarola's cheaper view cone.
#pragma once

#include <algorithm>
#include <cmath>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"

namespace pbr_lod {

/// Pajarola's view-cone test (§6, Fig. 10a; Pajarola 1998): the frustum is approximated by the
/// cone about the viewing direction w through its corners (semi-angle ω), and a sphere is
/// outside when γ − α > ω, γ the angle between w and c − e, α = asin(r/d) its angular radius.
/// Cheaper than six planes, looser in the corners; never culls a sphere the planes keep, except
/// beyond z_far (the cone has no far plane; spheres behind the near plane are kept).
[[nodiscard]] inline bool outside_view_cone(const view& v, const sphere& s) {
  const vec3f d = s.centre - v.eye;
  const float dist = d.norm();
  if (dist <= s.radius) return false;
  const float hx = 0.5f * static_cast<float>(v.width) / v.focal_px;
  const float omega = std::atan(std::sqrt(hx * hx + v.tan_half_fovy * v.tan_half_fovy));
  const float gamma = std::acos(std::clamp(d.dot(v.forward) / dist, -1.0f, 1.0f));
  const float alpha = std::asin(std::min(1.0f, s.radius / dist));
  return gamma - alpha > omega;
}

/// Frustum test of a sphere against the planes selected by `mask` (bit i = plane i still to be
/// tested). Returns -1 when the sphere is outside one plane, otherwise the mask of planes it
/// still straddles (0 = fully inside: children need no more tests).
[[nodiscard]] inline int frustum_test(const view& v, const sphere& s, int mask = 0x3f) {
  int out = 0;
  for (int i = 0; i < 6; ++i) {
    if (!(mask & (1 << i))) continue;
    const float dist = v.frustum[static_cast<std::size_t>(i)].distance(s.centre);
    if (dist < -s.radius) return -1;
    if (dist < s.radius) out |= 1 << i;
  }
  return out;
}

}  // namespace pbr_lod
