// pbr_lod — reading triangle meshes and point clouds from files.
//
// Formats (chosen by the file extension, case-insensitive):
//   .ply  ASCII, binary little and big endian (our own parser: double x/y/z stay double)
//   .obj  via OpenMesh (texture coordinates per face corner, map_Kd texture from the .mtl)
//   .off  via OpenMesh (ASCII; binary "OFF BINARY" without colours/normals)
//   .pcd  PCL point cloud: ascii, binary, binary_compressed (LZF)   — read_points only
//   .las  LAS 1.0–1.4, point formats 0–10                          — read_points only
//   .laz  LAZ (LASzip), point formats 0–10, our own decoder          — read_points only
//         (the format byte decides: a .las holding LAZ, or a .laz holding LAS, read as well)
// (.ply, .pcd, .las and .laz can also be read in blocks, for inputs larger than memory:
// io/point_source_file.hpp.)
// 3-D Gaussian Splatting scenes (3DGS .ply, .splat, .spz) are read by read_gaussians
// (io/gaussians.hpp); read_points on a 3DGS .ply gives its positions only.
//
// What every reader guarantees:
//  * positions are float relative to `origin`, the centre of the bounding box computed in double
//    (a PLY written by write_ply carries its origin and gets it back, so round trips are exact);
//  * points with a NaN/Inf coordinate are dropped and counted, and so are the faces that use them;
//  * every count, offset and index in the file is checked before use: malformed files throw
//    FormatError, unreadable ones IoError, both naming the file, the element and what was expected.
//
// Thread safety: reads of different files may run concurrently. OBJ and OFF go through OpenMesh,
// whose reader modules are global objects with per-read state, so those reads are serialised
// internally by a mutex.
#pragma once

#include <cstddef>
#include <string>
#include <vector>

#include "pbr_lod/core/point_set.hpp"
#include "pbr_lod/core/triangle_mesh.hpp"

namespace pbr_lod {

/// What a read did besides returning data. Reset at the start of every read.
struct read_report {
  std::size_t points_read = 0;         ///< points (vertices) in the file, before dropping any
  std::size_t dropped_non_finite = 0;  ///< of those, dropped for a NaN/Inf coordinate
  std::size_t faces_dropped = 0;  ///< triangles not returned: using a dropped vertex, or degenerate
                                  ///< (a face repeating a vertex index, or with < 3 vertices)
  std::vector<std::string> warnings;  ///< one line each, starting with the file name
  // Gaussian files (io/gaussians.hpp) only; points_read and dropped_non_finite count Gaussians.
  std::size_t dropped_bad_gaussians = 0;  ///< dropped for a non-finite scale or a NaN opacity
  std::size_t rotations_reset = 0;  ///< zero or non-finite quaternions replaced by the identity
  std::size_t values_clamped = 0;   ///< ±inf opacity logits (→ 1 / 0), non-finite SH (→ 0),
                                    ///< negative linear scales (→ |s|)
};

/// Reads a triangle mesh from a .ply, .obj or .off file. Polygons are fan-triangulated. A file
/// without faces (a vertex-only PLY, say) gives a mesh with empty `faces`. Vertex normals and
/// colours are kept when the file has them; OBJ texture coordinates become `face_texcoords` and
/// the map_Kd image of the .mtl `texture_path` (resolved relative to the OBJ's folder; a PLY's
/// `comment TextureFile`), loaded into `texture` when the mesh has texture coordinates (a PNG; one
/// that cannot be read leaves `texture` null with a warning in the report).
/// Throws IoError (cannot open/read) or FormatError (malformed content, unsupported format).
[[nodiscard]] triangle_mesh read_mesh(const std::string& path, read_report* report = nullptr);

/// Reads a point cloud: .ply/.obj/.off (the vertices of read_mesh), .pcd or .las.
/// Throws IoError or FormatError as read_mesh.
[[nodiscard]] point_cloud read_points(const std::string& path, read_report* report = nullptr);

}  // namespace pbr_lod
