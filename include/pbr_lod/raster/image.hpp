// pbr_lod — the image a rasteriser produces: colour plus eye-space depth per pixel.
//
// Depth is what says whether a pixel is covered: +inf means "background, nothing drawn here".
// Keeping coverage explicit (rather than comparing colours with the background colour) is what
// lets the metrics count holes exactly and lets a PNG round trip (alpha = coverage) keep it.
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/math.hpp"

namespace pbr_lod {

/// W×H pixels, row-major from the top-left pixel (the screen convention of camera.hpp).
///   colour  W·H colours; a background pixel holds the background colour it was rendered with
///   depth   W·H eye-space depths (z along the view direction, > 0); +inf for background
struct image {
  int width = 0;
  int height = 0;
  std::vector<rgb8> colour;
  std::vector<float> depth;

  image() = default;
  /// A background-only image of w×h pixels (w, h ≥ 0).
  image(int w, int h, rgb8 background = {})
      : width(w),
        height(h),
        colour(checked_size(w, h), background),
        depth(checked_size(w, h), std::numeric_limits<float>::infinity()) {}

  [[nodiscard]] std::size_t size() const { return colour.size(); }
  [[nodiscard]] std::size_t index(int x, int y) const {
    return static_cast<std::size_t>(y) * static_cast<std::size_t>(width) +
           static_cast<std::size_t>(x);
  }
  /// True when something was drawn at pixel (x, y) (0 ≤ x < width, 0 ≤ y < height).
  [[nodiscard]] bool covered(int x, int y) const {
    return depth[index(x, y)] < std::numeric_limits<float>::infinity();
  }
  [[nodiscard]] bool covered(std::size_t i) const {
    return depth[i] < std::numeric_limits<float>::infinity();
  }
  [[nodiscard]] rgb8 at(int x, int y) const { return colour[index(x, y)]; }
  /// Number of covered pixels.
  [[nodiscard]] std::size_t covered_count() const {
    std::size_t n = 0;
    for (float d : depth) n += d < std::numeric_limits<float>::infinity() ? 1 : 0;
    return n;
  }

  /// Byte-for-byte equality of size, colours and depths (what "same image" means in the tests).
  friend bool operator==(const image&, const image&) = default;

 private:
  static std::size_t checked_size(int w, int h) {
    if (w < 0 || h < 0)
      throw InvalidArgument("image: size must be non-negative, got " + std::to_string(w) + "x" +
                            std::to_string(h));
    return static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
  }
};

/// Box filter of k × k pixels (render_options::supersample): each output colour is the rounded
/// mean of its block, background samples included, so edges come out antialiased; its depth is
/// the nearest covered sample's (+inf when none is). Throws InvalidArgument unless k ≥ 1 divides
/// both sides of `big`.
[[nodiscard]] image downsample_box(const image& big, int k);

}  // namespace pbr_lod
