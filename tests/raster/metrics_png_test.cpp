// Image metrics, Hausdorff distance and PNG files.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "pbr_lod/core/error.hpp"
#include "pbr_lod/core/knn.hpp"
#include "pbr_lod/io/texture.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/png.hpp"

namespace pbr_lod {
namespace {

/// What a tool reads back from a PNG it wrote: io reads the file, raster makes the image.
image read_png_image(const std::string& path) {
  return image_from_texture(read_png_texture(path));
}

constexpr float kInf = std::numeric_limits<float>::infinity();

image uniform(int w, int h, rgb8 c) {
  image img(w, h);
  for (std::size_t i = 0; i < img.size(); ++i) {
    img.colour[i] = c;
    img.depth[i] = 1;
  }
  return img;
}

// Comparing an image with itself: no error, infinite PSNR, no holes.
TEST(Metrics, IdenticalImages) {
  image a = uniform(8, 6, {10, 200, 30});
  a.depth[5] = kInf;  // some background too
  const image_error e = compare_images(a, a);
  EXPECT_EQ(e.rmse, 0);
  EXPECT_TRUE(std::isinf(e.psnr) && e.psnr > 0);
  EXPECT_EQ(e.holes, 0u);
  EXPECT_EQ(e.hole_fraction, 0);
  EXPECT_EQ(e.covered_either, 47u);
  EXPECT_EQ(e.reference_covered, 47u);
}

// Four covered reference pixels of grey 100; the test differs by 10 in one channel of one pixel
// and has a hole (background 0,0,0) at another: squared error 10² + 3·100² = 30100 over
// 4 pixels × 3 channels → RMSE = sqrt(30100/12) = 50.083, PSNR = 20·log10(255/50.083) = 14.137 dB;
// 1 hole of 4 reference pixels. An extra covered pixel only in the test (the 5th, equal to its
// reference background colour) counts in covered_either but adds no error and no hole.
TEST(Metrics, KnownDifferences) {
  image ref(5, 1, {0, 0, 0}), test(5, 1, {0, 0, 0});
  for (int x = 0; x < 4; ++x) {
    ref.colour[std::size_t(x)] = {100, 100, 100};
    ref.depth[std::size_t(x)] = 1;
    test.colour[std::size_t(x)] = {100, 100, 100};
    test.depth[std::size_t(x)] = 1;
  }
  test.colour[1] = {110, 100, 100};
  test.colour[2] = {0, 0, 0};
  test.depth[2] = kInf;
  test.depth[4] = 2;  // covered in the test only, colour = the reference's background
  const image_error e = compare_images(ref, test);
  EXPECT_EQ(e.covered_either, 5u);
  EXPECT_EQ(e.reference_covered, 4u);
  EXPECT_EQ(e.holes, 1u);
  EXPECT_DOUBLE_EQ(e.hole_fraction, 0.25);
  EXPECT_NEAR(e.rmse, std::sqrt(30100.0 / 15.0), 1e-12);  // 5 pixels covered in either
  EXPECT_NEAR(e.psnr, 20 * std::log10(255 / std::sqrt(30100.0 / 15.0)), 1e-9);
  // Without the extra pixel: exactly the numbers of the comment.
  test.depth[4] = kInf;
  const image_error f = compare_images(ref, test);
  EXPECT_NEAR(f.rmse, 50.0832640, 1e-6);
  EXPECT_NEAR(f.psnr, 14.136951, 1e-5);
}

// compare_to_input on a 9×9 frame whose input render covers the 7×7 square x, y ∈ [1, 7]:
// with inset 2 the interior is the pixels whose disk of radius 2 stays covered — the 3×3 square
// x, y ∈ [3, 5] (a pixel at x = 2 has x = 0 within distance 2). Inset 0 keeps all 49.
TEST(Metrics, CompareToInputInteriorAndIou) {
  image input(9, 9, {0, 0, 0});
  for (int y = 1; y <= 7; ++y)
    for (int x = 1; x <= 7; ++x) {
      input.colour[input.index(x, y)] = {100, 100, 100};
      input.depth[input.index(x, y)] = 1;
    }
  image test = input;
  // A wrong colour on the silhouette (x = 1) is outside the interior: no interior error.
  test.colour[test.index(1, 4)] = {0, 255, 0};
  // A hole at the centre: the one interior pixel that differs, by 100 in each channel.
  test.depth[test.index(4, 4)] = kInf;
  test.colour[test.index(4, 4)] = {0, 0, 0};
  // Two covered pixels outside the input's silhouette.
  test.depth[test.index(0, 0)] = 1;
  test.depth[test.index(8, 8)] = 1;
  const input_likeness l = compare_to_input(input, test);
  EXPECT_EQ(l.interior_pixels, 9u);
  EXPECT_EQ(l.interior_holes, 1u);
  // RMSE = sqrt(3·100² / (9·3)) = 100/3; PSNR = 20·log10(255·3/100).
  EXPECT_NEAR(l.psnr_interior, 20 * std::log10(7.65), 1e-9);
  // both: 49 − 1 (the hole) = 48; either: 49 + 2 = 51.
  EXPECT_DOUBLE_EQ(l.silhouette_iou, 48.0 / 51.0);
  EXPECT_EQ(compare_to_input(input, test, 0).interior_pixels, 49u);
  EXPECT_EQ(compare_to_input(input, input, 0).psnr_interior,
            std::numeric_limits<double>::infinity());
  EXPECT_THROW((void)compare_to_input(input, test, -1), InvalidArgument);
  EXPECT_THROW((void)compare_to_input(input, image(8, 9)), InvalidArgument);
}

// A model that fills the frame: the frame's edge is not its silhouette, so every pixel is
// interior; an empty input render has no interior and an IoU of 1 against an empty test.
TEST(Metrics, CompareToInputFrameEdgeAndEmpty) {
  const image full = uniform(6, 5, {7, 8, 9});
  EXPECT_EQ(compare_to_input(full, full).interior_pixels, 30u);
  const image empty(6, 5);
  const input_likeness l = compare_to_input(empty, empty);
  EXPECT_EQ(l.interior_pixels, 0u);
  EXPECT_EQ(l.silhouette_iou, 1.0);
  EXPECT_EQ(compare_to_input(empty, full).silhouette_iou, 0.0);
}

// SSIM: 1 for identical images; for two uniform greys a and b (no structure, σ = 0) eq. 13
// reduces to (2ab + C1) / (a² + b² + C1), worked out by hand for 100 vs 120.
TEST(Metrics, SsimIdenticalAndUniform) {
  std::mt19937 rng(3);
  image a(24, 20);
  for (std::size_t i = 0; i < a.size(); ++i) {
    a.colour[i] = {static_cast<std::uint8_t>(rng() & 255), static_cast<std::uint8_t>(rng() & 255),
                   static_cast<std::uint8_t>(rng() & 255)};
    a.depth[i] = 1;
  }
  EXPECT_NEAR(ssim(a, a), 1.0, 1e-12);
  EXPECT_NEAR(ssim(uniform(16, 16, {100, 100, 100}), uniform(16, 16, {120, 120, 120})),
              0.9836109249983688, 1e-9);
}

// Structure counts: a checkerboard against its inverse has the same local means but covariance
// −σ², so SSIM ≈ −1; noise added to an image lowers SSIM, more noise lowers it more.
TEST(Metrics, SsimStructureAndNoise) {
  image board(32, 32), inverse(32, 32);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const std::uint8_t v = ((x + y) & 1) ? 255 : 0;
      board.colour[board.index(x, y)] = {v, v, v};
      inverse.colour[inverse.index(x, y)] = {static_cast<std::uint8_t>(255 - v),
                                             static_cast<std::uint8_t>(255 - v),
                                             static_cast<std::uint8_t>(255 - v)};
      board.depth[board.index(x, y)] = inverse.depth[inverse.index(x, y)] = 1;
    }
  EXPECT_LT(ssim(board, inverse), -0.9);
  image smooth(32, 32);
  for (int y = 0; y < 32; ++y)
    for (int x = 0; x < 32; ++x) {
      const auto v = static_cast<std::uint8_t>(4 * x + 2 * y);
      smooth.colour[smooth.index(x, y)] = {v, v, v};
      smooth.depth[smooth.index(x, y)] = 1;
    }
  const auto noisy = [&](int amplitude) {
    image n = smooth;
    std::mt19937 rng(7);
    for (auto& c : n.colour) {
      const int d = static_cast<int>(rng() % (2 * amplitude + 1)) - amplitude;
      const auto v = static_cast<std::uint8_t>(std::clamp(c.r + d, 0, 255));
      c = {v, v, v};
    }
    return n;
  };
  const double s4 = ssim(smooth, noisy(4)), s32 = ssim(smooth, noisy(32));
  EXPECT_LT(s4, 1.0);
  EXPECT_LT(s32, s4 - 0.1);
}

// Pixels background in both images do not take part: a frame with one covered block compares
// like the block alone.
TEST(Metrics, SsimIgnoresCommonBackground) {
  image a(40, 40), b(40, 40);
  for (int y = 10; y < 30; ++y)
    for (int x = 10; x < 30; ++x) {
      a.colour[a.index(x, y)] = {100, 100, 100};
      b.colour[b.index(x, y)] = {120, 120, 120};
      a.depth[a.index(x, y)] = b.depth[b.index(x, y)] = 1;
    }
  // With the black background inside the windows near the block's edge the value differs from
  // the uniform case, but it stays below 1 and the background itself adds no 1s.
  const double s = ssim(a, b);
  EXPECT_LT(s, 0.99);
  EXPECT_GT(s, 0.9);
  image a0 = a, b0 = b;
  for (std::size_t i = 0; i < a0.size(); ++i) a0.depth[i] = b0.depth[i] = 1;  // all covered
  EXPECT_GT(ssim(a0, b0), s);  // the equal background now counts as perfect pixels
}

/// SSIM as metrics.hpp defines it, written out the slow way: for each pixel covered in either
/// image, the 11×11 Gaussian window (σ = 1.5) over the pixels inside the image, weights
/// renormalised to sum 1, the local means, variances and covariance of the luminance
/// Y = 0.299 R + 0.587 G + 0.114 B, and eq. 13 with C1 = (0.01·255)², C2 = (0.03·255)².
double brute_force_ssim(const image& a, const image& b) {
  const auto lum = [](const image& img, int x, int y) {
    const rgb8 c = img.at(x, y);
    return 0.299 * c.r + 0.587 * c.g + 0.114 * c.b;
  };
  const double c1 = (0.01 * 255) * (0.01 * 255), c2 = (0.03 * 255) * (0.03 * 255);
  double sum = 0;
  std::size_t n = 0;
  for (int y = 0; y < a.height; ++y)
    for (int x = 0; x < a.width; ++x) {
      if (!a.covered(x, y) && !b.covered(x, y)) continue;
      double w = 0, ma = 0, mb = 0, saa = 0, sbb = 0, sab = 0;
      for (int j = -5; j <= 5; ++j)
        for (int i = -5; i <= 5; ++i) {
          const int xx = x + i, yy = y + j;
          if (xx < 0 || yy < 0 || xx >= a.width || yy >= a.height) continue;
          const double k = std::exp(-0.5 * (i * i + j * j) / (1.5 * 1.5));
          const double p = lum(a, xx, yy), q = lum(b, xx, yy);
          w += k;
          ma += k * p;
          mb += k * q;
          saa += k * p * p;
          sbb += k * q * q;
          sab += k * p * q;
        }
      ma /= w, mb /= w, saa /= w, sbb /= w, sab /= w;
      const double va = saa - ma * ma, vb = sbb - mb * mb, cov = sab - ma * mb;
      sum += (2 * ma * mb + c1) * (2 * cov + c2) / ((ma * ma + mb * mb + c1) * (va + vb + c2));
      ++n;
    }
  return n ? sum / double(n) : 1.0;
}

// Against the slow definition: coloured (not grey) random images, so the luminance weights
// count, partly background so the covered-in-either rule counts, one of them a blurred and
// shifted copy of the other so the covariance term is neither ±1 nor 0, on a frame smaller than
// two windows so the border renormalisation counts. The tests above use grey or uniform images
// only, which a wrong luminance weight, window width or C2 passes.
TEST(Metrics, SsimMatchesBruteForce) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> byte(0, 255), coin(0, 4);
  for (const auto& [w, h] : {std::pair{19, 17}, std::pair{40, 9}}) {
    image a(w, h, {5, 6, 7}), b(w, h, {9, 8, 7});
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (coin(rng) == 0) continue;  // background in a
        a.colour[a.index(x, y)] = {std::uint8_t(byte(rng)), std::uint8_t(byte(rng) / 2),
                                   std::uint8_t(255 - byte(rng) / 4)};
        a.depth[a.index(x, y)] = 1;
      }
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (coin(rng) == 0) continue;  // background in b
        // A shifted average of a's red and blue with noise in green: correlated, not equal.
        const rgb8 p = a.at(std::min(x + 1, w - 1), y), q = a.at(x, std::max(y - 1, 0));
        b.colour[b.index(x, y)] = {std::uint8_t((p.r + q.r) / 2), std::uint8_t(byte(rng)),
                                   std::uint8_t((p.b + q.b) / 2)};
        b.depth[b.index(x, y)] = 2;
      }
    const double want = brute_force_ssim(a, b);
    EXPECT_GT(want, 0.01) << w << "x" << h;  // a correlated pair: not 0, far from 1
    EXPECT_LT(want, 0.9) << w << "x" << h;
    EXPECT_NEAR(ssim(a, b), want, 1e-9) << w << "x" << h;
    EXPECT_NEAR(ssim(b, a), brute_force_ssim(b, a), 1e-9) << w << "x" << h;
  }
}

