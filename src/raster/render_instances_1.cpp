// pbr_lod — the rasteriser's effect combinations for two attribute sets, compiled once here
// (declared extern in raster/rasterizer.hpp). Four files, so a parallel build shares the work.
#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {
PBR_LOD_RENDER_BUFFERED(, true, true, false)
PBR_LOD_RENDER_BUFFERED(, false, false, false)
}  // namespace pbr_lod
