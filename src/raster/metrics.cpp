// pbr_lod — image metrics (RMSE, PSNR, hole fraction, SSIM) and the Hausdorff distance between
// point sets (exact nearest neighbours through core/knn.hpp).
#include "pbr_lod/raster/metrics.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/core/parallel.hpp"

namespace pbr_lod {

image_error compare_images(const image& reference, const image& test) {
  if (reference.width != test.width || reference.height != test.height)
    throw InvalidArgument("compare_images: reference is " + std::to_string(reference.width) + "x" +
                          std::to_string(reference.height) + " but test is " +
                          std::to_string(test.width) + "x" + std::to_string(test.height));
  const std::size_t n = reference.size();
  if (reference.depth.size() != n || test.colour.size() != n || test.depth.size() != n)
    throw InvalidArgument("compare_images: an image's buffers do not match its size");
  image_error e;
  double sum2 = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool r = reference.covered(i), t = test.covered(i);
    if (r) ++e.reference_covered;
    if (r && !t) ++e.holes;
    if (!r && !t) continue;
    ++e.covered_either;
    const rgb8 a = reference.colour[i], b = test.colour[i];
    const double dr = double(a.r) - b.r, dg = double(a.g) - b.g, db = double(a.b) - b.b;
    sum2 += dr * dr + dg * dg + db * db;
  }
  e.rmse = e.covered_either ? std::sqrt(sum2 / (3.0 * double(e.covered_either))) : 0.0;
  e.psnr = e.rmse > 0 ? 20.0 * std::log10(255.0 / e.rmse) : std::numeric_limits<double>::infinity();
  e.hole_fraction = e.reference_covered ? double(e.holes) / double(e.reference_covered) : 0.0;
  return e;
}

namespace {

/// The pixels of `img` that are covered and have every pixel within Euclidean distance r
/// (inside the frame) covered too: an erosion of the coverage mask by a disk.
std::vector<char> eroded_coverage(const image& img, int r) {
  const int w = img.width, h = img.height;
  std::vector<std::pair<int, int>> disk;
  for (int dy = -r; dy <= r; ++dy)
    for (int dx = -r; dx <= r; ++dx)
      if ((dx != 0 || dy != 0) && dx * dx + dy * dy <= r * r) disk.emplace_back(dx, dy);
  std::vector<char> in(img.size(), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      if (!img.covered(x, y)) continue;
      bool inside = true;
      for (const auto& [dx, dy] : disk) {
        const int xx = x + dx, yy = y + dy;
        if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
        if (!img.covered(xx, yy)) {
          inside = false;
          break;
        }
      }
      in[img.index(x, y)] = inside ? 1 : 0;
    }
  return in;
}

}  // namespace

input_likeness compare_to_input(const image& input_render, const image& test, int inset_px) {
  (void)compare_images(input_render, test);  // the same size and buffer checks
  if (inset_px < 0)
    throw InvalidArgument("compare_to_input: inset_px is " + std::to_string(inset_px) +
                          ", expected >= 0");
  const std::vector<char> interior = eroded_coverage(input_render, inset_px);
  input_likeness l;
  double sum2 = 0;
  std::size_t both = 0, either = 0;
  for (std::size_t i = 0; i < input_render.size(); ++i) {
    const bool r = input_render.covered(i), t = test.covered(i);
    both += (r && t) ? 1 : 0;
    either += (r || t) ? 1 : 0;
    if (!interior[i]) continue;
    ++l.interior_pixels;
    l.interior_holes += t ? 0 : 1;
    const rgb8 a = input_render.colour[i], b = test.colour[i];
    const double dr = double(a.r) - b.r, dg = double(a.g) - b.g, db = double(a.b) - b.b;
    sum2 += dr * dr + dg * dg + db * db;
  }
  const double rmse = l.interior_pixels ? std::sqrt(sum2 / (3.0 * double(l.interior_pixels))) : 0;
  l.psnr_interior =
      rmse > 0 ? 20.0 * std::log10(255.0 / rmse) : std::numeric_limits<double>::infinity();
  l.silhouette_iou = either ? double(both) / double(either) : 1.0;
  return l;
}

namespace {

/// Separable Gaussian blur (σ = 1.5, radius 5) with the weights renormalised where the window
/// leaves the image, so a constant image stays constant up to the border.
std::vector<double> gaussian_blur(const std::vector<double>& in, int w, int h) {
  constexpr int radius = 5;
  double k[2 * radius + 1];
  for (int i = -radius; i <= radius; ++i) k[i + radius] = std::exp(-0.5 * i * i / (1.5 * 1.5));
  const auto pass = [&](const std::vector<double>& src, bool horizontal) {
    std::vector<double> dst(src.size());
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        double sum = 0, wsum = 0;
        for (int i = -radius; i <= radius; ++i) {
          const int xx = horizontal ? x + i : x, yy = horizontal ? y : y + i;
          if (xx < 0 || yy < 0 || xx >= w || yy >= h) continue;
          sum +=
              k[i + radius] * src[static_cast<std::size_t>(yy) * std::size_t(w) + std::size_t(xx)];
          wsum += k[i + radius];
        }
        dst[static_cast<std::size_t>(y) * std::size_t(w) + std::size_t(x)] = sum / wsum;
      }
    return dst;
  };
  return pass(pass(in, true), false);
}