TEST(Metrics, SizeMismatchThrows) {
  EXPECT_THROW((void)compare_images(image(3, 2), image(2, 3)), InvalidArgument);
}

point_cloud grid_cloud(const vec3d& origin) {
  point_cloud c;
  c.origin = origin;
  for (int k = 0; k < 6; ++k)
    for (int j = 0; j < 6; ++j)
      for (int i = 0; i < 6; ++i) c.positions.emplace_back(0.1f * i, 0.1f * j, 0.1f * k);
  return c;
}

// A cloud against itself: 0. Against a copy translated by t with |t| < half the spacing h: the
// nearest point of every point is its own translate (any other is ≥ h − |t| > |t| away), so
// every distance, hence max and mean, is |t|.
TEST(Metrics, HausdorffSelfAndTranslated) {
  const point_cloud a = grid_cloud(vec3d::Zero());
  const hausdorff_result self = hausdorff(a, a);
  EXPECT_EQ(self.symmetric(), 0);
  EXPECT_EQ(self.a_to_b_mean, 0);
  point_cloud b = a;
  const vec3f t(0.02f, 0.01f, -0.015f);
  for (auto& p : b.positions) p += t;
  const hausdorff_result h = hausdorff(a, b);
  EXPECT_NEAR(h.a_to_b_max, t.norm(), 1e-6);
  EXPECT_NEAR(h.b_to_a_max, t.norm(), 1e-6);
  EXPECT_NEAR(h.a_to_b_mean, t.norm(), 1e-6);
  EXPECT_NEAR(h.symmetric(), t.norm(), 1e-6);
  EXPECT_NEAR(h.b_to_a_mean, t.norm(), 1e-6);
}

