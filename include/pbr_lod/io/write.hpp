// pbr_lod — writing point clouds and triangle meshes as PLY.
//
// Positions are written as world coordinates in double (`property double x y z`), so any PLY
// reader sees the data where it is, and the cloud's double origin goes into a comment
// ("comment pbr_lod_origin X Y Z") that read_mesh/read_points use, so read → write → read gives
// back identical positions, normals, colours, faces and texture coordinates.
//
// Layout: vertex x y z (double), nx ny nz (float) when present, red green blue (uchar) when
// present; face `list uchar int vertex_indices` (uint when there are more than 2³¹−1 vertices)
// and, for textured meshes, MeshLab's `list uchar float texcoord` plus "comment TextureFile"
// (the texture path relative to the PLY's folder when it can be).
#pragma once

#include <string>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// Writes a point cloud (a vertex-only PLY). Throws InvalidArgument when the cloud is not valid
/// (see point_cloud::validate) and IoError when the file cannot be written.
void write_ply(const std::string& path, const point_cloud& cloud, bool binary = true);

/// Writes a triangle mesh. Throws InvalidArgument when the mesh is not valid (see
/// triangle_mesh::validate) and IoError when the file cannot be written.
void write_ply(const std::string& path, const triangle_mesh& mesh, bool binary = true);

}  // namespace pbr_lod
