// pbr_lod — reading texture images (read_mesh loads a mesh's texture with it; POP §3.1 colours
// from it). The type itself lives in core/texture_image.hpp.
#pragma once

#include <string>

#include "pbr_lod/core/texture_image.hpp"

namespace pbr_lod {

/// Reads a PNG of any colour type (converted to 8-bit RGB(A)) through libpng. Throws IoError
/// when the file cannot be opened, FormatError (naming the file and libpng's reason) when it is
/// not a valid PNG or is empty.
[[nodiscard]] texture_image read_png_texture(const std::string& path);

}  // namespace pbr_lod
