// The 3-D Gaussian rasteriser (raster/gaussians.hpp): analytic footprints, depth order,
// compositing by hand, SH colour, a brute-force per-pixel reference, thread independence and
// degenerate input. Each expected value says why it is right.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <random>
#include <vector>

#include "pbr_lod/raster/gaussians.hpp"

namespace pbr_lod {
namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

/// Looking down −z from the origin; w × h pixels, fovy 40°.
camera test_camera(int w = 64, int h = 64) {
  camera c;
  c.eye = vec3d(0, 0, 0);
  c.target = vec3d(0, 0, -1);
  c.vp = {w, h};
  c.z_near = 0.1;
  c.z_far = 100;
  return c;
}

/// Degree-0 coefficients whose colour (0.5 + C0·dc) is `rgb`.
std::vector<float> dc_for(const vec3f& rgb) {
  const auto dc = [](float c) { return static_cast<float>((c - 0.5) / sh_c0); };
  return {dc(rgb.x()), dc(rgb.y()), dc(rgb.z())};
}

gaussian_prim isotropic(const vec3f& p, float sigma, float opacity, const std::vector<float>& sh) {
  const float v = sigma * sigma;
  return {.position = p, .covariance = {v, 0, 0, v, 0, v}, .opacity = opacity, .sh = sh.data()};
}

image draw(const camera& cam, const std::vector<gaussian_prim>& gs, rgb8 bg = {},
           unsigned threads = 1) {
  gaussian_rasterizer r(view(cam, vec3d::Zero()), {.background = bg, .threads = threads});
  for (const auto& g : gs) r.gaussian(g);
  return r.finish();
}

int channel(rgb8 c, int ch) {
  return ch == 0 ? c.r : ch == 1 ? c.g : c.b;
}

/// The 8-bit value of a float colour as the rasteriser quantises it.
int q8(double v) {
  return static_cast<int>(std::lround(std::clamp(v, 0.0, 1.0) * 255));
}

void expect_pixel_near(const image& img, int x, int y, const std::array<double, 3>& want) {
  for (int ch = 0; ch < 3; ++ch)
    EXPECT_NEAR(channel(img.at(x, y), ch), q8(want[ch]), 1) << "pixel " << x << "," << y;
}

// One isotropic Gaussian on the axis faces the camera: its footprint is the 2-D Gaussian of
// σ_px = f·σ/z (J = diag(f/z, −f/z) on the axis), widened by the 0.3 px² low-pass. Its mean
// projects to (32, 32), a pixel corner; pixel (i, j) is sampled at its centre (i + ½, j + ½).
// σ_px ≈ 1 px makes the low-pass visible (without it, pixel (34, 31) is off by ~8 units),
// σ_px ≈ 3.5 px the falloff over many pixels.
void expect_analytic_footprint(float sigma) {
  const camera cam = test_camera();
  const view v(cam, vec3d::Zero());
  const float z = 5, opacity = 0.8f;
  const vec3f colour(0.9f, 0.3f, 0.1f);
  const rgb8 bg{20, 40, 60};
  const auto sh = dc_for(colour);
  const image img = draw(cam, {isotropic({0, 0, -z}, sigma, opacity, sh)}, bg);
  const double s2 = std::pow(double(v.focal_px) * sigma / z, 2) + 0.3;
  const auto expected = [&](int i, int j) {
    const double dx = i + 0.5 - 32, dy = j + 0.5 - 32;
    double a = std::min(0.99, opacity * std::exp(-(dx * dx + dy * dy) / (2 * s2)));
    if (a < 1.0 / 255) a = 0;
    return std::array<double, 3>{a * colour.x() + (1 - a) * bg.r / 255.0,
                                 a * colour.y() + (1 - a) * bg.g / 255.0,
                                 a * colour.z() + (1 - a) * bg.b / 255.0};
  };
  for (const auto& [i, j] : std::vector<std::pair<int, int>>{
           {31, 31}, {32, 32}, {34, 31}, {36, 36}, {28, 33}, {40, 32}, {32, 22}, {45, 45}, {0, 0}})
    expect_pixel_near(img, i, j, expected(i, j));
  EXPECT_FLOAT_EQ(img.depth[img.index(32, 32)], z);  // α ≈ 0.67 / 0.78: T < ½, covered
  EXPECT_FALSE(img.covered(45, 45));                 // α ≤ 0.01: not covered
  EXPECT_EQ(img.at(0, 0), bg);                       // α < 1/255: exactly the background
}
TEST(GaussianRaster, IsotropicMatchesAnalyticFootprint) {
  expect_analytic_footprint(0.06f);  // σ_px = 1.05
  expect_analytic_footprint(0.2f);   // σ_px = 3.5
}

// Two opaque Gaussians on the same line of sight: the nearer one's colour wins whatever the
// emission order, because compositing runs in view-depth order.
TEST(GaussianRaster, NearerWinsRegardlessOfOrder) {
  const auto red = dc_for({1, 0, 0}), blue = dc_for({0, 0, 1});
  const gaussian_prim near_red = isotropic({0, 0, -4}, 0.3f, 1, red);
  const gaussian_prim far_blue = isotropic({0.05f, 0, -6}, 0.5f, 1, blue);
  const image a = draw(test_camera(), {near_red, far_blue});
  const image b = draw(test_camera(), {far_blue, near_red});
  EXPECT_EQ(a, b);
  const rgb8 c = a.at(32, 32);
  EXPECT_GE(c.r, 240);  // α = 0.99 of red, then at most 1 % of blue
  EXPECT_LE(c.b, 3);
  EXPECT_FLOAT_EQ(a.depth[a.index(32, 32)], 4.0f);
}

// Two half-transparent Gaussians: C = c₁α₁ + c₂α₂(1 − α₁) + bg(1 − α₁)(1 − α₂) (3DGS eq. 3),
// with each α from its own analytic footprint.
TEST(GaussianRaster, TwoHalfTransparentCompositeByHand) {
  const camera cam = test_camera();
  const view v(cam, vec3d::Zero());
  const vec3f c1(0.8f, 0.2f, 0.1f), c2(0.1f, 0.6f, 0.9f);
  const auto sh1 = dc_for(c1), sh2 = dc_for(c2);
  const rgb8 bg{50, 50, 50};
  const image img = draw(
      cam, {isotropic({0, 0, -6}, 0.4f, 0.5f, sh2), isotropic({0, 0, -4}, 0.3f, 0.5f, sh1)}, bg);
  const auto alpha = [&](double sigma, double z, double o, int i, int j) {
    const double s2 = std::pow(v.focal_px * sigma / z, 2) + 0.3;
    const double dx = i + 0.5 - 32, dy = j + 0.5 - 32;
    const double a = std::min(0.99, o * std::exp(-(dx * dx + dy * dy) / (2 * s2)));
    return a < 1.0 / 255 ? 0.0 : a;
  };
  for (const auto& [i, j] : std::vector<std::pair<int, int>>{{32, 32}, {35, 30}, {40, 40}}) {
    const double a1 = alpha(0.3, 4, 0.5, i, j), a2 = alpha(0.4, 6, 0.5, i, j);
    std::array<double, 3> want{};
    for (int ch = 0; ch < 3; ++ch)
      want[ch] =
          c1[ch] * a1 + c2[ch] * a2 * (1 - a1) + channel(bg, ch) / 255.0 * (1 - a1) * (1 - a2);
    expect_pixel_near(img, i, j, want);
  }
}

// sh_colour's basis against numbers worked by hand (3DGS's constants C1 = 0.4886025119,
// C3[3] = 0.3731763326, C3[1] = 2.8906114426).
TEST(GaussianRaster, ShColourWorkedNumbers) {
  // Degree 1, dir (0.6, 0, 0.8): colour = 0.5 + C0·dc − C1·y·k1 + C1·z·k2 − C1·x·k3.
  //   R: 0.5 + 0.2820948·1 + 0.4886025·0.8·0.5        = 0.9775358
  //   G: 0.5 + 0           − 0.4886025·0.6·0.5        = 0.3534192
  //   B: 0.5 (y = 0 removes k1, the only B coefficient)
  const float deg1[12] = {1, 0, 0, /*k1*/ 1, 1, 1, /*k2*/ 0.5f, 0, 0, /*k3*/ 0, 0.5f, 0};
  const vec3f c = sh_colour(deg1, 1, vec3f(0.6f, 0, 0.8f));
  EXPECT_NEAR(c.x(), 0.9775358f, 1e-6f);
  EXPECT_NEAR(c.y(), 0.3534192f, 1e-6f);
  EXPECT_NEAR(c.z(), 0.5f, 1e-6f);
  // Degree 3, one coefficient each: k12 = 0.5 (R) at dir (0, 0, 1): C3[3]·z(2z² − 3x² − 3y²)
  // = 0.3731763·2, times 0.5 → 0.8731763; k10 = 1 (G) at dir (1,1,1)/√3: C3[1]·xyz =
  // 2.8906114/(3√3) = 0.5562984 → 1.0562984 (not clamped above, as 3DGS).
  std::vector<float> deg3(48, 0.0f);
  deg3[3 * 12 + 0] = 0.5f;
  deg3[3 * 10 + 1] = 1.0f;
  const vec3f up = sh_colour(deg3.data(), 3, vec3f(0, 0, 1));
  EXPECT_NEAR(up.x(), 0.8731763f, 1e-6f);
  EXPECT_NEAR(up.y(), 0.5f, 1e-6f);  // xyz = 0 on the axis
  const vec3f diag = sh_colour(deg3.data(), 3, vec3f(1, 1, 1).normalized());
  EXPECT_NEAR(diag.y(), 1.0562984f, 1e-6f);
  // Clamped below at 0: a DC of −10 gives 0.5 − 2.82 < 0.
  const float dark[3] = {-10, -10, -10};
  EXPECT_EQ(sh_colour(dark, 0, vec3f(0, 0, 1)), vec3f::Zero());
}

// The centre pixel of a large opaque Gaussian is 0.99 × its view-dependent colour (α clamped at
// 0.99 where the falloff is < 1 %; background black), the colour sh_colour() gives for the
// direction from the eye to the mean — off the axis, so every band sees a general direction.
void expect_centre_is_sh_colour(int degree) {
  const camera cam = test_camera();
  const view v(cam, vec3d::Zero());
  std::mt19937 rng(7 + degree);  // any coefficients will do; small ones keep the colour in (0, 1)
  std::uniform_real_distribution<float> u(-0.25f, 0.25f);
  std::vector<float> sh(3 * std::size_t(sh_coefficients(degree)));
  for (float& c : sh) c = u(rng);
  gaussian_prim g = isotropic({1.0f, 0.5f, -5.0f}, 0.6f, 1, sh);
  g.sh_degree = degree;
  const image img = draw(cam, {g});
  const vec3f want = sh_colour(sh.data(), degree, g.position.normalized());  // eye at 0
  const vec2f xy = v.eye_to_screen(v.to_eye(g.position));
  const int i = int(std::floor(xy.x())), j = int(std::floor(xy.y()));
  for (int ch = 0; ch < 3; ++ch) {
    ASSERT_GT(want[ch], 0.05f);  // not clamped: the test sees the basis, not the clamp
    ASSERT_LT(want[ch], 0.95f);
    EXPECT_NEAR(channel(img.at(i, j), ch), q8(0.99 * want[ch]), 1) << "channel " << ch;
  }
  // And the view dependence is real: the same Gaussian seen along another direction differs.
  EXPECT_GT((want - sh_colour(sh.data(), degree, vec3f(0, 0, -1))).norm(), 0.01f);
}
TEST(GaussianRaster, ShDegree1CentrePixel) {
  expect_centre_is_sh_colour(1);
}
TEST(GaussianRaster, ShDegree3CentrePixel) {
  expect_centre_is_sh_colour(3);
}

struct random_cloud {
  std::vector<gaussian_prim> prims;
  std::vector<float> sh;
};

/// n Gaussians in and around the frustum of test_camera (some behind the eye, some outside the
/// guard band), anisotropic and rotated, opacities 0.02–1, SH degree 1. Random input is fine:
/// the reference below is defined for any input.
random_cloud make_random_cloud(std::size_t n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(0, 1);
  random_cloud rc;
  rc.sh.resize(n * 12);
  for (float& c : rc.sh) c = 2 * u(rng) - 1;
  for (std::size_t i = 0; i < n; ++i) {
    const float z = -0.5f - 9.5f * u(rng) + (i % 50 == 0 ? 12 : 0);  // every 50th behind the eye
    const vec3f p(z * (1.2f * u(rng) - 0.6f), z * (1.2f * u(rng) - 0.6f), z);
    const vec3f s = vec3f(u(rng), u(rng), u(rng)) * 0.15f * (0.1f + u(rng));
    const vec4f q = vec4f(u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f, u(rng) - 0.5f).normalized();
    rc.prims.push_back({.position = p,
                        .covariance = gaussian_covariance(s, q),
                        .opacity = 0.02f + 0.98f * u(rng),
                        .sh_degree = 1});
  }
  for (std::size_t i = 0; i < n; ++i) rc.prims[i].sh = rc.sh.data() + 12 * i;
  return rc;
}

/// Per pixel, every projected Gaussian in view-depth order (ties by index), 3DGS's compositing
/// rules and nothing else: no tiles, no boxes.
image brute_force(const view& v, const std::vector<gaussian_prim>& gs, rgb8 bg) {
  std::vector<detail::gaussian_2d> s;
  for (const auto& g : gs) {
    const detail::gaussian_2d p = detail::project_gaussian(v, g);
    if (p.status == detail::gaussian_2d::fate::drawn) s.push_back(p);
  }
  std::stable_sort(s.begin(), s.end(),
                   [](const auto& a, const auto& b) { return a.depth < b.depth; });
  image img(v.width, v.height, bg);
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) {
      float t = 1, c[3] = {0, 0, 0};
      for (const auto& g : s) {
        const float a = detail::gaussian_alpha(g, float(x) + 0.5f, float(y) + 0.5f);
        if (a < 1.0f / 255) continue;
        if (t * (1 - a) < 1e-4f) break;
        for (int ch = 0; ch < 3; ++ch) c[ch] += g.rgb[ch] * a * t;
        t *= 1 - a;
      }
      const auto q = [&](int ch) {
        return std::uint8_t(q8(c[ch] + t * float(channel(bg, ch)) / 255.0f));
      };
      img.colour[img.index(x, y)] = rgb8{q(0), q(1), q(2)};
    }
  return img;
}

