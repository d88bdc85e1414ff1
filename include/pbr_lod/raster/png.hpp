// pbr_lod — PNG output of rendered images (libpng, fenced off in src/raster/png.cpp), and the
// image of a PNG read by io (io/texture.hpp's read_png_texture): raster/ does not read files.
//
// Coverage survives the round trip through the alpha channel: covered pixels are written with
// alpha 255, background pixels with alpha 0 (their RGB keeps the background colour):
// image_from_texture(read_png_texture(path)) reads back what write_png(path, img) wrote.
#pragma once

#include <string>

#include "pbr_lod/core/texture_image.hpp"
#include "pbr_lod/raster/image.hpp"

namespace pbr_lod {

/// Writes an 8-bit RGBA PNG: RGB = img.colour, alpha = 255 where covered, 0 where background.
/// Throws InvalidArgument for an empty image or inconsistent buffers, IoError naming the file
/// when it cannot be written.
void write_png(const std::string& path, const image& img);

/// The image of a texture (a PNG as read_png_texture reads it): texels with alpha 0 are background
/// (depth +inf), every other texel is covered with depth 0; a texture without alpha is covered
/// everywhere.
[[nodiscard]] image image_from_texture(const texture_image& t);

}  // namespace pbr_lod
