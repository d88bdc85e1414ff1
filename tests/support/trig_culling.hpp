// Pajarola's §6 culling tests with the angles taken literally (acos, asin, atan per test): what
// the library evaluated before its trigonometry-free forms (traverse/culling.hpp,
// core/bounds.hpp), kept as the reference the benchmarks measure those against.
#pragma once

#include <algorithm>
#include <cmath>
#include <numbers>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"

namespace pbr_lod::test {

/// γ − α > ω: γ the angle between w and c − e, α = asin(r/d), ω the corner cone's semi-angle.
[[nodiscard]] inline bool outside_view_cone_trig(const view& v, const sphere& s) {
  const vec3f d = s.centre - v.eye;
  const float dist = d.norm();
  if (dist <= s.radius) return false;
  const float hx = 0.5f * static_cast<float>(v.width) / v.focal_px;
  const float omega = std::atan(std::sqrt(hx * hx + v.tan_half_fovy * v.tan_half_fovy));
  const float gamma = std::acos(std::clamp(d.dot(v.forward) / dist, -1.0f, 1.0f));
  const float alpha = std::asin(std::min(1.0f, s.radius / dist));
  return gamma - alpha > omega;
}

/// angle(axis, c − e) + θ + asin(r/d) < π/2.
[[nodiscard]] inline bool back_facing_trig(const sphere& bounds, const normal_cone& cone,
                                           const vec3f& eye) {
  if (cone.semi_angle >= std::numbers::pi_v<float> / 2) return false;
  const vec3f d = bounds.centre - eye;
  const float dist = d.norm();
  if (dist <= bounds.radius) return false;
  const float beta = std::asin(std::min(1.0f, bounds.radius / dist));
  const float cos_a = std::clamp(cone.axis.dot(d) / dist, -1.0f, 1.0f);
  return std::acos(cos_a) + cone.semi_angle + beta < std::numbers::pi_v<float> / 2;
}

}  // namespace pbr_lod::test
