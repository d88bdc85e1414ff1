// pbr_lod — PNG input through libpng's simplified API (png_image, libpng ≥ 1.6), which reports
// errors through a return code and a message instead of longjmp, so no C++ frame is skipped.
#include <png.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/io/texture.hpp"

namespace pbr_lod {

namespace {
struct file_closer {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
/// Frees libpng's read state on every path out (png_image_free is a no-op once finished).
struct png_image_guard {
  png_image* img;
  ~png_image_guard() { png_image_free(img); }
};
}  // namespace

texture_image read_png_texture(const std::string& path) {
  const std::unique_ptr<std::FILE, file_closer> f(std::fopen(path.c_str(), "rb"));
  if (!f) throw IoError("read_png: cannot open " + path + ": " + std::strerror(errno));
  png_image pi;
  std::memset(&pi, 0, sizeof pi);
  pi.version = PNG_IMAGE_VERSION;
  png_image_guard guard{&pi};
  if (!png_image_begin_read_from_stdio(&pi, f.get()))
    throw FormatError("read_png: " + path + " is not a readable PNG: " + pi.message);
  const bool has_alpha = (pi.format & PNG_FORMAT_FLAG_ALPHA) != 0;
  if (pi.width == 0 || pi.height == 0 ||
      pi.width > static_cast<png_uint_32>(std::numeric_limits<int>::max()) ||
      pi.height > static_cast<png_uint_32>(std::numeric_limits<int>::max()) ||
      std::size_t(pi.width) * pi.height > (std::size_t(1) << 31))
    throw FormatError("read_png: " + path + ": unsupported size " + std::to_string(pi.width) + "x" +
                      std::to_string(pi.height));
  // 8-bit sRGB RGBA: libpng converts palette, grey and 16-bit input; colour is not
  // premultiplied in the 8-bit formats.
  pi.format = PNG_FORMAT_RGBA;
  const std::size_t n = std::size_t(pi.width) * pi.height;
  std::vector<png_byte> rgba(PNG_IMAGE_SIZE(pi));
  if (!png_image_finish_read(&pi, nullptr, rgba.data(), 0, nullptr))
    throw FormatError("read_png: " + path + " is corrupt: " + pi.message);
  texture_image t;
  t.width = static_cast<int>(pi.width);
  t.height = static_cast<int>(pi.height);
  t.texels.resize(n);
  if (has_alpha) t.alpha.resize(n);
  for (std::size_t i = 0; i < n; ++i) {
    t.texels[i] = {rgba[4 * i], rgba[4 * i + 1], rgba[4 * i + 2]};
    if (has_alpha) t.alpha[i] = rgba[4 * i + 3];
  }
  return t;
}

}  // namespace pbr_lod