// The tiled, boxed, early-terminating image equals the per-pixel loop over all Gaussians within
// one unit of 8 bits (the boxes are where α ≥ 1/255 can happen, so they skip only work). The
// viewport is not a multiple of 16, so partial tiles are covered too.
TEST(GaussianRaster, TiledEqualsBruteForce) {
  const camera cam = test_camera(150, 90);
  const view v(cam, vec3d::Zero());
  const random_cloud rc = make_random_cloud(2000, 42);
  const rgb8 bg{30, 60, 90};
  gaussian_rasterizer r(v, {.background = bg, .threads = 2});
  for (const auto& g : rc.prims) r.gaussian(g);
  const image tiled = r.finish();
  EXPECT_GT(r.stats().drawn, 1000u);
  EXPECT_GT(r.stats().culled, 40u);  // the 40 behind the eye, and those outside the guard band
  const image ref = brute_force(v, rc.prims, bg);
  int worst = 0;
  std::size_t differing = 0;
  for (std::size_t i = 0; i < ref.size(); ++i) {
    int d = 0;
    for (int ch = 0; ch < 3; ++ch)
      d = std::max(d, std::abs(channel(ref.colour[i], ch) - channel(tiled.colour[i], ch)));
    worst = std::max(worst, d);
    differing += d > 0;
  }
  EXPECT_LE(worst, 1);
  RecordProperty("pixels_differing", int(differing));
  // The scene is not trivial: most pixels are drawn over, many saturate.
  EXPECT_GT(tiled.covered_count(), ref.size() / 2);
}

