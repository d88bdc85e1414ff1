// pbr_lod — a texture image, as a mesh carries it (triangle_mesh::texture), a builder keeps it
// (POP §3.1, Figure 5) and a textured_triangle_prim points into it. Reading one from a file is
// io's job (io/texture.hpp); this type needs nothing from io/ or raster/.
#pragma once

#include <cmath>
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
  /// Whether it can be sampled: a positive size and that many texels.
  [[nodiscard]] bool valid() const {
    return width > 0 && height > 0 &&
           texels.size() == static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  }
};

/// Texel space of texture coordinates uv (OpenGL's: (0, 0) the bottom-left corner of the image,
/// (1, 1) the top-right), minus the half texel that puts texel centres on integers.
[[nodiscard]] inline vec2f texel_position(const texture_image& tex, const vec2f& uv) {
  return {uv.x() * static_cast<float>(tex.width) - 0.5f,
          (1 - uv.y()) * static_cast<float>(tex.height) - 0.5f};
}

/// Bilinear sample of `tex` at texel-space (x, y) with texel centres on integers, wrapping
/// (GL_REPEAT): the four texels around (x, y) weighted by their distances. Non-finite
/// coordinates give texel (0, 0).
[[nodiscard]] inline rgb8 sample_bilinear_repeat(const texture_image& tex, float x, float y) {
  if (!std::isfinite(x) || !std::isfinite(y)) return tex.texels[0];
  const float fx = std::floor(x), fy = std::floor(y);
  const float tx = x - fx, ty = y - fy;
  const auto wrap = [](float f, int n) {
    const double m = std::fmod(static_cast<double>(f), static_cast<double>(n));
    const int i = static_cast<int>(m < 0 ? m + n : m);
    return i >= n ? 0 : i;  // m + n may round up to n
  };
  const int w = tex.width, h = tex.height;
  const int x0 = wrap(fx, w), y0 = wrap(fy, h);
  const int x1 = x0 + 1 == w ? 0 : x0 + 1, y1 = y0 + 1 == h ? 0 : y0 + 1;
  const auto at = [&](int i, int j) {
    return tex.texels[static_cast<std::size_t>(j) * static_cast<std::size_t>(w) +
                      static_cast<std::size_t>(i)];
  };
  const rgb8 c00 = at(x0, y0), c10 = at(x1, y0), c01 = at(x0, y1), c11 = at(x1, y1);
  const auto mix = [tx, ty](std::uint8_t a, std::uint8_t b, std::uint8_t c, std::uint8_t d) {
    const float top = float(a) + (float(b) - float(a)) * tx;
    const float bottom = float(c) + (float(d) - float(c)) * tx;
    const float v = top + (bottom - top) * ty;  // rounded and clamped, NaN → 0
    return v > 0 ? (v >= 255 ? std::uint8_t{255} : static_cast<std::uint8_t>(v + 0.5f))
                 : std::uint8_t{0};
  };
  return {mix(c00.r, c10.r, c01.r, c11.r), mix(c00.g, c10.g, c01.g, c11.g),
          mix(c00.b, c10.b, c01.b, c11.b)};
}
/// The texture's colour at texture coordinates uv, as the rasteriser samples a textured
/// triangle.
[[nodiscard]] inline rgb8 sample_texture(const texture_image& tex, const vec2f& uv) {
  const vec2f t = texel_position(tex, uv);
  return sample_bilinear_repeat(tex, t.x(), t.y());
}

}  // namespace pbr_lod
