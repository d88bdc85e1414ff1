// The CPU reference rasteriser for 3-D Gaussians (raster/gaussians.hpp): 3DGS's pipeline
// (Kerbl et al. 2023 §6) on the CPU — project every Gaussian, sort by view depth, bin to 16×16
// tiles, composite each tile front to back. Every step is deterministic: the projection is per
// Gaussian, the sort has no ties (depth, then arrival index), and a tile is written by one task.
#include "pbr_lod/raster/gaussians.hpp"

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {
namespace detail {
namespace {

// 3DGS's guard band: the mean may lie up to 1.3× the half field of view outside the frustum
// (a Gaussian centred just off screen still covers its edge); the Jacobian is taken no further
// out, because the affine approximation of the projection degrades away from the axis.
constexpr double guard = 1.3;
// computeCov2D's low-pass: 0.3 px² on the diagonal, so every Gaussian covers about a pixel and a
// zero-variance one is a dot rather than a singular conic.
constexpr double low_pass = 0.3;

bool prim_finite(const gaussian_prim& g) {
  bool ok = all_finite(g.position) && std::isfinite(g.opacity);
  for (const float c : g.covariance) ok = ok && std::isfinite(c);
  return ok;
}

/// Σ' = J W Σ Wᵀ Jᵀ + 0.3 I, as (xx, xy, yy), in double: a covariance of 10³⁸ stays finite.
/// J is the Jacobian of the screen map (camera.hpp: x right, y down) at the eye-space mean t,
/// with t.x/t.z and t.y/t.z clamped to the guard band as computeCov2D does.
std::array<double, 3> projected_covariance(const view& v, const vec3f& t,
                                           const std::array<float, 6>& cov) {
  const double z = t.z(), f = v.focal_px;
  const double limx = guard * 0.5 * v.width / f, limy = guard * v.tan_half_fovy;
  const double tx = std::clamp(t.x() / z, -limx, limx) * z;
  const double ty = std::clamp(t.y() / z, -limy, limy) * z;
  // Screen y grows down while eye y grows up: the second row of J is negated.
  const double j0[3] = {f / z, 0, -f * tx / (z * z)};
  const double j1[3] = {0, -f / z, f * ty / (z * z)};
  const vec3f* axes[3] = {&v.right, &v.up, &v.forward};  // the rows of W
  double m0[3], m1[3];                                   // the rows of J W
  for (int k = 0; k < 3; ++k) {
    m0[k] = m1[k] = 0;
    for (int r = 0; r < 3; ++r) {
      m0[k] += j0[r] * (*axes[r])[k];
      m1[k] += j1[r] * (*axes[r])[k];
    }
  }
  const double s[3][3] = {
      {cov[0], cov[1], cov[2]}, {cov[1], cov[3], cov[4]}, {cov[2], cov[4], cov[5]}};
  const auto quad = [&](const double* a, const double* b) {
    double q = 0;
    for (int i = 0; i < 3; ++i)
      for (int k = 0; k < 3; ++k) q += a[i] * s[i][k] * b[k];
    return q;
  };
  return {quad(m0, m0) + low_pass, quad(m0, m1), quad(m1, m1) + low_pass};
}

vec3f view_colour(const gaussian_prim& g, const vec3f& eye) {
  if (!g.sh) return vec3f::Constant(0.5f);  // no coefficients: all zero, 3DGS's grey
  return sh_colour(g.sh, g.sh_degree, (g.position - eye).normalized());
}

/// The pixel and tile box outside which α < 1/255; false when it misses the screen. The exact
/// extent of the ellipse dᵀ Σ'⁻¹ d ≤ k² along x is k √Σ'xx; the relative and absolute margins
/// cover the rounding of the float conic the pixels are tested with.
bool screen_box(const view& v, gaussian_2d& s, const std::array<double, 3>& cov) {
  // ≥ 0: opacity ≥ 1/255 in float may still give 255·opacity a hair below 1.
  const double k2 = std::max(0.0, 2 * std::log(255.0 * s.opacity));
  const double ex = std::sqrt(k2 * cov[0]) * 1.001 + 0.5;
  const double ey = std::sqrt(k2 * cov[2]) * 1.001 + 0.5;
  // Pixel i's centre is i + ½; clamp in double before converting, the box may be 10³⁰ wide.
  const auto range = [](double c, double e, int n, int& lo, int& hi) {
    lo = static_cast<int>(std::ceil(std::clamp(c - e - 0.5, -1.0, double(n))));
    hi = static_cast<int>(std::floor(std::clamp(c + e - 0.5, -1.0, double(n))));
    lo = std::max(lo, 0);
    hi = std::min(hi, n - 1);
    return lo <= hi;
  };
  if (!range(s.x, ex, v.width, s.px0, s.px1) || !range(s.y, ey, v.height, s.py0, s.py1))
    return false;
  s.tx0 = s.px0 / gaussian_tile;
  s.tx1 = s.px1 / gaussian_tile;
  s.ty0 = s.py0 / gaussian_tile;
  s.ty1 = s.py1 / gaussian_tile;
  s.min_power = static_cast<float>(-0.5 * k2 - 1e-3 * (1 + 0.5 * k2));
  return true;
}

}  // namespace

gaussian_2d project_gaussian(const view& v, const gaussian_prim& g) {
  gaussian_2d s;
  s.status = gaussian_2d::fate::invalid;
  if (!prim_finite(g) || g.sh_degree < 0 || g.sh_degree > max_sh_degree) return s;
  s.status = gaussian_2d::fate::culled;
  const vec3f t = v.to_eye(g.position);
  // Near plane first: it also removes a mean at or behind the eye, where the Jacobian blows up.
  if (!(t.z() > v.z_near)) return s;
  const float limx = static_cast<float>(guard) * 0.5f * float(v.width) / v.focal_px;
  const float limy = static_cast<float>(guard) * v.tan_half_fovy;
  if (std::abs(t.x()) > limx * t.z() || std::abs(t.y()) > limy * t.z()) return s;
  if (!(g.opacity >= gaussian_min_alpha)) return s;  // α ≤ opacity: no pixel reaches 1/255

  s.status = gaussian_2d::fate::invalid;
  const std::array<double, 3> cov = projected_covariance(v, t, g.covariance);
  const double det = cov[0] * cov[2] - cov[1] * cov[1];
  if (!(det > 0) || !(cov[0] > 0) || !std::isfinite(det))
    return s;  // Σ not positive (semi)definite
  const vec3f rgb = view_colour(g, v.eye);
  if (!all_finite(rgb)) return s;

  const vec2f xy = v.eye_to_screen(t);
  s.x = xy.x();
  s.y = xy.y();
  s.a = static_cast<float>(cov[2] / det);
  s.b = static_cast<float>(-cov[1] / det);
  s.c = static_cast<float>(cov[0] / det);
  s.opacity = g.opacity;
  s.depth = t.z();
  s.rgb = {rgb.x(), rgb.y(), rgb.z()};
  s.status = screen_box(v, s, cov) ? gaussian_2d::fate::drawn : gaussian_2d::fate::culled;
  return s;
}

}  // namespace detail

namespace {

using detail::gaussian_2d;
using detail::gaussian_tile;

/// Tile t's Gaussians, front to back: ids[offsets[t], offsets[t + 1]).
struct tile_bins {
  int tiles_x = 0, tiles_y = 0;
  std::vector<std::size_t> offsets;
  std::vector<std::uint32_t> ids;
};

/// The drawn Gaussians by view depth, ties by arrival index. Depths are > 0, where a float's
/// bits order as unsigned integers, so one 64-bit key per Gaussian sorts both at once.
std::vector<std::uint32_t> depth_order(const std::vector<gaussian_2d>& s) {
  std::vector<std::uint64_t> keys;
  keys.reserve(s.size());
  for (std::size_t i = 0; i < s.size(); ++i)
    if (s[i].status == gaussian_2d::fate::drawn)
      keys.push_back(std::uint64_t(std::bit_cast<std::uint32_t>(s[i].depth)) << 32 | i);
  std::sort(keys.begin(), keys.end());
  std::vector<std::uint32_t> order(keys.size());
  for (std::size_t i = 0; i < keys.size(); ++i) order[i] = static_cast<std::uint32_t>(keys[i]);
  return order;
}

/// A counting sort of (tile, Gaussian) pairs, filled in depth order: each tile's list comes out
/// sorted, as 3DGS's radix sort of (tile, depth) keys gives it. 4 bytes per pair.
tile_bins bin_to_tiles(const view& v, const std::vector<gaussian_2d>& s,
                       const std::vector<std::uint32_t>& order) {
  tile_bins b;
  b.tiles_x = (v.width + gaussian_tile - 1) / gaussian_tile;
  b.tiles_y = (v.height + gaussian_tile - 1) / gaussian_tile;
  const auto each_tile = [&](const gaussian_2d& g, auto&& f) {
    for (int ty = g.ty0; ty <= g.ty1; ++ty)
      for (int tx = g.tx0; tx <= g.tx1; ++tx) f(std::size_t(ty) * std::size_t(b.tiles_x) + tx);
  };
  b.offsets.assign(std::size_t(b.tiles_x) * std::size_t(b.tiles_y) + 1, 0);
  for (const std::uint32_t i : order) each_tile(s[i], [&](std::size_t t) { ++b.offsets[t + 1]; });
  for (std::size_t t = 1; t < b.offsets.size(); ++t) b.offsets[t] += b.offsets[t - 1];
  b.ids.resize(b.offsets.back());
  std::vector<std::size_t> fill(b.offsets.begin(), b.offsets.end() - 1);
  for (const std::uint32_t i : order) each_tile(s[i], [&](std::size_t t) { b.ids[fill[t]++] = i; });
  return b;
}

/// One tile's pixels, composited as renderCUDA does per pixel. Gaussians run in the outer loop
/// so a tile stops as soon as every pixel is saturated, and each Gaussian visits only the
/// pixels of its box; per pixel the operations and their order are those of a loop over all
/// Gaussians (what the tests' brute force does).
class tile_compositor {
 public:
  tile_compositor(int x0, int y0, int w, int h) : x0_(x0), y0_(y0), w_(w), h_(h), active_(w * h) {
    std::fill_n(t_, w * h, 1.0f);
    std::fill_n(depth_, w * h, std::numeric_limits<float>::infinity());
  }

  /// False once every pixel of the tile is done.
  bool add(const gaussian_2d& s) {
    const int ya = std::max(s.py0, y0_), yb = std::min(s.py1, y0_ + h_ - 1);
    const int xa = std::max(s.px0, x0_), xb = std::min(s.px1, x0_ + w_ - 1);
    for (int y = ya; y <= yb; ++y)
      for (int x = xa; x <= xb; ++x) pixel(s, x, y);
    return active_ > 0;
  }

  void write(image& img, const vec3f& background) const {
    for (int j = 0; j < h_; ++j)
      for (int i = 0; i < w_; ++i) {
        const int p = j * w_ + i;
        const std::size_t o = img.index(x0_ + i, y0_ + j);
        const auto q = [&](int ch) {
          const float v = c_[ch][p] + t_[p] * background[ch];
          return static_cast<std::uint8_t>(std::lround(std::clamp(v, 0.0f, 1.0f) * 255.0f));
        };
        img.colour[o] = rgb8{q(0), q(1), q(2)};
        img.depth[o] = depth_[p];
      }
  }

 private:
  void pixel(const gaussian_2d& s, int x, int y) {
    const int p = (y - y0_) * w_ + (x - x0_);
    if (done_[p]) return;
    const float px = float(x) + 0.5f, py = float(y) + 0.5f;
    const float dx = s.x - px, dy = s.y - py;
    if (-0.5f * (s.a * dx * dx + s.c * dy * dy) - s.b * dx * dy < s.min_power) return;
    const float alpha = detail::gaussian_alpha(s, px, py);
    if (alpha < detail::gaussian_min_alpha) return;
    const float t = t_[p], test_t = t * (1 - alpha);
    if (test_t < detail::gaussian_min_transmittance) {  // renderCUDA: done, not added
      done_[p] = true;
      --active_;
      return;
    }
    for (int ch = 0; ch < 3; ++ch) c_[ch][p] += s.rgb[ch] * alpha * t;
    if (t >= 0.5f && test_t < 0.5f) depth_[p] = s.depth;  // the median depth
    t_[p] = test_t;
  }

  static constexpr int n = gaussian_tile * gaussian_tile;
  int x0_, y0_, w_, h_, active_;
  float t_[n];
  float c_[3][n] = {};
  float depth_[n];
  bool done_[n] = {};
};

}  // namespace

gaussian_rasterizer::gaussian_rasterizer(const view& v, const gaussian_render_options& options)
    : view_(v), options_(options) {}

gaussian_raster_stats gaussian_rasterizer::stats() const {
  gaussian_raster_stats s = last_;
  s.ignored = ignored_;
  return s;
}

image gaussian_rasterizer::finish() {
  if (prims_.size() >= std::numeric_limits<std::uint32_t>::max())
    throw InvalidArgument("gaussian_rasterizer: " + std::to_string(prims_.size()) +
                          " Gaussians in one frame (at most 2^32 - 1)");
  const unsigned threads = resolve_threads(options_.threads);
  std::vector<gaussian_2d> s(prims_.size());
  detail::parallel_pieces(s.size(), threads, 8 * std::size_t(threads), 4096,
                          [&](std::size_t lo, std::size_t hi) {
                            for (std::size_t i = lo; i < hi; ++i)
                              s[i] = detail::project_gaussian(view_, prims_[i]);
                          });
  last_ = {};
  last_.received = s.size();
  for (const gaussian_2d& g : s) {
    last_.drawn += g.status == gaussian_2d::fate::drawn;
    last_.culled += g.status == gaussian_2d::fate::culled;
    last_.invalid += g.status == gaussian_2d::fate::invalid;
  }
  prims_.clear();

  const tile_bins bins = bin_to_tiles(view_, s, depth_order(s));
  const rgb8 bg8 = options_.background;
  const vec3f bg = vec3f(bg8.r, bg8.g, bg8.b) / 255.0f;
  image img(view_.width, view_.height, bg8);
  detail::parallel_tasks(bins.offsets.size() - 1, threads, [&](std::size_t t, unsigned) {
    const int x0 = int(t % std::size_t(bins.tiles_x)) * gaussian_tile;
    const int y0 = int(t / std::size_t(bins.tiles_x)) * gaussian_tile;
    tile_compositor tile(x0, y0, std::min(gaussian_tile, view_.width - x0),
                         std::min(gaussian_tile, view_.height - y0));
    for (std::size_t k = bins.offsets[t]; k < bins.offsets[t + 1]; ++k)
      if (!tile.add(s[bins.ids[k]])) break;
    tile.write(img, bg);
  });
  return img;
}

image render_gaussians(const gaussian_cloud& cloud, const camera& cam,
                       const gaussian_render_options& options) {
  const std::size_t n = cloud.size();
  if (cloud.sh_degree < 0 || cloud.sh_degree > max_sh_degree || cloud.scales.size() != n ||
      cloud.rotations.size() != n || cloud.opacities.size() != n ||
      cloud.sh.size() != n * cloud.sh_stride())
    throw InvalidArgument(
        "render_gaussians: the cloud's arrays disagree in length or its sh_degree is not 0-3 "
        "(gaussian_cloud::validate() says which)");
  gaussian_rasterizer r(view(cam, cloud.origin), options);
  for (std::size_t i = 0; i < n; ++i)
    r.gaussian({.position = cloud.positions[i],
                .covariance = gaussian_covariance(cloud.scales[i], cloud.rotations[i]),
                .opacity = cloud.opacities[i],
                .sh_degree = cloud.sh_degree,
                .sh = cloud.sh.data() + i * cloud.sh_stride()});
  return r.finish();
}

}  // namespace pbr_lod