TEST(GaussianRaster, ThreadCountDoesNotChangeTheBytes) {
  const camera cam = test_camera(200, 120);
  const random_cloud rc = make_random_cloud(2000, 3);
  const image one = draw(cam, rc.prims, {10, 20, 30}, 1);
  const image two = draw(cam, rc.prims, {10, 20, 30}, 2);
  EXPECT_TRUE(one == two);
  EXPECT_TRUE(draw(cam, rc.prims, {10, 20, 30}, 0) == one);
}

/// No NaN depth; covered depths within [z_near, z_far].
void expect_sane(const image& img, const camera& cam) {
  for (std::size_t i = 0; i < img.size(); ++i) {
    ASSERT_FALSE(std::isnan(img.depth[i])) << i;
    if (img.covered(i)) {
      ASSERT_GE(img.depth[i], cam.z_near);
      ASSERT_LE(img.depth[i], cam.z_far);
    }
  }
}

// Zero covariance: the low-pass alone gives a 0.3 px² dot, α = o·exp(−d²/0.6) at its pixels.
TEST(GaussianRasterDegenerate, ZeroScaleIsALowPassDot) {
  const auto sh = dc_for({1, 1, 1});
  const gaussian_prim g{.position = {0, 0, -3}, .opacity = 1, .sh = sh.data()};
  const image img = draw(test_camera(), {g});
  const double a = std::exp(-0.5 / 0.6);  // pixel (32, 32): d = (½, ½)
  expect_pixel_near(img, 32, 32, {a, a, a});
  expect_pixel_near(img, 31, 31, {a, a, a});
  EXPECT_EQ(img.at(34, 32), rgb8{});  // d² = 6.25 + 0.25: α = 1.9·10⁻⁵ < 1/255
  expect_sane(img, test_camera());
}

