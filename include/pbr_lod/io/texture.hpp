// pbr_lod — reading texture images, for builders that colour a mesh from its texture (POP §3.1).
// Pixels in, texels out: no rendering types, so a builder needs nothing from raster/.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// An 8-bit RGB texture, rows top to bottom.
struct texture_image {
  int width = 0, height = 0;
  std::vector<rgb8> texels;         ///< width × height
  std::vector<std::uint8_t> alpha;  ///< width × height, or empty when the file has no alpha
};

/// Reads a PNG of any colour type (converted to 8-bit RGB(A)) through libpng. Throws IoError
/// when the file cannot be opened, FormatError (naming the file and libpng's reason) when it is
/// not a valid PNG or is empty.
[[nodiscard]] texture_image read_png_texture(const std::string& path);

}  // namespace pbr_lod
