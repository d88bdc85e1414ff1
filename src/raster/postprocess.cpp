// pbr_lod — whole-frame passes of the reference rasteriser: shadow resolve (second pass of a
// two-pass shadow map, Williams 1978), screen-space hole filling (Pfister et al. 2000 visibility
// splatting + reconstruction; Chen & Nguyen 2001 §3.4 uniform filter), depth conversion, the
// supersampling box filter.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "pbr_lod/raster/detail/postprocess.hpp"
#include "pbr_lod/raster/detail/raster_core.hpp"
#include "pbr_lod/raster/detail/shadow_map.hpp"
#include "pbr_lod/raster/image.hpp"

namespace pbr_lod::detail {

void resolve_shadows(const view& v, const shadow_map* sm, float ambient, std::span<const float> key,
                     float key_far, std::span<rgb8> colour, std::span<const float> lit) {
  const bool have_map = sm != nullptr && !sm->empty();
  const int w = v.width, h = v.height;
  const float cx = 0.5f * static_cast<float>(w), cy = 0.5f * static_cast<float>(h);
  const float inv_f = 1.0f / v.focal_px;
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const std::size_t i =
          static_cast<std::size_t>(y) * static_cast<std::size_t>(w) + static_cast<std::size_t>(x);
      const float k = key[i];
      if (!(k > key_far)) continue;
      float f = lit.empty() ? 1.0f : lit[i];
      if (have_map) {
        // The surface point seen through the pixel centre, back from its depth.
        const float z = 1.0f / k;
        const float ex = (static_cast<float>(x) + 0.5f - cx) * z * inv_f;
        const float ey = (cy - (static_cast<float>(y) + 0.5f)) * z * inv_f;
        const vec3f p = v.eye + v.right * ex + v.up * ey + v.forward * z;
        const ortho_projection& lp = sm->proj;
        const vec3f e = lp.frame(p);
        const float tx = lp.cx + lp.scale * e.x(), ty = lp.cy - lp.scale * e.y();
        if (tx >= 0 && tx < static_cast<float>(lp.width) && ty >= 0 &&
            ty < static_cast<float>(lp.height)) {
          const std::size_t t =
              static_cast<std::size_t>(static_cast<int>(ty)) * static_cast<std::size_t>(lp.width) +
              static_cast<std::size_t>(static_cast<int>(tx));
          // Caster depth −key; the receiver is at e.z. Shadowed when a caster is nearer the light
          // by more than the bias.
          if (-sm->key[t] < e.z() - sm->bias) f = ambient;
        }
      }
      colour[i] = scale_colour(colour[i], f);
    }
  }
}

namespace {

/// Sector (0..7, 45° each, counter-clockwise from +x in (dx, dy)) of a non-zero offset.
/// Half-open sectors: each offset belongs to exactly one.
int sector_of(int dx, int dy) {
  if (dy >= 0 && dx > 0) return dy < dx ? 0 : 1;
  if (dx <= 0 && dy > 0) return -dx < dy ? 2 : 3;
  if (dy <= 0 && dx < 0) return -dy < -dx ? 4 : 5;
  return dx < -dy ? 6 : 7;  // dx >= 0 && dy < 0
}

struct offset {
  int dx, dy;
  std::uint8_t sector_bit;
};

}  // namespace

