// pbr_lod — four lanes of doubles for the builders' small fixed-size geometry (internal).
//
// The POP builder does the same arithmetic four times in its two hottest places: the paper's
// 4-child rule works on the four faces of the children's centres' tetrahedron, and most leaves
// hold four triangles. As four lanes the compiler does two of them per SSE2 instruction instead
// of one Eigen vec3d at a time with a scalar z, and the cross products need no shuffles. Every
// lane does exactly the operations of the vec3d code it replaces, in the same order (Eigen sums
// a dot product as x + y, then + z), so the results are the same bit for bit; branches become
// per-lane selects.
//
// A lane vector is two GCC/Clang vectors of two doubles: a 32-byte vector type would be split by
// the compiler without AVX, and its comparisons and selects then become a scalar compare and a
// branch per lane.
#pragma once

#include <cstdint>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod::detail::lanes {

#define PBR_LOD_LANE [[gnu::always_inline]] inline

using d2 = double __attribute__((vector_size(16)));
using m2 = decltype(d2{} < d2{});  // per lane: all bits set (true) or none

/// Four doubles.
struct d4 {
  d2 lo, hi;
  [[nodiscard]] PBR_LOD_LANE double operator[](int k) const { return k < 2 ? lo[k] : hi[k - 2]; }
};
/// Four truth values, as comparisons of d4 give them.
struct m4 {
  m2 lo, hi;
  [[nodiscard]] PBR_LOD_LANE bool operator[](int k) const {
    return (k < 2 ? lo[k] : hi[k - 2]) != 0;
  }
};

PBR_LOD_LANE d4 splat(double s) {
  return {d2{s, s}, d2{s, s}};
}
PBR_LOD_LANE d4 make(double a, double b, double c, double d) {
  return {d2{a, b}, d2{c, d}};
}

#define PBR_LOD_LANE_OP(op)                               \
  PBR_LOD_LANE d4 operator op(const d4& a, const d4& b) { \
    return {a.lo op b.lo, a.hi op b.hi};                  \
  }
PBR_LOD_LANE_OP(+)
PBR_LOD_LANE_OP(-)
PBR_LOD_LANE_OP(*)
PBR_LOD_LANE_OP(/)
#undef PBR_LOD_LANE_OP
#define PBR_LOD_LANE_CMP(op)                              \
  PBR_LOD_LANE m4 operator op(const d4& a, const d4& b) { \
    return {a.lo op b.lo, a.hi op b.hi};                  \
  }                                                       \
  PBR_LOD_LANE m4 operator op(const d4& a, double b) {    \
    return a op splat(b);                                 \
  }
PBR_LOD_LANE_CMP(<)
PBR_LOD_LANE_CMP(>)
PBR_LOD_LANE_CMP(>=)
PBR_LOD_LANE_CMP(==)
PBR_LOD_LANE_CMP(!=)
#undef PBR_LOD_LANE_CMP
PBR_LOD_LANE d4 operator-(const d4& a) {
  return {-a.lo, -a.hi};
}
PBR_LOD_LANE d4 operator*(double s, const d4& a) {
  return splat(s) * a;
}
PBR_LOD_LANE m4 operator&(const m4& a, const m4& b) {
  return {a.lo & b.lo, a.hi & b.hi};
}
PBR_LOD_LANE m4 operator|(const m4& a, const m4& b) {
  return {a.lo | b.lo, a.hi | b.hi};
}
PBR_LOD_LANE m4 operator~(const m4& a) {
  return {~a.lo, ~a.hi};
}
/// Per lane: m ? a : b.
PBR_LOD_LANE d4 select(const m4& m, const d4& a, const d4& b) {
  return {m.lo ? a.lo : b.lo, m.hi ? a.hi : b.hi};
}
/// std::max(a, b) per lane: (a < b) ? b : a, the same value including which of equal values.
PBR_LOD_LANE d4 max(const d4& a, const d4& b) {
  return select(a < b, b, a);
}
/// Per lane: x is finite (x − x is 0 for finite x, NaN for ±∞ and NaN).
PBR_LOD_LANE m4 finite(const d4& x) {
  return x - x == 0.0;
}
/// std::sqrt per lane.
PBR_LOD_LANE d4 sqrt(const d4& x) {
  return make(std::sqrt(x[0]), std::sqrt(x[1]), std::sqrt(x[2]), std::sqrt(x[3]));
}

/// Three coordinates of four points (or vectors), one per lane.
struct v3 {
  d4 x, y, z;
};

PBR_LOD_LANE v3 operator+(const v3& a, const v3& b) {
  return {a.x + b.x, a.y + b.y, a.z + b.z};
}
PBR_LOD_LANE v3 operator-(const v3& a, const v3& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}
PBR_LOD_LANE v3 operator-(const v3& a) {
  return {-a.x, -a.y, -a.z};
}
PBR_LOD_LANE v3 operator*(const d4& s, const v3& a) {
  return {s * a.x, s * a.y, s * a.z};
}
PBR_LOD_LANE v3 operator*(const v3& a, const d4& s) {
  return {a.x * s, a.y * s, a.z * s};
}
/// Eigen's a.dot(b) for Vector3d: (x·x' + y·y') + z·z'.
PBR_LOD_LANE d4 dot(const v3& a, const v3& b) {
  return a.x * b.x + a.y * b.y + a.z * b.z;
}
/// Eigen's a.cross(b) for Vector3d.
PBR_LOD_LANE v3 cross(const v3& a, const v3& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
PBR_LOD_LANE v3 select(const m4& m, const v3& a, const v3& b) {
  return {select(m, a.x, b.x), select(m, a.y, b.y), select(m, a.z, b.z)};
}
PBR_LOD_LANE m4 finite(const v3& v) {
  return finite(v.x) & finite(v.y) & finite(v.z);
}
/// Four points as lanes, and one back.
PBR_LOD_LANE v3 load(const vec3d& a, const vec3d& b, const vec3d& c, const vec3d& d) {
  return {make(a.x(), b.x(), c.x(), d.x()), make(a.y(), b.y(), c.y(), d.y()),
          make(a.z(), b.z(), c.z(), d.z())};
}
PBR_LOD_LANE vec3d lane(const v3& v, int k) {
  return {v.x[k], v.y[k], v.z[k]};
}

#undef PBR_LOD_LANE

}  // namespace pbr_lod::detail::lanes
