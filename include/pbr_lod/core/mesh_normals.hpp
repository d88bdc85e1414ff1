// pbr_lod — vertex normals of a triangle mesh, for meshes that come without them. Builders (POP,
// the ρ-grid) and the reference renderer use the same ones, so a hierarchy and its reference
// shade alike.
#pragma once

#include <cmath>
#include <vector>

#include "pbr_lod/core/math.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// Area-weighted vertex normals of a mesh (each face adds its cross product, i.e. its normal
/// times twice its area, to its three vertices); unit length, or zero for a vertex without a
/// face of non-zero area.
[[nodiscard]] std::vector<vec3f> area_weighted_normals(const triangle_mesh& m);

/// The unnormalised sums behind area_weighted_normals(), in double, faces in input order (on
/// huge pages when large): area_weighted_normals(m)[i] == unit_or_zero(sums[i]). For builders
/// that normalise on the way, without the float copy.
[[nodiscard]] std::vector<vec3d> area_weighted_normal_sums(const triangle_mesh& m);

/// s normalised to float, or zero when s has no (finite) length.
[[nodiscard]] inline vec3f unit_or_zero(const vec3d& s) {
  const double len = s.norm();
  return len > 0 && std::isfinite(len) ? vec3f((s / len).cast<float>()) : vec3f::Zero();
}

}  // namespace pbr_lod
