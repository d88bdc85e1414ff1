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
/// white background. Labels use a built-in 5×7 bitmap font drawn at twice its size (upper case;
/// lower case is drawn as upper case; characters it lacks are drawn as '?').
[[nodiscard]] pbr_lod::image contact_sheet(const std::vector<std::vector<sheet_tile>>& rows);

/// The colour image shrunk by an integer factor (box filter; depth is kept where any source
/// pixel was covered). factor ≥ 1.
[[nodiscard]] pbr_lod::image shrink(const pbr_lod::image& src, int factor);

/// Pixels a label line of n characters takes: the width of the font at the sheet's scale.
[[nodiscard]] int label_width(std::size_t n);

}  // namespace pbrlod_tool