void fill_holes(int width, int height, std::vector<float>& key, std::vector<rgb8>& colour,
                float key_far, const render_options& opt) {
  const int r = opt.hole_filling_radius;
  if (r <= 0 || width <= 0 || height <= 0) return;
  const int min_sectors = std::clamp(opt.hole_filling_min_sectors, 1, 8);
  const float tol = std::isfinite(opt.hole_filling_depth_tolerance)
                        ? std::max(opt.hole_filling_depth_tolerance, 0.0f)
                        : 0.0f;
  const std::size_t W = static_cast<std::size_t>(width), H = static_cast<std::size_t>(height);

  // Disk of offsets (dx² + dy² ≤ r²) with their sector: a disk keeps the filter isotropic.
  std::vector<offset> disk;
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx)
      if ((dx != 0 || dy != 0) && dx * dx + dy * dy <= r * r)
        disk.push_back({dx, dy, static_cast<std::uint8_t>(1u << sector_of(dx, dy))});

  // Summed-area table of coverage: most background pixels have no covered pixel within r and
  // are skipped in O(1).
  std::vector<std::uint32_t> sat((W + 1) * (H + 1), 0);
  for (std::size_t y = 0; y < H; ++y) {
    std::uint32_t run = 0;
    for (std::size_t x = 0; x < W; ++x) {
      run += key[y * W + x] > key_far ? 1u : 0u;
      sat[(y + 1) * (W + 1) + x + 1] = sat[y * (W + 1) + x + 1] + run;
    }
  }
  const auto box_count = [&](int x0, int y0, int x1, int y1) {  // inclusive, clamped
    const std::size_t a = static_cast<std::size_t>(std::max(x0, 0));
    const std::size_t b = static_cast<std::size_t>(std::max(y0, 0));
    const std::size_t c = static_cast<std::size_t>(std::min(x1, width - 1)) + 1;
    const std::size_t d = static_cast<std::size_t>(std::min(y1, height - 1)) + 1;
    return sat[d * (W + 1) + c] - sat[b * (W + 1) + c] - sat[d * (W + 1) + a] +
           sat[b * (W + 1) + a];
  };

  // Read from the unfilled frame, write to copies: order-independent and no cascade.
  std::vector<float> out_key = key;
  std::vector<rgb8> out_colour = colour;
  for (int y = 0; y < height; ++y) {
    for (int x = 0; x < width; ++x) {
      const std::size_t i = static_cast<std::size_t>(y) * W + static_cast<std::size_t>(x);
      if (key[i] > key_far) continue;  // covered
      if (box_count(x - r, y - r, x + r, y + r) == 0) continue;
      // Front-most neighbour (largest key = smallest depth).
      float kmax = key_far;
      for (const offset& o : disk) {
        const int nx = x + o.dx, ny = y + o.dy;
        if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
        kmax = std::max(kmax, key[static_cast<std::size_t>(ny) * W + static_cast<std::size_t>(nx)]);
      }
      if (!(kmax > key_far)) continue;
      // z ≤ z_front·(1 + tol)  ⟺  key ≥ key_front / (1 + tol)
      const float kmin = kmax / (1 + tol);
      unsigned sectors = 0, n = 0, sr = 0, sg = 0, sb = 0;
      for (const offset& o : disk) {
        const int nx = x + o.dx, ny = y + o.dy;
        if (nx < 0 || ny < 0 || nx >= width || ny >= height) continue;
        const std::size_t j = static_cast<std::size_t>(ny) * W + static_cast<std::size_t>(nx);
        const float k = key[j];
        if (!(k > key_far) || k < kmin) continue;
        sectors |= o.sector_bit;
        ++n;
        sr += colour[j].r;
        sg += colour[j].g;
        sb += colour[j].b;
      }
      if (std::popcount(sectors) < min_sectors) continue;
      out_key[i] = kmax;
      out_colour[i] = {static_cast<std::uint8_t>((sr + n / 2) / n),
                       static_cast<std::uint8_t>((sg + n / 2) / n),
                       static_cast<std::uint8_t>((sb + n / 2) / n)};
    }
  }
  key.swap(out_key);
  colour.swap(out_colour);
}

std::vector<float> keys_to_depth(std::span<const float> key, float key_far) {
  std::vector<float> depth(key.size());
  for (std::size_t i = 0; i < key.size(); ++i)
    depth[i] = key[i] > key_far ? 1.0f / key[i] : std::numeric_limits<float>::infinity();
  return depth;
}

}  // namespace pbr_lod::detail

namespace pbr_lod {

image downsample_box(const image& big, int k) {
  if (k < 1 || big.width % k != 0 || big.height % k != 0)
    throw InvalidArgument("downsample_box: factor " + std::to_string(k) + " for " +
                          std::to_string(big.width) + "x" + std::to_string(big.height) +
                          " pixels (expected k >= 1 dividing both sides)");
  image small(big.width / k, big.height / k);
  const auto n = static_cast<std::uint64_t>(k) * static_cast<std::uint64_t>(k);
  for (int y = 0; y < small.height; ++y) {
    for (int x = 0; x < small.width; ++x) {
      std::uint64_t r = 0, g = 0, b = 0;
      float depth = std::numeric_limits<float>::infinity();
      for (int j = 0; j < k; ++j) {
        const std::size_t row = big.index(x * k, y * k + j);
        for (std::size_t i = row; i < row + static_cast<std::size_t>(k); ++i) {
          r += big.colour[i].r;
          g += big.colour[i].g;
          b += big.colour[i].b;
          depth = std::min(depth, big.depth[i]);
        }
      }
      const std::size_t s = small.index(x, y);
      small.colour[s] = {static_cast<std::uint8_t>((r + n / 2) / n),
                         static_cast<std::uint8_t>((g + n / 2) / n),
                         static_cast<std::uint8_t>((b + n / 2) / n)};
      small.depth[s] = depth;
    }
  }
  return small;
}

}  // namespace pbr_lod
