// pbr_lod — a triangle mesh's vertices as splats: what a point builder draws when its input is
// a mesh, so its finest cut covers the mesh's surface and no more.
//
// The splat of vertex v lies in v's tangent plane (the mesh's vertex normal) and bounds v's
// barycentric dual cell: for every face around v, the midpoints of its two edges at v and its
// centroid. The dual cells tile the surface, so the splats cover it (up to the projection onto
// each tangent plane), and a splat reaches about half an edge beyond its vertex — at an open
// edge, a crease or a silhouette it overhangs by that, not by the k-NN neighbourhood's radius
// (two rings) that an ellipse estimated from the positions bounds (core/estimation.hpp).
#pragma once

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// The vertices of `m` with normals and splat ellipses (axis_u major, axis_v minor semi-axis).
///  * Normals: the mesh's own where it has them (non-zero, finite), else area-weighted
///    (core/mesh_normals.hpp, what the reference renderer shades a mesh without normals with).
///  * Ellipse: centred at the vertex, in the plane orthogonal to its normal, bounding the tangent
///    projections of its dual cell's corners by Pajarola's rule (2003, Fig. 6a: the second-
///    moment ellipse about the centre scaled to hold every corner), minor/major ≥
///    splat_min_axis_ratio (core/estimation.hpp).
///  * A vertex with no face of non-zero area covers no surface and is left out (unreferenced
///    vertices: the mesh's render does not draw them either); colours and materials of the
///    others are kept, the origin too. A textured mesh without vertex colours gives its splats
///    the texture's colours at their vertices (texture_vertex_colours, core/mesh_colours.hpp).
/// Throws InvalidArgument when the mesh does not validate. A mesh without faces gives an empty
/// cloud.
[[nodiscard]] point_cloud mesh_splats(const triangle_mesh& m);

}  // namespace pbr_lod