std::vector<double> luminance(const image& img) {
  std::vector<double> y(img.size());
  for (std::size_t i = 0; i < y.size(); ++i)
    y[i] = 0.299 * img.colour[i].r + 0.587 * img.colour[i].g + 0.114 * img.colour[i].b;
  return y;
}

/// max, mean and root mean square over `from` of the distance to the nearest point of `to`.
/// Sums per fixed chunk, added in chunk order: the same result on any number of threads.
one_sided_distance one_sided(std::span<const vec3f> from, const knn_index& to, unsigned threads) {
  constexpr std::size_t chunk = 4096;
  const std::size_t chunks = (from.size() + chunk - 1) / chunk;
  std::vector<one_sided_distance> part(chunks);
  detail::parallel_tasks(chunks, resolve_threads(threads), [&](std::size_t c, unsigned) {
    one_sided_distance& r = part[c];
    const std::size_t end = std::min(from.size(), (c + 1) * chunk);
    for (std::size_t i = c * chunk; i < end; ++i) {
      const double d = to.nearest_distance(from[i]);
      r.max = std::max(r.max, d);
      r.mean += d;
      r.rms += d * d;
    }
  });
  one_sided_distance r;
  for (const auto& p : part) {
    r.max = std::max(r.max, p.max);
    r.mean += p.mean;
    r.rms += p.rms;
  }
  const auto n = static_cast<double>(from.size());
  r.mean /= n;
  r.rms = std::sqrt(r.rms / n);
  return r;
}

hausdorff_result both_sides(std::span<const vec3f> a, const knn_index& index_a,
                            std::span<const vec3f> b, const knn_index& index_b, unsigned threads) {
  const one_sided_distance ab = one_sided(a, index_b, threads);
  const one_sided_distance ba = one_sided(b, index_a, threads);
  return {.a_to_b_max = ab.max,
          .b_to_a_max = ba.max,
          .a_to_b_mean = ab.mean,
          .b_to_a_mean = ba.mean,
          .a_to_b_rms = ab.rms,
          .b_to_a_rms = ba.rms};
}

}  // namespace

double ssim(const image& reference, const image& test) {
  (void)compare_images(reference, test);  // the same size and buffer checks
  const int w = reference.width, h = reference.height;
  const std::vector<double> a = luminance(reference), b = luminance(test);
  std::vector<double> aa(a.size()), bb(a.size()), ab(a.size());
  for (std::size_t i = 0; i < a.size(); ++i) {
    aa[i] = a[i] * a[i];
    bb[i] = b[i] * b[i];
    ab[i] = a[i] * b[i];
  }
  const auto ma = gaussian_blur(a, w, h), mb = gaussian_blur(b, w, h);
  const auto saa = gaussian_blur(aa, w, h), sbb = gaussian_blur(bb, w, h),
             sab = gaussian_blur(ab, w, h);
  constexpr double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  double sum = 0;
  std::size_t n = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (!reference.covered(i) && !test.covered(i)) continue;
    const double va = std::max(0.0, saa[i] - ma[i] * ma[i]);
    const double vb = std::max(0.0, sbb[i] - mb[i] * mb[i]);
    const double cov = sab[i] - ma[i] * mb[i];
    sum += (2 * ma[i] * mb[i] + c1) * (2 * cov + c2) /
           ((ma[i] * ma[i] + mb[i] * mb[i] + c1) * (va + vb + c2));
    ++n;
  }
  return n ? sum / double(n) : 1.0;
}

hausdorff_result hausdorff(const point_cloud& a, const point_cloud& b) {
  if (a.empty() || b.empty())
    throw InvalidArgument(std::string("hausdorff: point cloud ") + (a.empty() ? "a" : "b") +
                          " is empty");
  if (!all_finite(a.origin) || !all_finite(b.origin))
    throw InvalidArgument("hausdorff: a cloud's origin is not finite");
  // b in a's frame: world = b.origin + p, relative to a = (b.origin − a.origin) + p, in double.
  const vec3d shift = b.origin - a.origin;
  std::vector<vec3f> b_in_a(b.size());
  for (std::size_t i = 0; i < b.size(); ++i)
    b_in_a[i] = (b.positions[i].cast<double>() + shift).cast<float>();
  const knn_index index_a(a.positions);  // throws on non-finite positions
  const knn_index index_b(b_in_a);
  return both_sides(a.positions, index_a, b_in_a, index_b, 1);
}

one_sided_distance distance_to(std::span<const vec3f> from, const knn_index& to, unsigned threads) {
  if (from.empty() || to.size() == 0) throw InvalidArgument("distance_to: an empty point set");
  return one_sided(from, to, threads);
}

hausdorff_result hausdorff(std::span<const vec3f> a, const knn_index& index_a,
                           std::span<const vec3f> b, unsigned threads) {
  if (a.empty() || b.empty())
    throw InvalidArgument(std::string("hausdorff: point set ") + (a.empty() ? "a" : "b") +
                          " is empty");
  if (index_a.size() != a.size())
    throw InvalidArgument("hausdorff: the index holds " + std::to_string(index_a.size()) +
                          " points, a has " + std::to_string(a.size()));
  const knn_index index_b(b);  // throws on non-finite positions
  return both_sides(a, index_a, b, index_b, threads);
}

}  // namespace pbr_lod