// Distances that differ from point to point, so max and mean are different numbers and the two
// directions differ: b is a jittered, thinned copy of a plus one far outlier. Checked against a
// brute-force nearest neighbour over all pairs (216 × ~110 points).
TEST(Metrics, HausdorffWithAnOutlierMatchesBruteForce) {
  const point_cloud a = grid_cloud(vec3d::Zero());
  point_cloud b;
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> jitter(-0.03f, 0.03f);
  for (std::size_t i = 0; i < a.size(); i += 2)
    b.positions.push_back(a.positions[i] + vec3f(jitter(rng), jitter(rng), jitter(rng)));
  // An outlier 1.5 beyond grid point (5, 2, 3) on the grid's x = 0.5 face: its nearest point.
  b.positions.push_back(a.positions[3 * 36 + 2 * 6 + 5] + vec3f(1.5f, 0, 0));
  const auto one_sided = [](const point_cloud& from, const point_cloud& to) {
    double mx = 0, sum = 0;
    for (const vec3f& p : from.positions) {
      double best = std::numeric_limits<double>::infinity();
      for (const vec3f& q : to.positions)
        best = std::min(best, (p.cast<double>() - q.cast<double>()).norm());
      mx = std::max(mx, best);
      sum += best;
    }
    return std::pair{mx, sum / double(from.size())};
  };
  const auto [ab_max, ab_mean] = one_sided(a, b);
  const auto [ba_max, ba_mean] = one_sided(b, a);
  EXPECT_NEAR(ba_max, 1.5, 1e-6);    // the outlier
  ASSERT_GT(ab_max, 1.5 * ab_mean);  // the numbers do tell max from mean
  const hausdorff_result h = hausdorff(a, b);
  EXPECT_NEAR(h.a_to_b_max, ab_max, 1e-6);
  EXPECT_NEAR(h.a_to_b_mean, ab_mean, 1e-6);
  EXPECT_NEAR(h.b_to_a_max, ba_max, 1e-6);
  EXPECT_NEAR(h.b_to_a_mean, ba_mean, 1e-6);
  EXPECT_NEAR(h.symmetric(), std::max(ab_max, ba_max), 1e-6);
}

