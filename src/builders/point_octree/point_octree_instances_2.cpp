// pbr_lod — the point-octree (Pajarola 2003) compiled once for the inputs with colour
// (declared extern in builders/point_octree.hpp). Two files, so a parallel build shares the work.
#include "pbr_lod/builders/point_octree.hpp"

namespace pbr_lod {
PBR_LOD_POINT_OCTREE_CLASS(, true)
PBR_LOD_POINT_OCTREE_BUILD(, false, true, false)
PBR_LOD_POINT_OCTREE_BUILD(, true, true, false)
PBR_LOD_POINT_OCTREE_BUILD(, false, true, true)
PBR_LOD_POINT_OCTREE_BUILD(, true, true, true)
}  // namespace pbr_lod
