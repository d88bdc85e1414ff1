// pbr_lod — the point-octree (Pajarola 2003) compiled once for the inputs without colour
// (declared extern in builders/point_octree.hpp). Two files, so a parallel build shares the work.
#include "pbr_lod/builders/point_octree.hpp"

namespace pbr_lod {
PBR_LOD_POINT_OCTREE_CLASS(, false)
PBR_LOD_POINT_OCTREE_BUILD(, false, false, false)
PBR_LOD_POINT_OCTREE_BUILD(, true, false, false)
PBR_LOD_POINT_OCTREE_BUILD(, false, false, true)
PBR_LOD_POINT_OCTREE_BUILD(, true, false, true)
}  // namespace pbr_lod