TEST(GaussianRasterDegenerate, CulledAndInvalidAreCountedAndDrawNothing) {
  const auto sh = dc_for({1, 0, 0});
  std::vector<float> bad_sh = sh;
  bad_sh[1] = kNaN;
  const camera cam = test_camera();
  std::vector<gaussian_prim> gs = {
      isotropic({0, 0, -3}, 0.2f, 0, sh),       // culled: zero opacity
      isotropic({0, 0, -3}, 0.2f, 0.003f, sh),  // culled: α < 1/255 everywhere
      isotropic({0, 0, 2}, 0.2f, 1, sh),        // culled: behind the eye
      isotropic({0, 0, 0}, 0.2f, 1, sh),        // culled: at the eye
      isotropic({0, 0, -0.05f}, 0.2f, 1, sh),   // culled: in front of z_near = 0.1
      isotropic({5, 0, -3}, 0.2f, 1, sh),       // culled: x/z = 1.67 > 1.3 tan(20°)
      isotropic({kNaN, 0, -3}, 0.2f, 1, sh),    // invalid: position
      isotropic({0, 0, -3}, kInf, 1, sh),       // invalid: covariance
      isotropic({0, 0, -3}, 0.2f, kNaN, sh),    // invalid: opacity
      isotropic({0, 0, -3}, 0.2f, 1, bad_sh),   // invalid: SH coefficient → colour
      isotropic({0, 0, -3}, 0.2f, 1, sh),       // invalid: sh_degree 4 (set below)
      {.position = {0, 0, -3}, .covariance = {-1, 0, 0, -1, 0, -1}, .opacity = 1, .sh = sh.data()},
  };
  gs[10].sh_degree = 4;
  gaussian_rasterizer r(view(cam, vec3d::Zero()), {.background = {1, 2, 3}});
  for (const auto& g : gs) r.gaussian(g);
  r.point(point_prim<positions_only>{});
  r.splat(splat_prim<with_normals_colours>{});
  r.triangle(triangle_prim<positions_only>{});
  const image img = r.finish();
  EXPECT_TRUE(img == image(64, 64, {1, 2, 3}));
  const gaussian_raster_stats st = r.stats();
  EXPECT_EQ(st.received, gs.size());
  EXPECT_EQ(st.drawn, 0u);
  EXPECT_EQ(st.culled, 6u);
  EXPECT_EQ(st.invalid, 6u);
  EXPECT_EQ(st.ignored, 3u);
  EXPECT_EQ(r.ignored(), 3u);
}

