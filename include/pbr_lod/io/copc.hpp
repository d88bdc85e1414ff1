// pbr_lod — writing a level-of-detail point hierarchy as COPC (Cloud Optimized Point Cloud 1.0,
// copc.io): a LAZ 1.4 file whose points are grouped into the nodes of a regular octree, one
// variable-size LAZ chunk per node, with the octree's index in an extended VLR. PDAL, QGIS,
// CloudCompare, Potree and the `copc` npm package open it; any LAZ 1.4 reader reads its points.
//
// What goes where (docs/io.md, "COPC out"): each point carries its hierarchy level (the depth of
// the node that holds it: an inner node's representative at its depth, a leaf's samples at the
// leaf's). COPC readers refine additively — reading octree levels 0…L gives every point stored
// at those levels — so hierarchy level ℓ is stored in COPC level max(0, ℓ − shift), in the voxel
// of that level that contains it; `shift` is the smallest that makes the mean node hold at
// least copc_options::node_points points (a LAZ chunk per few points would cost more than the
// points). Reading COPC levels 0…L therefore gives hierarchy levels 0…L + shift: our cut at that
// level plus the coarser representatives above it. Each record's user data byte is its
// hierarchy level, so a reader that wants exactly one cut can select it.
//
// Records: point data record format 7 with colour, else 6 (X, Y, Z scaled by a power of ten that
// keeps the extent within 2^30 steps; return 1 of 1; class 0), and with normals three float
// extra bytes NormalX, NormalY, NormalZ (described in the LAS 1.4 Extra Bytes VLR). The file is
// written to a temporary name and renamed (core/atomic_file.hpp); the same input and options
// give the same bytes.
#pragma once

#include <cstdint>
#include <span>
#include <string>

#include "pbr_lod/core/point_set.hpp"

namespace pbr_lod {

struct copc_options {
  /// The level shift is the smallest that gives at least this many points per non-empty node
  /// on average (PDAL's COPC writer aims at nodes of a few thousand points).
  std::uint32_t node_points = 4096;
  /// The spatial reference as OGC WKT (a LASF_Projection VLR, record 2112), or empty for none.
  std::string wkt = {};
  unsigned threads = 0;  ///< for compressing the nodes (0: every core)
};

/// What write_copc wrote.
struct copc_summary {
  std::uint64_t points = 0;
  std::uint64_t nodes = 0;        ///< hierarchy entries with points
  std::uint64_t empty_nodes = 0;  ///< entries without points that lead to nodes with points
  int shift = 0;                  ///< hierarchy level ℓ is COPC level max(0, ℓ − shift)
  int max_level = 0;              ///< the deepest COPC level
  vec3d centre = vec3d::Zero();   ///< the octree's cube, in world coordinates
  double halfsize = 0;
  double spacing = 0;  ///< the info VLR's spacing at the root
  double scale = 0;    ///< of X, Y and Z
  std::uint64_t bytes = 0;
};

/// Writes `points` (world positions origin + position; normals and colours when it has them)
/// as a COPC file at `path`, point i at hierarchy level levels[i]. Throws InvalidArgument for an
/// invalid cloud or a levels span of another size, and IoError when the file cannot be written
/// (the previous file at `path`, if any, is then unchanged).
copc_summary write_copc(const std::string& path, const point_cloud& points,
                        std::span<const std::uint8_t> levels, const copc_options& options = {});

/// The spatial reference of a LAS or LAZ file as OGC WKT (its LASF_Projection VLR or EVLR,
/// record 2112), or empty when it has none (a file with only GeoTIFF keys has none in WKT).
/// Throws IoError / FormatError as read_points does.
[[nodiscard]] std::string las_wkt(const std::string& path);

}  // namespace pbr_lod
