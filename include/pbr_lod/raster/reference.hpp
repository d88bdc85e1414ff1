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

#include "pbr_lod/core/camera.hpp"
#include "pbr_lod/core/mesh_normals.hpp"  // area_weighted_normals(), which the reference shades with
#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"
#include "pbr_lod/raster/effects.hpp"
#include "pbr_lod/raster/image.hpp"
#include "pbr_lod/traverse/widening_sink.hpp"

namespace pbr_lod {

/// Renders every triangle of m seen by the world camera `cam` (the view is built relative to
/// m.vertices.origin). Throws InvalidArgument when the mesh is invalid (mesh::validate).
[[nodiscard]] image render_reference(const triangle_mesh& m, const camera& cam,
                                     const render_options& opt);

/// Renders every point of c as a splat seen by `cam` (view relative to c.origin). Throws
/// InvalidArgument when the cloud is invalid (point_cloud::validate).
[[nodiscard]] image render_reference(const point_cloud& c, const camera& cam,
                                     const render_options& opt);

/// The primitives render_reference(m, cam, opt) draws, appended to `out` for a host renderer
/// that draws the reference itself (examples/gl_viewer), in the same order, relative to
/// m.vertices.origin. Returns the attributes they carry: fields outside it are zero. Throws as
/// render_reference.
attributes reference_primitives(const triangle_mesh& m, const camera& cam,
                                buffer_sink<with_normals_colours>& out);

/// The same for render_reference(c, cam, opt): the splats (or, without normals, the squares
/// sized for this camera) of every point, relative to c.origin.
attributes reference_primitives(const point_cloud& c, const camera& cam, const render_options& opt,
                                buffer_sink<with_normals_colours>& out);

}  // namespace pbr_lod
