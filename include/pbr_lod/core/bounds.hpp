// pbr_lod — bounding volumes shared by the builders: sphere, normal cone, elliptical disk, box.
#pragma once

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <span>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// Axis-aligned box. An empty box has min > max.
struct box3 {
  vec3f min = vec3f::Constant(std::numeric_limits<float>::infinity());
  vec3f max = vec3f::Constant(-std::numeric_limits<float>::infinity());

  [[nodiscard]] bool empty() const { return (min.array() > max.array()).any(); }
  void extend(const vec3f& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  [[nodiscard]] vec3f centre() const { return 0.5f * (min + max); }
  [[nodiscard]] vec3f extent() const { return max - min; }
  [[nodiscard]] static box3 of(std::span<const vec3f> pts) {
    box3 b;
    for (const auto& p : pts) b.extend(p);
    return b;
  }
};

/// Bounding sphere. radius ≥ 0; a single point is a sphere of radius 0.
struct sphere {
  vec3f centre = vec3f::Zero();
  float radius = 0;

  /// True when p lies inside, with a relative tolerance for float rounding.
  [[nodiscard]] bool contains(const vec3f& p, float rel_eps = 1e-5f) const {
    const float slack = rel_eps * std::max(radius, centre.cwiseAbs().maxCoeff()) + 1e-30f;
    return (p - centre).norm() <= radius + slack;
  }
  [[nodiscard]] bool contains(const sphere& s, float rel_eps = 1e-5f) const {
    const float slack = rel_eps * std::max(radius, centre.cwiseAbs().maxCoeff()) + 1e-30f;
    return (s.centre - centre).norm() + s.radius <= radius + slack;
  }
};

/// Sphere about the centre of the points' box, radius to the farthest point (computed in double).
/// Not minimal; CGAL's Min_sphere_of_spheres_d is the minimal one (used where a builder needs it).
[[nodiscard]] inline sphere bounding_sphere_about_box_centre(std::span<const vec3f> pts) {
  if (pts.empty()) return {};
  const vec3f c = box3::of(pts).centre();
  double r2 = 0;
  for (const auto& p : pts) r2 = std::max(r2, (p - c).cast<double>().squaredNorm());
  return {c, static_cast<float>(std::sqrt(r2))};
}

/// Cone of normals: every normal n of the node satisfies angle(n, axis) ≤ semi_angle.
/// semi_angle ≥ π means "any direction" (the node can never be back-face culled).
struct normal_cone {
  vec3f axis = vec3f::UnitZ();
  float semi_angle = std::numbers::pi_v<float>;

  [[nodiscard]] bool full() const { return semi_angle >= std::numbers::pi_v<float> / 2; }
  [[nodiscard]] bool contains(const vec3f& n, float eps_rad = 1e-4f) const {
    if (semi_angle >= std::numbers::pi_v<float>) return true;
    const float c = std::clamp(axis.dot(n.normalized()), -1.0f, 1.0f);
    return std::acos(c) <= semi_angle + eps_rad;
  }
};

/// A normal cone with its semi-angle θ given by cos θ and sin θ, which a hierarchy derives once
/// per node (after build and load) so that back-face culling needs no trigonometry per frame.
struct normal_cone_cs {
  vec3f axis = vec3f::UnitZ();
  float cos_semi = -1;  ///< cos θ; θ ≥ π/2 (cos θ ≤ 0) never culls
  float sin_semi = 0;
};

/// True when every surface point inside `bounds` with a normal inside `cone` faces away from an
/// eye at `eye`, i.e. (p − eye)·n > 0 for all of them. Conservative: false whenever unsure.
/// The view directions towards a sphere of radius r at distance d fill a cone of half-angle
/// β = asin(r/d) about the centre direction; all normals face away iff
/// a + θ + β < π/2, a = angle(axis, centre − eye) (Pajarola 2003 §6, Fig. 10b: β + θ < 90°
/// with his β the angle to the sphere's nearest view direction).
///
/// Without trigonometry (his "only a few floating-point operations", [14, 15]): with
/// p = axis·(c − e), q = √(d² − r²) = d·cos β and r = d·sin β, the test is θ + β < π/2
/// (cos(θ + β) > 0: cos θ·q > sin θ·r) and cos a > sin(θ + β) (p > sin θ·q + cos θ·r); both
/// sides are squared where they are non-negative, so not even q's square root is taken.
[[nodiscard]] inline bool back_facing(const sphere& bounds, const normal_cone_cs& cone,
                                      const vec3f& eye) {
  if (!(cone.cos_semi > 0)) return false;  // θ ≥ π/2: some normal faces every direction
  const vec3f d = bounds.centre - eye;
  const float r = bounds.radius, q2 = d.squaredNorm() - r * r;
  if (!(q2 > 0)) return false;  // eye inside the bounds
  const float c2 = cone.cos_semi * cone.cos_semi, s2 = cone.sin_semi * cone.sin_semi;
  if (!(c2 * q2 > s2 * r * r)) return false;  // θ + β ≥ π/2
  const float m = cone.axis.dot(d) - cone.cos_semi * r;
  return m > 0 && m * m > s2 * q2;
}

/// The same test for a cone given by its semi-angle (two trigonometric calls per test; the
/// hierarchies that cull many nodes per frame provide normal_cone_cs instead).
[[nodiscard]] inline bool back_facing(const sphere& bounds, const normal_cone& cone,
                                      const vec3f& eye) {
  if (cone.semi_angle >= std::numbers::pi_v<float> / 2) return false;
  return back_facing(
      bounds, normal_cone_cs{cone.axis, std::cos(cone.semi_angle), std::sin(cone.semi_angle)}, eye);
}

/// Elliptical disk (a splat): centre, unit normal, and the two semi-axis vectors u, v
/// (orthogonal to each other and to the normal; their lengths are the semi-axes).
struct elliptical_disk {
  vec3f centre = vec3f::Zero();
  vec3f normal = vec3f::UnitZ();
  vec3f u = vec3f::UnitX();
  vec3f v = vec3f::UnitY();

  /// True when p (projected onto the disk's plane) lies inside the ellipse.
  [[nodiscard]] bool covers(const vec3f& p, float rel_eps = 1e-4f) const {
    const vec3f d = p - centre;
    const float a2 = u.squaredNorm(), b2 = v.squaredNorm();
    if (a2 == 0 || b2 == 0) return d.squaredNorm() == 0;
    const float x = d.dot(u) / a2, y = d.dot(v) / b2;  // coordinates in units of the semi-axes
    return x * x + y * y <= 1 + rel_eps;
  }
};

}  // namespace pbr_lod
