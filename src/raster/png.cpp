// pbr_lod — PNG files through libpng's simplified API (png_image, libpng ≥ 1.6), which reports
// errors through a return code and a message instead of longjmp, so no C++ frame is skipped.
#include "pbr_lod/raster/png.hpp"

#include <png.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <vector>

#include "pbr_lod/core/error.hpp"

namespace pbr_lod {

namespace {

struct file_closer {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using file_ptr = std::unique_ptr<std::FILE, file_closer>;

/// Frees libpng's read state on every path out (png_image_free is a no-op once finished).
struct png_image_guard {
  png_image* img;
  ~png_image_guard() { png_image_free(img); }
};

}  // namespace

void write_png(const std::string& path, const image& img) {
  if (img.width <= 0 || img.height <= 0)
    throw InvalidArgument("write_png: " + path + ": image is empty (" + std::to_string(img.width) +
                          "x" + std::to_string(img.height) + ")");
  const std::size_t n = static_cast<std::size_t>(img.width) * static_cast<std::size_t>(img.height);
  if (img.colour.size() != n || img.depth.size() != n)
    throw InvalidArgument("write_png: " + path + ": colour/depth buffers do not match " +
                          std::to_string(img.width) + "x" + std::to_string(img.height));
  std::vector<png_byte> rgba(4 * n);
  for (std::size_t i = 0; i < n; ++i) {
    rgba[4 * i + 0] = img.colour[i].r;
    rgba[4 * i + 1] = img.colour[i].g;
    rgba[4 * i + 2] = img.colour[i].b;
    rgba[4 * i + 3] = img.covered(i) ? 255 : 0;
  }
  file_ptr f(std::fopen(path.c_str(), "wb"));
  if (!f) throw IoError("write_png: cannot open " + path + " for writing: " + std::strerror(errno));
  png_image pi;
  std::memset(&pi, 0, sizeof pi);
  pi.version = PNG_IMAGE_VERSION;
  pi.width = static_cast<png_uint_32>(img.width);
  pi.height = static_cast<png_uint_32>(img.height);
  pi.format = PNG_FORMAT_RGBA;
  const int ok = png_image_write_to_stdio(&pi, f.get(), 0, rgba.data(), 0, nullptr);
  const std::string message = pi.message;
  png_image_free(&pi);
  if (!ok) throw IoError("write_png: cannot write " + path + ": " + message);
  if (std::fflush(f.get()) != 0 || std::ferror(f.get()))
    throw IoError("write_png: cannot write " + path + ": " + std::strerror(errno));
  if (std::fclose(f.release()) != 0)
    throw IoError("write_png: cannot close " + path + ": " + std::strerror(errno));
}

image read_png(const std::string& path) {
  file_ptr f(std::fopen(path.c_str(), "rb"));
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
  image img(static_cast<int>(pi.width), static_cast<int>(pi.height));
  for (std::size_t i = 0; i < n; ++i) {
    img.colour[i] = {rgba[4 * i], rgba[4 * i + 1], rgba[4 * i + 2]};
    img.depth[i] =
        (!has_alpha || rgba[4 * i + 3] != 0) ? 0.0f : std::numeric_limits<float>::infinity();
  }
  return img;
}

}  // namespace pbr_lod