// Covariances far beyond the screen: the projection runs in double (no overflow) and the box is
// clamped to the screen, so the whole frame is one flat α = min(0.99, o) — never NaN.
TEST(GaussianRasterDegenerate, HugeCovarianceCoversTheFrameWithoutNaN) {
  const auto sh = dc_for({0.5f, 0.5f, 0.5f});
  const float big = std::numeric_limits<float>::max();
  for (const float v : {1e6f, 1e30f, big}) {
    const gaussian_prim g{.position = {0.3f, -0.2f, -3},
                          .covariance = {v, 0, 0, v, 0, v},
                          .opacity = 0.6f,
                          .sh = sh.data()};
    const image img = draw(test_camera(), {g});
    expect_sane(img, test_camera());
    for (const auto& [i, j] : std::vector<std::pair<int, int>>{{0, 0}, {63, 63}, {20, 40}})
      expect_pixel_near(img, i, j, {0.3, 0.3, 0.3});  // 0.6 × 0.5
  }
}

// The guard band: a large Gaussian whose mean lies just outside the frustum (1.2× the half fov)
// still covers the frame's edge; at 1.4× it is culled.
TEST(GaussianRasterDegenerate, GuardBandKeepsMeansJustOffScreen) {
  const auto sh = dc_for({1, 1, 1});
  const float tan_half = float(std::tan(20 * std::numbers::pi / 180));
  const image in = draw(test_camera(), {isotropic({1.2f * tan_half * 5, 0, -5}, 0.5f, 1, sh)});
  EXPECT_GT(in.at(63, 32).r, 50);
  const image out = draw(test_camera(), {isotropic({1.4f * tan_half * 5, 0, -5}, 0.5f, 1, sh)});
  EXPECT_TRUE(out == image(64, 64));
}

