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
///
/// Without trigonometry, as the paper asks ([14, 15]): ω + α < π, so γ > ω + α is
/// cos γ < cos ω·cos α − sin ω·sin α; times d, with t = w·(c − e), q = √(d² − r²) = d·cos α and
/// r = d·sin α: t + sin ω·r < cos ω·q. A negative left side is outside at once; otherwise both
/// sides are squared, so the test is a dot product, a squared norm and four products
/// (cos ω, sin ω are the view's, computed once per frame).
[[nodiscard]] inline bool outside_view_cone(const view& v, const sphere& s) {
  const vec3f d = s.centre - v.eye;
  const float r = s.radius, q2 = d.squaredNorm() - r * r;
  if (!(q2 > 0)) return false;  // eye inside the sphere
  const float lhs = d.dot(v.forward) + v.sin_cone * r;
  return lhs < 0 || lhs * lhs < v.cos_cone * v.cos_cone * q2;
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

/// Back-face test of node n (bounded by `s`) of a hierarchy with normal cones: through the
/// cone's precomputed cos θ / sin θ when the hierarchy derives them (normal_cone_cs(n)),
/// otherwise from its semi-angle.
template <class H, class Node>
[[nodiscard]] bool node_back_facing(const H& h, const Node& n, const sphere& s, const vec3f& eye) {
  if constexpr (requires { h.normal_cone_cs(n); })
    return back_facing(s, h.normal_cone_cs(n), eye);
  else
    return back_facing(s, h.normal_cone(n), eye);
}

}  // namespace pbr_lod
