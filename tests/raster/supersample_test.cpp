// Supersampling (render_options::supersample, view::supersampled, downsample_box): the box filter
// on pixels worked out by hand, an edge at a known sub-pixel position coming out as its covered
// fraction, points sized in the drawn view's pixels, and the misuses that must throw.
#include <gtest/gtest.h>

#include <array>
#include <limits>

#include "pbr_lod/raster/rasterizer.hpp"
#include "support/cameras.hpp"

namespace pbr_lod {
namespace {

constexpr attributes colour_only{.colour = true};
constexpr float inf = std::numeric_limits<float>::infinity();
using test::origin_camera;

// A 4×2 image filtered by 2: block 0 holds colours 0, 1, 2, 3 in red (mean 1.5 rounds up to 2)
// and one covered sample at depth 5 beside three background ones (depth +inf); block 1 holds
// 255 three times and 0 once in green (191.25 → 191), depths 4, 3, 7, +inf (nearest: 3).
TEST(DownsampleBox, HandCheckedBlocks) {
  image big(4, 2);
  big.colour = {{0, 0, 0}, {1, 0, 0}, {0, 255, 0}, {0, 255, 0},  //
                {2, 0, 0}, {3, 0, 0}, {0, 255, 0}, {0, 0, 0}};
  big.depth = {inf, inf, 4, 3,  //
               5,   inf, 7, inf};
  const image small = downsample_box(big, 2);
  ASSERT_EQ(small.width, 2);
  ASSERT_EQ(small.height, 1);
  EXPECT_EQ(small.colour[0], (rgb8{2, 0, 0}));
  EXPECT_EQ(small.depth[0], 5.0f);
  EXPECT_EQ(small.colour[1], (rgb8{0, 191, 0}));
  EXPECT_EQ(small.depth[1], 3.0f);
  EXPECT_EQ(downsample_box(big, 1), big);
}

TEST(DownsampleBox, RejectsFactorsThatDoNotDivide) {
  const image big(6, 4);
  EXPECT_THROW((void)downsample_box(big, 0), InvalidArgument);
  EXPECT_THROW((void)downsample_box(big, -2), InvalidArgument);
  EXPECT_THROW((void)downsample_box(big, 3), InvalidArgument);  // 4 rows
  EXPECT_THROW((void)downsample_box(big, 4), InvalidArgument);  // 6 columns
  EXPECT_NO_THROW((void)downsample_box(big, 2));
}

TEST(ViewSupersampled, ScalesPixelsNotTheFrustum) {
  const view v(origin_camera(40, 30), vec3d::Zero());
  const view s = v.supersampled(4);
  EXPECT_EQ(s.width, 160);
  EXPECT_EQ(s.height, 120);
  EXPECT_EQ(s.focal_px, 4 * v.focal_px);
  EXPECT_EQ(s.cos_cone, v.cos_cone);
  for (std::size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(s.frustum[i].n, v.frustum[i].n);
    EXPECT_EQ(s.frustum[i].d, v.frustum[i].d);
  }
  // A point's screen position scales by k about the origin of the pixel grid.
  const vec3f e(0.3f, -0.2f, 2.0f);
  EXPECT_FLOAT_EQ(s.eye_to_screen(e).x(), 4 * v.eye_to_screen(e).x());
  EXPECT_FLOAT_EQ(s.eye_to_screen(e).y(), 4 * v.eye_to_screen(e).y());
  EXPECT_THROW((void)v.supersampled(0), InvalidArgument);
  EXPECT_THROW((void)view(origin_camera(40000, 30), vec3d::Zero()).supersampled(2),
               InvalidArgument);
}

/// A white triangle in the plane z = −2 whose right edge is the vertical line at screen x = 10.25
/// of a 64×64 view, covering every row: with k = 4 the column of pixel 10 holds one covered
/// sample column of four (centres at 10.125, 10.375, 10.625, 10.875), so its colour is
/// 255/4 = 63.75 → 64; without supersampling pixel 10's centre (10.5) is outside.
image edge_frame(int k) {
  const view v(origin_camera(64, 64), vec3d::Zero());
  const float z = 2;
  const float x = (10.25f - 32.0f) * z / v.focal_px;
  triangle_prim<colour_only> t;
  t.p = {vec3f(x, -40, -z), vec3f(x, 40, -z), vec3f(-40, 0, -z)};
  t.colour = {rgb8{255, 255, 255}, rgb8{255, 255, 255}, rgb8{255, 255, 255}};
  render_options opt;
  opt.fx = effects{.colour = true};
  opt.supersample = k;
  return render<colour_only>(v, opt, [&](auto& sink, const view&) { sink.triangle(t); });
}

TEST(Supersample, EdgeComesOutAsItsCoveredFraction) {
  const image plain = edge_frame(1), ss = edge_frame(4);
  ASSERT_EQ(ss.width, 64);
  ASSERT_EQ(ss.height, 64);
  for (int y = 8; y < 56; ++y) {
    EXPECT_EQ(plain.at(9, y), (rgb8{255, 255, 255})) << y;
    EXPECT_EQ(plain.at(10, y), (rgb8{0, 0, 0})) << y;
    EXPECT_EQ(ss.at(9, y), (rgb8{255, 255, 255})) << y;
    EXPECT_EQ(ss.at(10, y), (rgb8{64, 64, 64})) << y;
    EXPECT_EQ(ss.at(11, y), (rgb8{0, 0, 0})) << y;
    EXPECT_TRUE(ss.covered(10, y));  // one sample of the block is: depth is its depth
    EXPECT_FLOAT_EQ(ss.depth[ss.index(10, y)], 2.0f);
    EXPECT_FALSE(ss.covered(11, y));
  }
}

// A point of 2 px in v is a point of 2k px in the k× view the draw is given: the covered pixels
// after filtering are v's 2 × 2 block, fully covered (the square lands on whole pixels).
TEST(Supersample, DrawIsGivenTheKFoldView) {
  const view v(origin_camera(32, 32), vec3d::Zero());
  render_options opt;
  opt.fx = effects{.colour = true};
  for (const int k : {1, 2, 3}) {
    opt.supersample = k;
    int calls = 0;
    const image img = render<colour_only>(v, opt, [&](auto& sink, const view& dv) {
      ++calls;
      EXPECT_EQ(dv.width, 32 * k);
      EXPECT_EQ(dv.focal_px, v.supersampled(k).focal_px);
      point_prim<colour_only> p;
      p.position = vec3f(0, 0, -3);  // projects to the pixel corner (16, 16)
      p.size_px = 2.0f * static_cast<float>(k);
      p.colour = {200, 100, 50};
      sink.point(p);
    });
    EXPECT_EQ(calls, 1);
    EXPECT_EQ(img.covered_count(), 4u) << k;
    for (const auto& [x, y] :
         std::array<std::array<int, 2>, 4>{{{15, 15}, {16, 15}, {15, 16}, {16, 16}}})
      EXPECT_EQ(img.at(x, y), (rgb8{200, 100, 50})) << k << ": " << x << ", " << y;
  }
}

// render_direct supersamples as render() does, with every effect the frame can take.
TEST(Supersample, DirectEqualsBuffered) {
  const image a = edge_frame(3);
  const view v(origin_camera(64, 64), vec3d::Zero());
  const float x = (10.25f - 32.0f) * 2 / v.focal_px;
  triangle_prim<colour_only> t;
  t.p = {vec3f(x, -40, -2), vec3f(x, 40, -2), vec3f(-40, 0, -2)};
  t.colour = {rgb8{255, 255, 255}, rgb8{255, 255, 255}, rgb8{255, 255, 255}};
  render_options opt;
  opt.fx = effects{.colour = true};
  opt.supersample = 3;
  const image b =
      render_direct<colour_only>(v, opt, [&](auto& sink, const view&) { sink.triangle(t); });
  EXPECT_EQ(a, b);
}

TEST(Supersample, MisusesThrow) {
  const view v(origin_camera(16, 16), vec3d::Zero());
  render_options opt;
  opt.supersample = 2;
  // A draw without the view would size its points for v, not for the frame it draws into.
  EXPECT_THROW((void)render<colour_only>(v, opt, [](auto&) {}), InvalidArgument);
  EXPECT_THROW((void)render_direct<colour_only>(v, opt, [](auto&) {}), InvalidArgument);
  // Buffered primitives were drawn for one view.
  const buffer_sink<colour_only> prims;
  EXPECT_THROW((void)render_buffered<colour_only>(v, opt, prims), InvalidArgument);
  opt.supersample = 0;
  EXPECT_THROW((void)render<colour_only>(v, opt, [](auto&, const view&) {}), InvalidArgument);
  // 1 is the frame itself, whichever form the draw takes.
  opt.supersample = 1;
  const image a = render<colour_only>(v, opt, [](auto&) {});
  const image b = render<colour_only>(v, opt, [](auto&, const view&) {});
  EXPECT_EQ(a, b);
}

}  // namespace
}  // namespace pbr_lod