gaussian_cloud cloud_of(const random_cloud& rc, const vec3d& origin) {
  gaussian_cloud c;
  c.origin = origin;
  c.sh_degree = 1;
  c.sh = rc.sh;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(0.01f, 0.1f);
  for (const auto& g : rc.prims) {
    c.positions.push_back(g.position);
    c.scales.push_back(vec3f(u(rng), u(rng), u(rng)));
    c.rotations.push_back(vec4f(1, 0, 0, 0));
    c.opacities.push_back(g.opacity);
  }
  return c;
}

// Data 10⁷ units from the world origin draws as at the origin: the view is built relative to the
// cloud's origin in double, the Gaussians are float relative to it.
TEST(GaussianRasterDegenerate, FarOriginDrawsTheSameImage) {
  const random_cloud rc = make_random_cloud(500, 9);
  const vec3d far(1e7, -1e7, 1e7);
  camera c0 = test_camera(96, 96), c1 = c0;
  c1.eye += far;
  c1.target += far;
  const image a = render_gaussians(cloud_of(rc, vec3d::Zero()), c0);
  const image b = render_gaussians(cloud_of(rc, far), c1);
  int worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i)
    for (int ch = 0; ch < 3; ++ch)
      worst = std::max(worst, std::abs(channel(a.colour[i], ch) - channel(b.colour[i], ch)));
  EXPECT_LE(worst, 1);
  EXPECT_GT(a.covered_count(), 100u);
}

// render_gaussians is the rasteriser fed every Gaussian of the cloud with
// gaussian_covariance(scale, rotation); it refuses arrays of different lengths.
TEST(GaussianRaster, RenderGaussiansIsTheRasteriserOverTheCloud) {
  const random_cloud rc = make_random_cloud(300, 11);
  const gaussian_cloud cloud = cloud_of(rc, vec3d::Zero());
  const camera cam = test_camera(80, 60);
  std::vector<gaussian_prim> gs;
  for (std::size_t i = 0; i < cloud.size(); ++i)
    gs.push_back({.position = cloud.positions[i],
                  .covariance = gaussian_covariance(cloud.scales[i], cloud.rotations[i]),
                  .opacity = cloud.opacities[i],
                  .sh_degree = 1,
                  .sh = cloud.sh.data() + 12 * i});
  EXPECT_TRUE(render_gaussians(cloud, cam) == draw(cam, gs));
  gaussian_cloud broken = cloud;
  broken.opacities.pop_back();
  EXPECT_THROW((void)render_gaussians(broken, cam), InvalidArgument);
  EXPECT_TRUE(render_gaussians(gaussian_cloud{}, cam, {.background = {9, 9, 9}}) ==
              image(80, 60, {9, 9, 9}));
}

// A buffer_sink replays Gaussians to the rasteriser as Gaussians (it models GaussianSink), and
// one-pixel and odd-sized viewports work.
TEST(GaussianRaster, BufferReplayAndSmallViewports) {
  const random_cloud rc = make_random_cloud(200, 13);
  buffer_sink<positions_only> buf;
  for (const auto& g : rc.prims) buf.gaussian(g);
  const camera cam = test_camera(17, 5);
  gaussian_rasterizer r(view(cam, vec3d::Zero()));
  buf.replay(r);
  EXPECT_TRUE(r.finish() == draw(cam, rc.prims));
  EXPECT_EQ(r.ignored(), 0u);
  expect_sane(draw(test_camera(1, 1), rc.prims), test_camera(1, 1));
}

}  // namespace
}  // namespace pbr_lod