// Different origins 10⁷ apart describing the same world points: rebasing in double keeps them
// identical, so the distance is 0 (float coordinates of the world position would be 1 m off).
TEST(Metrics, HausdorffAcrossOrigins) {
  const point_cloud a = grid_cloud(vec3d(1e7, -2e6, 3e5));
  point_cloud b = a;
  rebase(b, vec3d(1e7 + 123.25, -2e6 - 0.5, 3e5 + 7));
  EXPECT_NEAR(hausdorff(a, b).symmetric(), 0, 1e-5);
  EXPECT_THROW((void)hausdorff(a, point_cloud{}), InvalidArgument);
}

// The indexed overload against a brute-force O(n·m) loop over every pair: random sets of
// different sizes (seeded; any data will do — the answer is defined pair by pair), computed on
// 1 and on 3 threads, which must agree exactly (fixed chunks, summed in order).
TEST(Metrics, IndexedHausdorffMatchesBruteForce) {
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> u(-1, 1);
  std::vector<vec3f> a(700), b(450);
  for (auto& p : a) p = vec3f(u(rng), u(rng), 0.3f * u(rng));
  for (auto& p : b) p = vec3f(u(rng), u(rng), u(rng));
  const auto brute = [](const std::vector<vec3f>& from, const std::vector<vec3f>& to) {
    double mx = 0, sum = 0, sum2 = 0;
    for (const auto& p : from) {
      double best = std::numeric_limits<double>::infinity();
      for (const auto& q : to) best = std::min(best, static_cast<double>((p - q).norm()));
      mx = std::max(mx, best);
      sum += best;
      sum2 += best * best;
    }
    const auto n = static_cast<double>(from.size());
    return std::array<double, 3>{mx, sum / n, std::sqrt(sum2 / n)};
  };
  const auto ab = brute(a, b), ba = brute(b, a);
  const knn_index index_a(a);
  const hausdorff_result h = hausdorff(a, index_a, b, 1);
  EXPECT_NEAR(h.a_to_b_max, ab[0], 1e-6);
  EXPECT_NEAR(h.a_to_b_mean, ab[1], 1e-6);
  EXPECT_NEAR(h.a_to_b_rms, ab[2], 1e-6);
  EXPECT_NEAR(h.b_to_a_max, ba[0], 1e-6);
  EXPECT_NEAR(h.b_to_a_mean, ba[1], 1e-6);
  EXPECT_NEAR(h.b_to_a_rms, ba[2], 1e-6);
  const one_sided_distance ba1 = distance_to(b, index_a);  // b → a alone, as in hausdorff()
  EXPECT_EQ(ba1.max, h.b_to_a_max);
  EXPECT_EQ(ba1.rms, h.b_to_a_rms);
  const hausdorff_result h3 = hausdorff(a, index_a, b, 3);
  EXPECT_EQ(h3.a_to_b_mean, h.a_to_b_mean);
  EXPECT_EQ(h3.b_to_a_rms, h.b_to_a_rms);
  EXPECT_THROW((void)hausdorff(a, knn_index(b), b), InvalidArgument);  // index over other points
  EXPECT_THROW((void)hausdorff(a, index_a, std::vector<vec3f>{}), InvalidArgument);
}

