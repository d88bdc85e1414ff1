// pbr_lod — a texture image, as a mesh carries it (triangle_mesh::texture), a builder keeps it
// (POP §3.1, Figure 5) and a textured_triangle_prim points into it. Reading one from a file is
// io's job (io/texture.hpp); this type needs nothing from io/ or raster/.
#pragma once

#include <cstdint>
#include <vector>

#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// An 8-bit RGB texture, rows top to bottom.
struct texture_image {
  int width = 0, height = 0;
  std::vector<rgb8> texels;         ///< width × height
  std::vector<std::uint8_t> alpha;  ///< width × height, or empty when the file has no alpha

  [[nodiscard]] bool operator==(const texture_image&) const = default;
};

}  // namespace pbr_lod
