// pbr_lod — write_gaussians_ply: the standard 3DGS PLY (layout in io/gaussians.hpp).
//
// Float x y z, as every 3DGS file has them, so every 3DGS viewer opens the result; the cloud's
// double origin also goes into "comment pbr_lod_origin", which other readers skip and
// read_gaussians uses, so a round trip keeps the origin.
#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <limits>

#include "io_internal.hpp"
#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/io/gaussians.hpp"

namespace pbr_lod {
namespace {

std::string shortest(double v) {
  char tmp[64];
  const auto r = std::to_chars(tmp, tmp + sizeof tmp, v);
  return std::string(tmp, r.ptr);
}

std::string header(const gaussian_cloud& c) {
  const int rest = 3 * (sh_coefficients(c.sh_degree) - 1);
  std::string h = "ply\nformat binary_little_endian 1.0\ncomment written by pbr_lod\n";
  h += "comment pbr_lod_origin " + shortest(c.origin.x()) + " " + shortest(c.origin.y()) + " " +
       shortest(c.origin.z()) + "\n";
  h += detail::cat("element vertex ", c.size(), "\n");
  for (const char* n : {"x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"})
    h += detail::cat("property float ", n, "\n");
  for (int k = 0; k < rest; ++k) h += detail::cat("property float f_rest_", k, "\n");
  for (const char* n :
       {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"})
    h += detail::cat("property float ", n, "\n");
  return h + "end_header\n";
}

}  // namespace

void write_gaussians_ply(const gaussian_cloud& c, const std::string& path) {
  c.validate(path, std::numeric_limits<float>::infinity());  // merged opacities > 1: written as 1
  const std::string h = header(c);
  const int m = sh_coefficients(c.sh_degree) - 1;
  const std::size_t floats = 9 + 3 * static_cast<std::size_t>(m) + 8;

  atomic_output file(path);
  std::ofstream out(file.temp_path(), std::ios::binary | std::ios::trunc);
  if (!out) throw IoError(path + ": cannot open for writing: " + std::strerror(errno));
  out.write(h.data(), static_cast<std::streamsize>(h.size()));

  // The inverse activations. Opacities 0 and 1 and scale 0 have no finite logit / log: clamped
  // just inside, so the file holds no inf (readers in other tools choke on it).
  constexpr float o_lo = 1e-7f, o_hi = 1.0f - 1e-7f;
  const float s_lo = std::numeric_limits<float>::denorm_min();
  std::vector<float> row(floats);
  std::vector<char> buf;
  buf.reserve(std::size_t{1} << 20);
  for (std::size_t i = 0; i < c.size(); ++i) {
    std::size_t k = 0;
    const vec3d p = c.world(i);
    for (int a = 0; a < 3; ++a) row[k++] = static_cast<float>(p[a]);
    for (int a = 0; a < 3; ++a) row[k++] = 0.0f;  // nx ny nz: zero in every 3DGS file
    for (int ch = 0; ch < 3; ++ch) row[k++] = c.sh[c.sh_index(i, 0, ch)];
    for (int ch = 0; ch < 3; ++ch)  // f_rest channel-major: all R, then G, then B
      for (int j = 1; j <= m; ++j) row[k++] = c.sh[c.sh_index(i, j, ch)];
    const double o = std::clamp(c.opacities[i], o_lo, o_hi);
    row[k++] = static_cast<float>(std::log(o / (1.0 - o)));
    for (int a = 0; a < 3; ++a)
      row[k++] = static_cast<float>(std::log(static_cast<double>(std::max(c.scales[i][a], s_lo))));
    for (int a = 0; a < 4; ++a) row[k++] = c.rotations[i][a];
    for (float v : row) {
      if constexpr (std::endian::native == std::endian::big) v = detail::byte_swapped(v);
      const auto* b = reinterpret_cast<const char*>(&v);
      buf.insert(buf.end(), b, b + sizeof v);
    }
    if (buf.size() >= (std::size_t{1} << 20) || i + 1 == c.size()) {
      out.write(buf.data(), static_cast<std::streamsize>(buf.size()));
      buf.clear();
      if (!out) throw IoError(path + ": cannot write: " + std::strerror(errno));
    }
  }
  out.close();
  if (!out) throw IoError(path + ": cannot write: " + std::strerror(errno));
  file.commit();
}

}  // namespace pbr_lod