// A 20×20 grid of spacing 1 against the same grid shifted by d = 0.3 along z (off its plane):
// every point's nearest is its own copy (any other is ≥ √(1 + d²) away), so max, mean and RMS
// are all exactly d, both ways — the analytic case of the sweep's object-space error.
TEST(Metrics, HausdorffGridShiftedOffPlane) {
  std::vector<vec3f> a, b;
  for (int j = 0; j < 20; ++j)
    for (int i = 0; i < 20; ++i) {
      a.emplace_back(float(i), float(j), 0.0f);
      b.emplace_back(float(i), float(j), 0.3f);
    }
  const hausdorff_result h = hausdorff(a, knn_index(a), b);
  for (const double d :
       {h.a_to_b_max, h.b_to_a_max, h.a_to_b_mean, h.b_to_a_mean, h.a_to_b_rms, h.b_to_a_rms})
    EXPECT_NEAR(d, 0.3, 1e-6);
}

// --- PNG ---------------------------------------------------------------------------------------

std::string temp_path(const std::string& name) {
  return (std::filesystem::temp_directory_path() / ("pbr_lod_raster_" + name)).string();
}

// Colours, including those of background pixels, and coverage survive a write/read exactly.
TEST(Png, RoundTripExact) {
  std::mt19937 rng(1);  // seeded random content: every byte value and coverage pattern
  std::uniform_int_distribution<int> byte(0, 255), coin(0, 3);
  image img(37, 23, {7, 8, 9});
  for (std::size_t i = 0; i < img.size(); ++i) {
    if (coin(rng) == 0) continue;  // stays background, colour (7, 8, 9)
    img.colour[i] = {std::uint8_t(byte(rng)), std::uint8_t(byte(rng)), std::uint8_t(byte(rng))};
    img.depth[i] = 3.5f;
  }
  const std::string path = temp_path("roundtrip.png");
  write_png(path, img);
  const image back = read_png_image(path);
  std::filesystem::remove(path);
  ASSERT_EQ(back.width, img.width);
  ASSERT_EQ(back.height, img.height);
  EXPECT_EQ(back.colour, img.colour);
  for (std::size_t i = 0; i < img.size(); ++i) {
    ASSERT_EQ(back.covered(i), img.covered(i)) << i;
    if (back.covered(i)) {
      EXPECT_EQ(back.depth[i], 0.0f);  // PNG keeps no depth
    }
  }
}

