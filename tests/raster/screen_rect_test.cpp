// Screen-space rectangles (screen_rect_prim): integer pixel coverage from fixed-point bounds,
// the z-buffer shared with point(), shading as point()'s. Every expected pixel set is worked out
// by hand in the comment above it.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <utility>

#include "pbr_lod/raster/rasterizer.hpp"
#include "support/cameras.hpp"

namespace pbr_lod {
namespace {

using test::origin_camera;
constexpr attributes C{.colour = true};
using pixels = std::set<std::pair<int, int>>;  // (column, row)

/// A rectangle with bounds in pixels (converted to 1/256 pixel exactly: all bounds below are
/// multiples of 1/256), at eye depth `depth`, its 3-D position straight ahead at that depth.
screen_rect_prim<C> rect(double x0, double y0, double x1, double y1, float depth = 2,
                         rgb8 colour = {255, 0, 0}) {
  constexpr double one = screen_rect_prim<C>::one_px;
  screen_rect_prim<C> r;
  r.x0 = std::int32_t(std::lround(x0 * one));
  r.y0 = std::int32_t(std::lround(y0 * one));
  r.x1 = std::int32_t(std::lround(x1 * one));
  r.y1 = std::int32_t(std::lround(y1 * one));
  r.depth = depth;
  r.position = vec3f(0, 0, -depth);
  r.colour = colour;
  return r;
}

/// The pixels an 8×6 frame of the given rectangles covers.
pixels covered(std::initializer_list<screen_rect_prim<C>> rs) {
  const view v(origin_camera(8, 6), vec3d::Zero());
  rasterizer<C> r(v, render_options{});
  for (const auto& q : rs) r.screen_rect(q);
  const image img = r.finish();
  pixels out;
  for (int j = 0; j < img.height; ++j)
    for (int i = 0; i < img.width; ++i)
      if (std::isfinite(img.depth[std::size_t(j * img.width + i)])) out.insert({i, j});
  return out;
}

// A pixel is covered when its centre (i + ½, j + ½) lies in [x0, x1) × [y0, y1).
TEST(ScreenRect, CoversThePixelsWhoseCentresItContains) {
  // Columns: centres 1.5 and 2.5 lie in [1.25, 3.5), 3.5 does not (half-open); rows: 2.5 lies in
  // [2.5, 4.5) (closed below), 3.5 too, 4.5 not.
  EXPECT_EQ(covered({rect(1.25, 2.5, 3.5, 4.5)}), (pixels{{1, 2}, {2, 2}, {1, 3}, {2, 3}}));
  // Exactly one pixel's span: its centre only.
  EXPECT_EQ(covered({rect(2, 0, 3, 1)}), (pixels{{2, 0}}));
  // Clipped: columns −2 … 1 have centres in [−2, 1.6), of which 0 and 1 are on screen; rows:
  // only 5.5 in [5.2, 9) is on a 6-row screen.
  EXPECT_EQ(covered({rect(-2, 5.2, 1.6, 9)}), (pixels{{0, 5}, {1, 5}}));
  // Wholly off screen, left and right.
  EXPECT_EQ(covered({rect(-3, 1, -1, 2)}), pixels{});
  EXPECT_EQ(covered({rect(8, 1, 9.5, 2)}), pixels{});
}

// Along an axis where no centre lies inside, the pixel containing the midpoint: a degenerate
// rectangle is a one-pixel point, as point_prim's size ≤ 1.
TEST(ScreenRect, ThinnerThanAPixelTakesThePixelOfItsMidpoint) {
  // x0 = x1 = 5 (a pixel edge: pixel 5 is [5, 6)), y = 0.75 in row 0.
  EXPECT_EQ(covered({rect(5, 0.75, 5, 0.75)}), (pixels{{5, 0}}));
  // [6.6, 6.9) holds no centre (6.5 < 6.6, 7.5 ≥ 6.9): the midpoint 6.75 is in column 6; rows 1
  // and 2 have their centres in [1, 3).
  EXPECT_EQ(covered({rect(6.6, 1, 6.9, 3)}), (pixels{{6, 1}, {6, 2}}));
  // A midpoint off screen draws nothing.
  EXPECT_EQ(covered({rect(-0.5, 2, -0.5, 2)}), pixels{});
  EXPECT_EQ(covered({rect(3.2, 6.1, 3.4, 6.3)}), pixels{});
}

// The same pixels as point()'s square of the same size about the same centre: a square of 3
// pixels at the centre of pixel (3, 2) covers columns 2–4, rows 1–3, and so does the rectangle
// [2, 5) × [1, 4).
TEST(ScreenRect, AgreesWithPointSquares) {
  const view v(origin_camera(8, 6), vec3d::Zero());
  // The position whose projection is (3.5, 2.5): x = (3.5 − 4)·z/f, y = −(2.5 − 3)·z/f.
  const float z = 2, f = v.focal_px;
  point_prim<C> p{vec3f(-0.5f * z / f, 0.5f * z / f, -z), 3};
  p.colour = {0, 255, 0};
  rasterizer<C> a(v, render_options{}), b(v, render_options{});
  a.point(p);
  b.screen_rect(rect(2, 1, 5, 4));
  const image ia = a.finish(), ib = b.finish();
  EXPECT_EQ(ia.depth, ib.depth);
  std::size_t n = 0;
  for (float d : ia.depth) n += std::isfinite(d);
  EXPECT_EQ(n, 9u);
}

// Depth: key 1/depth, the key point() writes for a point at that eye depth, so a frame mixing
// the two z-tests correctly: the nearer wins whichever comes first, a tie keeps the first drawn,
// the depth buffer reads the rectangle's depth, and a rectangle before the near plane is dropped.
TEST(ScreenRect, SharesTheDepthTestWithPoints) {
  const view v(origin_camera(8, 6), vec3d::Zero());
  const float f = v.focal_px;
  const auto point_at = [&](float z, rgb8 colour) {  // a 1-pixel point at pixel (3, 2)
    point_prim<C> p{vec3f(-0.5f * z / f, 0.5f * z / f, -z), 1};
    p.colour = colour;
    return p;
  };
  const rgb8 red{255, 0, 0}, green{0, 255, 0};
  const std::size_t px = 2 * 8 + 3;
  const auto run = [&](auto&& draw) {
    rasterizer<C> r(v, render_options{});
    draw(r);
    return r.finish();
  };
  // Point at depth 2, then a nearer and a farther rectangle over it.
  image img = run([&](auto& r) {
    r.point(point_at(2, green));
    r.screen_rect(rect(3, 2, 4, 3, 3, red));
  });
  EXPECT_EQ(img.colour[px], green);
  img = run([&](auto& r) {
    r.point(point_at(2, green));
    r.screen_rect(rect(3, 2, 4, 3, 1, red));
  });
  EXPECT_EQ(img.colour[px], red);
  EXPECT_FLOAT_EQ(img.depth[px], 1);
  // The other order.
  img = run([&](auto& r) {
    r.screen_rect(rect(3, 2, 4, 3, 2, red));
    r.point(point_at(1, green));
  });
  EXPECT_EQ(img.colour[px], green);
  img = run([&](auto& r) {
    r.screen_rect(rect(3, 2, 4, 3, 2, red));
    r.point(point_at(3, green));
  });
  EXPECT_EQ(img.colour[px], red);
  EXPECT_FLOAT_EQ(img.depth[px], 2);
  // Equal depth (z = 2 exactly for both): the first drawn stays.
  img = run([&](auto& r) {
    r.screen_rect(rect(3, 2, 4, 3, 2, red));
    r.point(point_at(2, green));
  });
  EXPECT_EQ(img.colour[px], red);
  img = run([&](auto& r) {
    r.point(point_at(2, green));
    r.screen_rect(rect(3, 2, 4, 3, 2, red));
  });
  EXPECT_EQ(img.colour[px], green);
  // Before the near plane (0.1): dropped, as point() drops it.
  EXPECT_EQ(covered({rect(1, 1, 4, 4, 0.05f)}), pixels{});
}

// Shading: two-sided Lambert with the view direction from the 3-D position, as point()'s, so a
// rectangle and a point with the same normal and position have the same colour.
TEST(ScreenRect, ShadedAsPoints) {
  const view v(origin_camera(8, 6), vec3d::Zero());
  render_options ro;
  ro.fx.shading = true;
  ro.sun.direction = vec3f(0.3f, 0.5f, 0.8f);
  const float z = 2, f = v.focal_px;
  const vec3f pos(-0.5f * z / f, 0.5f * z / f, -z);
  for (const vec3f& n : {vec3f(0, 0, 1), vec3f(0.6f, 0, -0.8f), vec3f(0, 1, 0)}) {
    constexpr effects E{.shading = true};
    rasterizer<with_normals, E> a(v, ro), b(v, ro);
    point_prim<with_normals> p{pos, 1};
    p.normal = n;
    screen_rect_prim<with_normals> r{3 << 8, 2 << 8, 4 << 8, 3 << 8, z, pos};
    r.normal = n;
    a.point(p);
    b.screen_rect(r);
    EXPECT_EQ(a.finish().colour, b.finish().colour);
  }
}

}  // namespace
}  // namespace pbr_lod
