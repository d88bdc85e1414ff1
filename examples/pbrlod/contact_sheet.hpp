// pbrlod — the demo's contact sheet: rendered tiles in a grid, each labelled underneath.
#pragma once

#include <string>
#include <vector>

#include "pbr_lod/raster/image.hpp"

namespace pbrlod_tool {

struct sheet_tile {
  pbr_lod::image img;              ///< all tiles of a sheet have the same size
  std::vector<std::string> lines;  ///< label lines drawn under the tile
};

/// The tiles row by row (rows may differ in length), each with its label lines under it, on a
/// white background. Labels use a built-in 5×7 bitmap font (upper case; lower case is drawn as
/// upper case; characters it lacks as '?'), at twice its size under tiles of 300 pixels or
/// more, clipped at the tile's width.
[[nodiscard]] pbr_lod::image contact_sheet(const std::vector<std::vector<sheet_tile>>& rows);

/// The colour image shrunk by an integer factor (box filter; depth is kept where any source
/// pixel was covered). factor ≥ 1.
[[nodiscard]] pbr_lod::image shrink(const pbr_lod::image& src, int factor);

}  // namespace pbrlod_tool