// A 2×2 RGB PNG without alpha (bytes made with Python's zlib): every pixel is covered.
TEST(Png, RgbWithoutAlphaIsAllCovered) {
  const unsigned char bytes[] = {0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00,
                                 0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00, 0x02, 0x00, 0x00,
                                 0x00, 0x02, 0x08, 0x02, 0x00, 0x00, 0x00, 0xfd, 0xd4, 0x9a, 0x73,
                                 0x00, 0x00, 0x00, 0x13, 0x49, 0x44, 0x41, 0x54, 0x78, 0x9c, 0x63,
                                 0xf8, 0xcf, 0xc0, 0xc0, 0x00, 0xc2, 0x0c, 0xff, 0xb9, 0x44, 0xe4,
                                 0x00, 0x1a, 0x58, 0x03, 0x3a, 0x56, 0x63, 0xa2, 0x3c, 0x00, 0x00,
                                 0x00, 0x00, 0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82};
  const std::string path = temp_path("rgb.png");
  std::ofstream(path, std::ios::binary).write(reinterpret_cast<const char*>(bytes), sizeof bytes);
  const image img = read_png_image(path);
  std::filesystem::remove(path);
  ASSERT_EQ(img.width, 2);
  ASSERT_EQ(img.height, 2);
  EXPECT_EQ(img.covered_count(), 4u);
  EXPECT_EQ(img.at(0, 0), (rgb8{255, 0, 0}));
  EXPECT_EQ(img.at(1, 0), (rgb8{0, 255, 0}));
  EXPECT_EQ(img.at(0, 1), (rgb8{0, 0, 255}));
  EXPECT_EQ(img.at(1, 1), (rgb8{10, 20, 30}));
}

// Errors name the file: missing → IoError, not a PNG or truncated → FormatError.
TEST(Png, Errors) {
  const std::string missing = temp_path("does_not_exist.png");
  try {
    (void)read_png_image(missing);
    FAIL();
  } catch (const IoError& e) {
    EXPECT_NE(std::string(e.what()).find(missing), std::string::npos);
  }
  const std::string junk = temp_path("junk.png");
  std::ofstream(junk) << "this is not a png";
  EXPECT_THROW((void)read_png_image(junk), FormatError);
  // A valid PNG cut in the middle of its data.
  image img(16, 16, {1, 2, 3});
  write_png(junk, img);
  const auto size = std::filesystem::file_size(junk);
  std::filesystem::resize_file(junk, size / 2);
  try {
    (void)read_png_image(junk);
    FAIL();
  } catch (const FormatError& e) {
    EXPECT_NE(std::string(e.what()).find(junk), std::string::npos);
  }
  std::filesystem::remove(junk);
  EXPECT_THROW(write_png(temp_path("no_such_dir/x.png"), img), IoError);
  EXPECT_THROW(write_png(junk, image()), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod
