// pbr_lod — full-detail reference renders of the input data, the ground truth every LOD render
// is compared with (raster/metrics.hpp).
//
//  * A triangle mesh: every triangle, with per-vertex normals (the mesh's, else area-weighted
//    vertex normals) and per-vertex colours when the mesh has them.
//  * A point cloud: every point as its own splat. With ellipse axes: that ellipse. With normals:
//    a disk in the tangent plane of radius reference_radius_factor × the distance to the
//    reference_knn-th nearest neighbour (8th by default, factor 0.8: see effects.hpp and
//    docs/rasterizer.md for why this closes the surface). Without normals: a screen-aligned
//    square whose side is the projection of that diameter at the point's depth.
#pragma once

#include <cmath>
#include <vector>

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/raster/effects.hpp"
#include "pbr_lod/raster/image.hpp"

namespace pbr_lod {

/// Renders every triangle of m seen by the world camera `cam` (the view is built relative to
/// m.vertices.origin). Throws InvalidArgument when the mesh is invalid (mesh::validate).
[[nodiscard]] image render_reference(const triangle_mesh& m, const camera& cam,
                                     const render_options& opt);

/// Renders every point of c as a splat seen by `cam` (view relative to c.origin). Throws
/// InvalidArgument when the cloud is invalid (point_cloud::validate).
[[nodiscard]] image render_reference(const point_cloud& c, const camera& cam,
                                     const render_options& opt);

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
