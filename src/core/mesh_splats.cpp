// pbr_lod — a mesh's vertices as splats bounding their dual cells (core/mesh_splats.hpp).
#include "pbr_lod/core/mesh_splats.hpp"

#include <algorithm>
#include <cmath>

#include "moment_ellipse.hpp"
#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/mesh_colours.hpp"
#include "pbr_lod/core/mesh_normals.hpp"

namespace pbr_lod {
namespace {

/// The given normal when it is usable, else the area-weighted sum's direction (or zero).
vec3d vertex_normal(const triangle_mesh& m, const std::vector<vec3d>& sums, std::size_t i) {
  if (!m.vertices.normals.empty()) {
    const vec3d n = m.vertices.normals[i].cast<double>();
    const double len = n.norm();
    if (len > 0 && std::isfinite(len)) return n / len;
  }
  const double len = sums[i].norm();
  return len > 0 && std::isfinite(len) ? vec3d(sums[i] / len) : vec3d::Zero();
}

/// A unit vector orthogonal to the unit vector n (any_orthogonal in double).
vec3d tangent_of(const vec3d& n) {
  const vec3d a = n.cwiseAbs();
  const vec3d axis = (a.x() <= a.y() && a.x() <= a.z()) ? vec3d::UnitX()
                     : (a.y() <= a.z())                 ? vec3d::UnitY()
                                                        : vec3d::UnitZ();
  return n.cross(axis).normalized();
}

/// Semi-axes (major u, minor v; vectors) of the ellipse centred at the origin of the tangent
/// frame (t1, t2) that holds every offset in xy: the second-moment ellipse about the centre,
/// scaled by the largest normalised distance of an offset (Pajarola 2003, Fig. 6a). Zero axes
/// when every offset is zero.
std::pair<vec3d, vec3d> bounding_ellipse(const std::vector<vec2d>& xy, const vec3d& t1,
                                         const vec3d& t2) {
  detail::moments_2d m;
  for (const auto& q : xy) m.add(q);
  if (!(m.major() > 0)) return {vec3d::Zero(), vec3d::Zero()};
  constexpr double ratio2 = splat_min_axis_ratio * splat_min_axis_ratio;
  const auto e = detail::covering_ellipse(m, xy, ratio2);
  const double f = e.f * (1 + 1e-5);  // float rounding never leaves a corner outside
  return {f * std::sqrt(e.l1) * (e.e1.x() * t1 + e.e1.y() * t2),
          f * std::sqrt(e.l2) * (e.e2.x() * t1 + e.e2.y() * t2)};
}

}  // namespace

point_cloud mesh_splats(const triangle_mesh& m) {
  m.validate("mesh_splats");
  const auto& p = m.vertices.positions;
  const std::size_t n = p.size();
  const std::vector<vec3d> sums = area_weighted_normal_sums(m);
  // Each vertex's dual-cell corners, as offsets from it: per face, the two edge midpoints at
  // the vertex and the centroid.
  std::vector<std::uint32_t> count(n + 1, 0);
  for (const auto& f : m.faces)
    for (const auto i : f) ++count[i + 1];
  for (std::size_t i = 0; i < n; ++i) count[i + 1] += count[i];
  std::vector<std::uint32_t> faces_of(count[n]), fill(count.begin(), count.end() - 1);
  for (std::uint32_t f = 0; f < m.faces.size(); ++f)
    for (const auto i : m.faces[f]) faces_of[fill[i]++] = f;

  point_cloud out;
  out.origin = m.vertices.origin;
  // A textured mesh without vertex colours is seen textured: its splats take the texture's
  // colour at their vertex.
  const std::vector<rgb8> texture_colours =
      m.vertices.colours.empty() ? texture_vertex_colours(m) : std::vector<rgb8>{};
  const std::vector<rgb8>& colours =
      m.vertices.colours.empty() ? texture_colours : m.vertices.colours;
  std::vector<vec2d> xy;
  for (std::size_t i = 0; i < n; ++i) {
    const vec3d nrm = vertex_normal(m, sums, i);
    if (sums[i].squaredNorm() == 0 || nrm.squaredNorm() == 0) continue;  // no surface here
    const vec3d pi = p[i].cast<double>();
    const vec3d t1 = tangent_of(nrm), t2 = nrm.cross(t1);
    xy.clear();
    for (std::uint32_t k = count[i]; k < count[i + 1]; ++k) {
      const auto& f = m.faces[faces_of[k]];
      const vec3d centroid =
          (p[f[0]].cast<double>() + p[f[1]].cast<double>() + p[f[2]].cast<double>()) / 3.0 - pi;
      for (const vec3d& d :
           {centroid, vec3d(0.5 * (p[f[0]].cast<double>() - pi)),
            vec3d(0.5 * (p[f[1]].cast<double>() - pi)), vec3d(0.5 * (p[f[2]].cast<double>() - pi))})
        xy.emplace_back(d.dot(t1), d.dot(t2));  // the vertex itself adds (0, 0)
    }
    const auto [u, v] = bounding_ellipse(xy, t1, t2);
    if (u.squaredNorm() == 0) continue;  // every corner on the normal: no tangent extent
    out.positions.push_back(p[i]);
    out.normals.push_back(nrm.cast<float>());
    out.axis_u.push_back(u.cast<float>());
    out.axis_v.push_back(v.cast<float>());
    if (!colours.empty()) out.colours.push_back(colours[i]);
    if (!m.vertices.materials.empty()) out.materials.push_back(m.vertices.materials[i]);
  }
  return out;
}

}  // namespace pbr_lod
