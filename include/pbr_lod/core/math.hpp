// pbr_lod — vector types shared by every part.
//
// Positions are stored in float relative to a double-precision origin (see point_set.hpp);
// anything that accumulates (sums, covariances, distances over large ranges) uses double.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cmath>
#include <cstdint>
#include <numbers>

namespace pbr_lod {

using vec2f = Eigen::Vector2f;
using vec3f = Eigen::Vector3f;
using vec4f = Eigen::Vector4f;
using vec2d = Eigen::Vector2d;
using vec3d = Eigen::Vector3d;
using vec4d = Eigen::Vector4d;
using mat3f = Eigen::Matrix3f;
using mat3d = Eigen::Matrix3d;
using mat4d = Eigen::Matrix4d;

/// 8-bit RGB colour. Three bytes, no padding: what a scan file stores and what we store.
struct rgb8 {
  std::uint8_t r = 0, g = 0, b = 0;
  friend constexpr bool operator==(const rgb8&, const rgb8&) = default;
};
static_assert(sizeof(rgb8) == 3);

/// True when every component is finite (no NaN, no Inf).
template <class Derived>
[[nodiscard]] inline bool all_finite(const Eigen::MatrixBase<Derived>& v) {
  return v.array().isFinite().all();
}

/// A unit vector orthogonal to n (n need not be normalised but must be non-zero).
/// Picks the axis least aligned with n so the result is well conditioned for every n.
[[nodiscard]] inline vec3f any_orthogonal(const vec3f& n) {
  const vec3f a = n.cwiseAbs();
  const vec3f axis = (a.x() <= a.y() && a.x() <= a.z()) ? vec3f::UnitX()
                     : (a.y() <= a.z())                 ? vec3f::UnitY()
                                                        : vec3f::UnitZ();
  return n.cross(axis).normalized();
}

}  // namespace pbr_lod
