// pbr_lod — area-weighted vertex normals (core/mesh_normals.hpp).
#include "pbr_lod/core/mesh_normals.hpp"

#include <algorithm>

#include "pbr_lod/core/memory.hpp"

namespace pbr_lod {

std::vector<vec3d> area_weighted_normal_sums(const triangle_mesh& m) {
  std::vector<vec3d> acc;
  detail::reserve_huge(acc, m.vertices.size());
  acc.assign(m.vertices.size(), vec3d::Zero());
  const auto& p = m.vertices.positions;
  for (const auto& f : m.faces) {
    const vec3d a = p[f[0]].cast<double>(), b = p[f[1]].cast<double>(), c = p[f[2]].cast<double>();
    const vec3d n = (b - a).cross(c - a);  // |n| = twice the area: the area weighting
    for (auto i : f) acc[i] += n;
  }
  return acc;
}

std::vector<vec3f> area_weighted_normals(const triangle_mesh& m) {
  const std::vector<vec3d> acc = area_weighted_normal_sums(m);
  std::vector<vec3f> out(acc.size());
  std::transform(acc.begin(), acc.end(), out.begin(), unit_or_zero);
  return out;
}

}  // namespace pbr_lod
