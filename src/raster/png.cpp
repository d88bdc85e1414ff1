// pbr_lod — PNG output through libpng's simplified API (png_image, libpng ≥ 1.6), which reports
// errors through a return code and a message instead of longjmp, so no C++ frame is skipped. Input
// is io/texture.hpp's read_png_texture(), turned into an image by image_from_texture().
#include "pbr_lod/raster/png.hpp"

#include <png.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "pbr_lod/core/atomic_file.hpp"
#include "pbr_lod/core/error.hpp"

namespace pbr_lod {

namespace {

struct file_closer {
  void operator()(std::FILE* f) const { std::fclose(f); }
};
using file_ptr = std::unique_ptr<std::FILE, file_closer>;

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
  // Whole or not at all: written beside the target, renamed over it once complete.
  atomic_output file(path);
  file_ptr f(std::fopen(file.temp_path().c_str(), "wb"));
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
  file.commit();
}

image image_from_texture(const texture_image& t) {
  const auto n = static_cast<std::size_t>(std::max(t.width, 0)) *
                 static_cast<std::size_t>(std::max(t.height, 0));
  if (t.width <= 0 || t.height <= 0 || t.texels.size() != n ||
      (!t.alpha.empty() && t.alpha.size() != n))
    throw InvalidArgument("image_from_texture: " + std::to_string(t.width) + " x " +
                          std::to_string(t.height) + " texture with " +
                          std::to_string(t.texels.size()) + " texels and " +
                          std::to_string(t.alpha.size()) + " alpha values");
  image img(t.width, t.height);
  img.colour = t.texels;
  for (std::size_t i = 0; i < img.depth.size(); ++i)
    img.depth[i] =
        (t.alpha.empty() || t.alpha[i] != 0) ? 0.0f : std::numeric_limits<float>::infinity();
  return img;
}

}  // namespace pbr_lod
