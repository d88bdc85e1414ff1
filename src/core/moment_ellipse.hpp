// pbr_lod — the second-moment ellipse of offsets in a tangent plane, scaled to hold them all
// (Pajarola 2003, Fig. 6a). Shared by the k-NN splat ellipses (estimation.cpp) and a mesh
// vertex's dual-cell splat (mesh_splats.cpp). Internal to src/core.
#pragma once

#include <algorithm>
#include <cmath>
#include <span>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod::detail {

/// Σx², Σxy, Σy² of 2-D offsets and the eigen-decomposition's pieces: the major moment
/// l1 = ½(a + c) + r, the minor ½(a + c) − r, with h = ½(a − c) and r = √(h² + b²).
struct moments_2d {
  double a = 0, b = 0, c = 0;
  void add(const vec2d& q) {
    a += q.x() * q.x();
    b += q.x() * q.y();
    c += q.y() * q.y();
  }
  [[nodiscard]] double h() const { return 0.5 * (a - c); }
  [[nodiscard]] double r() const { return std::hypot(h(), b); }
  [[nodiscard]] double major() const { return 0.5 * (a + c) + r(); }
  [[nodiscard]] double minor() const { return 0.5 * (a + c) - r(); }
};

/// The ellipse x²/l1 + y²/l2 ≤ f² in the frame (e1, e2) of the moments' axes.
struct moment_ellipse {
  vec2d e1, e2;   ///< major and minor directions in the tangent frame
  double l1, l2;  ///< the moments along them; l2 at least min_ratio2 · l1
  double f;       ///< the smallest scale at which the ellipse holds every offset
};

/// The moments' ellipse holding every offset of xy. m.major() must be > 0 (the callers handle
/// offsets that all vanish). The major axis is at ψ = ½·atan2(2b, a − c); isotropic moments
/// (r = 0) take ψ = 0, since any direction is an eigenvector.
inline moment_ellipse covering_ellipse(const moments_2d& m, std::span<const vec2d> xy,
                                       double min_ratio2) {
  const double r = m.r(), l1 = m.major();
  const double l2 = std::max(0.5 * (m.a + m.c) - r, min_ratio2 * l1);
  const double psi = r > 0 ? 0.5 * std::atan2(m.b, m.h()) : 0.0;
  const vec2d e1(std::cos(psi), std::sin(psi)), e2(-e1.y(), e1.x());
  double f2 = 0;
  for (const auto& q : xy) {
    const double x = q.dot(e1), y = q.dot(e2);
    f2 = std::max(f2, x * x / l1 + y * y / l2);
  }
  return {e1, e2, l1, l2, std::sqrt(f2)};
}

}  // namespace pbr_lod::detail
