// pbr_lod — screen-size metrics: how large a node's bounding sphere appears, in pixels. The
// traversal's refine rule compares them with the tolerance (traverse/traverse.hpp).
#pragma once

#include <cmath>
#include <limits>

#include "pbr_lod/core/bounds.hpp"
#include "pbr_lod/core/camera.hpp"

namespace pbr_lod {

// ---------------------------------------------------------------------------------------------
// Projected size of a bounding sphere, in pixels.
//
// The silhouette of a sphere (centre c, radius r) seen from the eye is a cone of half-angle
// α = asin(r/d), d = |c − eye|, about the direction to c. Its intersection with the image plane
// (at distance f = focal_px) is an ellipse. With θ the angle between that direction and the
// optical axis, the ellipse's semi-axes are
//     a = f·sinα·cosα / (cos²θ − sin²α)    (radial: the largest extent)
//     b = f·sinα / sqrt(cos²θ − sin²α)
// valid while the whole sphere lies in front of the eye plane (cos²θ > sin²α, i.e. z_c > r).
// `projected_radius_exact` returns a (+∞ when the sphere reaches the eye plane): the exact
// largest screen-space radius, what decides whether a node's splat can cover it.
//
// The papers use cheaper estimates; each can be compared with the exact one:
//  * eye_z:    f·r / z_c           — eye-space depth only (QSplat, POP, Pajarola's d²/|(c−e)·w|²);
//              under-estimates off-axis, where a > f·r/z_c.
//  * distance: f·r / d             — Euclidean distance; under-estimates off-axis even more.
//  * pmr:      r / pixel size at the box corner nearest the eye (Dey & Hudson §4): the world
//              size of a pixel measured by projecting a unit offset at that corner.
// ---------------------------------------------------------------------------------------------

enum class projection_metric { exact, eye_z, distance, pmr_corner };

[[nodiscard]] inline float projected_radius_exact(const view& v, const sphere& s) {
  // With sinα = r/d, cosα = sqrt(d²−r²)/d, cos²θ − sin²α = (z² − r²)/d² the major semi-axis
  // simplifies to a = f·r·sqrt(d² − r²) / (z² − r²): one square root, one division.
  const vec3f e = v.to_eye(s.centre);
  const float r2 = s.radius * s.radius;
  const float z2r2 = e.z() * e.z() - r2;
  if (e.z() <= s.radius || !(z2r2 > 0)) return std::numeric_limits<float>::infinity();
  return v.focal_px * s.radius * std::sqrt(e.squaredNorm() - r2) / z2r2;
}

/// Semi-minor axis of the same ellipse, b = f·r / sqrt(z² − r²) (tests, area estimates).
[[nodiscard]] inline float projected_minor_radius_exact(const view& v, const sphere& s) {
  const vec3f e = v.to_eye(s.centre);
  const float z2r2 = e.z() * e.z() - s.radius * s.radius;
  if (e.z() <= s.radius || !(z2r2 > 0)) return std::numeric_limits<float>::infinity();
  return v.focal_px * s.radius / std::sqrt(z2r2);
}

[[nodiscard]] inline float projected_radius_eye_z(const view& v, const sphere& s) {
  const float z = v.to_eye(s.centre).z();
  if (z <= 0) return std::numeric_limits<float>::infinity();
  return v.focal_px * s.radius / z;
}

[[nodiscard]] inline float projected_radius_distance(const view& v, const sphere& s) {
  const float d = (s.centre - v.eye).norm();
  if (d <= s.radius) return std::numeric_limits<float>::infinity();
  return v.focal_px * s.radius / d;
}

/// World size of a pixel at point p, measured as Dey & Hudson do: project p and a point at the
/// same distance from the eye one world unit away (along the camera's right axis, re-normalised
/// to that distance) and take the reciprocal of their screen distance.
[[nodiscard]] inline float pixel_size_pmr(const view& v, const vec3f& p) {
  const vec3f ep = v.to_eye(p);
  if (ep.z() <= 0) return 0;
  const float dist = ep.norm();
  // A unit step orthogonal to the ray, then back onto the sphere of radius dist about the eye.
  vec3f step = vec3f::UnitX() - ep.normalized() * ep.normalized().x();
  if (step.squaredNorm() < 1e-12f) step = vec3f::UnitY();
  vec3f q = ep + step.normalized();
  q *= dist / q.norm();
  if (q.z() <= 0) return 0;
  const float px = (v.eye_to_screen(ep) - v.eye_to_screen(q)).norm();
  return px > 0 ? 1.0f / px : 0.0f;
}

/// Dey & Hudson's estimate applied to a sphere: the pixel size at the corner of the sphere's
/// bounding cube nearest the eye.
[[nodiscard]] inline float projected_radius_pmr(const view& v, const sphere& s) {
  vec3f corner;
  for (int i = 0; i < 3; ++i)
    corner[i] = s.centre[i] + (v.eye[i] < s.centre[i] ? -s.radius : s.radius);
  const float size = pixel_size_pmr(v, corner);
  if (!(size > 0)) return std::numeric_limits<float>::infinity();
  return s.radius / size;
}

[[nodiscard]] inline float projected_radius(projection_metric m, const view& v, const sphere& s) {
  switch (m) {
    case projection_metric::eye_z:
      return projected_radius_eye_z(v, s);
    case projection_metric::distance:
      return projected_radius_distance(v, s);
    case projection_metric::pmr_corner:
      return projected_radius_pmr(v, s);
    case projection_metric::exact:
      break;
  }
  return projected_radius_exact(v, s);
}

}  // namespace pbr_lod
