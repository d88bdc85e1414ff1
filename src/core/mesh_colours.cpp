// pbr_lod — a textured mesh's colours at its vertices (core/mesh_colours.hpp).
#include "pbr_lod/core/mesh_colours.hpp"

#include <array>
#include <cmath>

namespace pbr_lod {

std::vector<rgb8> texture_vertex_colours(const triangle_mesh& m) {
  m.validate("texture_vertex_colours: mesh");  // every face's indices name a vertex
  if (!m.textured()) return {};
  const texture_image* tex = m.texture.get();
  const std::size_t n = m.vertices.size();
  std::vector<std::array<double, 3>> sum(n, {0, 0, 0});
  std::vector<std::uint32_t> count(n, 0);
  for (std::size_t f = 0; f < m.faces.size(); ++f)
    for (std::size_t k = 0; k < 3; ++k) {
      const vec2f& uv = m.face_texcoords[f][k];
      if (!std::isfinite(uv.x()) || !std::isfinite(uv.y())) continue;
      const rgb8 c = sample_texture(*tex, uv);
      auto& s = sum[m.faces[f][k]];
      s[0] += c.r;
      s[1] += c.g;
      s[2] += c.b;
      ++count[m.faces[f][k]];
    }
  std::array<double, 3> mean{0, 0, 0};
  for (const rgb8& c : tex->texels) {
    mean[0] += c.r;
    mean[1] += c.g;
    mean[2] += c.b;
  }
  const double texels = static_cast<double>(tex->texels.size());
  const auto channel = [](double v) {
    return static_cast<std::uint8_t>(std::lround(std::fmin(std::fmax(v, 0.0), 255.0)));
  };
  std::vector<rgb8> out(n);
  for (std::size_t i = 0; i < n; ++i) {
    const auto& s = count[i] > 0 ? sum[i] : mean;
    const double d = 1.0 / (count[i] > 0 ? static_cast<double>(count[i]) : texels);
    out[i] = {channel(s[0] * d), channel(s[1] * d), channel(s[2] * d)};
  }
  return out;
}

}  // namespace pbr_lod
