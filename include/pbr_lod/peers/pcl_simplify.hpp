// pbr_lod — PCL's level-of-detail tools as peers: a VoxelGrid pyramid and an octree's leaf
// means at a resolution, which `pbrlod sweep` measures beside the builders (docs/accuracy.md).
//
// Optional: these live in the library pbr_lod::peers_pcl, built only when PCL is found
// (CMake option PBR_LOD_PEERS=AUTO|ON|OFF), so pbr_lod itself never depends on PCL. PCL stays
// out of this header.
#pragma once

#include "pbr_lod/core/point_set.hpp"

namespace pbr_lod::peers {

/// pcl::VoxelGrid with cubic leaves of side `leaf`: one point per occupied voxel, the centroid
/// of its points; normals are averaged and renormalised, colours averaged. Throws
/// InvalidArgument for leaf ≤ 0 or not finite (and for a grid too fine for PCL's 32-bit voxel
/// index, which PCL would only warn about).
[[nodiscard]] point_cloud pcl_voxel_grid(const point_cloud& in, double leaf);

/// A PCL octree (pcl::octree::OctreePointCloudPointVector) with leaf voxels of side
/// `resolution`: one point per occupied leaf, the mean of its points (normals renormalised,
/// colours averaged). Throws InvalidArgument for resolution ≤ 0 or not finite.
[[nodiscard]] point_cloud pcl_octree_centroids(const point_cloud& in, double resolution);

}  // namespace pbr_lod::peers
