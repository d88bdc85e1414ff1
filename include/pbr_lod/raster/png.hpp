// pbr_lod — PNG output and input of rendered images (libpng, fenced off in src/raster/png.cpp).
//
// Coverage survives the round trip through the alpha channel: covered pixels are written with
// alpha 255, background pixels with alpha 0 (their RGB keeps the background colour).
#pragma once

#include <string>

#include "pbr_lod/raster/image.hpp"

namespace pbr_lod {

/// Writes an 8-bit RGBA PNG: RGB = img.colour, alpha = 255 where covered, 0 where background.
/// Throws InvalidArgument for an empty image or inconsistent buffers, IoError naming the file
/// when it cannot be written.
void write_png(const std::string& path, const image& img);

/// Reads a PNG of any colour type (converted to 8-bit RGB(A)). Pixels with alpha 0 are
/// background (depth +inf), every other pixel is covered with depth 0; a PNG without an alpha
/// channel is covered everywhere. Throws IoError when the file cannot be opened, FormatError
/// (naming the file and libpng's reason) when it is not a valid PNG.
[[nodiscard]] image read_png(const std::string& path);

}  // namespace pbr_lod
