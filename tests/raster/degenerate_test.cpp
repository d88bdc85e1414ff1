// Degenerate primitives: zero-area triangles, zero-axis / parallel-axis / edge-on splats, points
// behind the eye or off screen, NaN and infinite coordinates, huge primitives, tiny viewports.
// None may write a NaN, write out of bounds (the sanitizer build checks), or draw in front of
// the near plane. Run with every effect on, so the shadow and hole-filling passes see them too.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <vector>

#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {
namespace {

constexpr attributes A = with_normals_colours;
constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

camera test_camera(int w, int h) {
  camera c;
  c.eye = vec3d(0, 0, 0);
  c.target = vec3d(0, 0, -1);
  c.vp = {w, h};
  c.z_near = 0.5;
  c.z_far = 50;
  return c;
}

/// Every depth is +inf or in [z_near, z_far]; no NaN anywhere.
void expect_sane(const image& img, const view& v) {
  for (std::size_t i = 0; i < img.size(); ++i) {
    const float d = img.depth[i];
    ASSERT_FALSE(std::isnan(d)) << i;
    if (img.covered(i)) {
      ASSERT_GE(d, v.z_near * (1 - 1e-5f)) << i;
      ASSERT_LE(d, v.z_far * (1 + 1e-5f)) << i;
    }
  }
}

triangle_prim<A> make_triangle(vec3f a, vec3f b, vec3f c) {
  triangle_prim<A> t;
  t.p = {a, b, c};
  t.normal = {vec3f::UnitZ(), vec3f::UnitZ(), vec3f::UnitZ()};
  t.colour = {rgb8{255, 0, 0}, rgb8{0, 255, 0}, rgb8{0, 0, 255}};
  return t;
}

splat_prim<A> make_splat(vec3f c, vec3f u, vec3f v, vec3f n = vec3f::UnitZ()) {
  splat_prim<A> s{c, u, v};
  s.normal = n;
  s.colour = {100, 100, 100};
  return s;
}

point_prim<A> make_point(vec3f p, float size) {
  point_prim<A> q{p, size};
  q.normal = vec3f::UnitZ();
  q.colour = {50, 60, 70};
  return q;
}

image draw(const view& v, const std::vector<triangle_prim<A>>& tris,
           const std::vector<splat_prim<A>>& splats, const std::vector<point_prim<A>>& points,
           effects fx = all_effects) {
  render_options opt;
  opt.fx = fx;
  opt.shadow_map_size = 256;
  return render<A>(v, opt, [&](auto& sink) {
    for (const auto& t : tris) sink.triangle(t);
    for (const auto& s : splats) sink.splat(s);
    for (const auto& p : points) sink.point(p);
  });
}

// Zero-area triangles (a repeated vertex, three collinear vertices, all three equal) draw nothing.
TEST(Degenerate, ZeroAreaTriangles) {
  const view v(test_camera(64, 48), vec3d::Zero());
  const vec3f a(-0.5f, -0.5f, -2), b(0.5f, 0.5f, -2);
  for (effects fx : {no_effects, all_effects}) {
    const image img = draw(v,
                           {make_triangle(a, a, b), make_triangle(a, 0.5f * (a + b), b),
                            make_triangle(a, a, a), make_triangle(a, b, a)},
                           {}, {}, fx);
    EXPECT_EQ(img.covered_count(), 0u);
    expect_sane(img, v);
  }
}

// Splats with a zero axis, two parallel axes, or a plane through the eye (edge-on: their image
// is a line segment) have no area and draw nothing; nearly edge-on ones draw a sliver, finite.
TEST(Degenerate, DegenerateSplats) {
  const view v(test_camera(64, 48), vec3d::Zero());
  const vec3f c(0.1f, 0, -2);
  const image img = draw(
      v, {},
      {make_splat(c, vec3f::Zero(), vec3f(0, 0.3f, 0)), make_splat(c, vec3f::Zero(), vec3f::Zero()),
       make_splat(c, vec3f(0.3f, 0, 0), vec3f(0.6f, 0, 0)),
       // Plane x = 0.1·z/(−2)… spanned by c itself and the y axis: contains the eye.
       make_splat(c, c.normalized() * 0.3f, vec3f(0, 0.3f, 0), vec3f::UnitX())},
      {});
  EXPECT_EQ(img.covered_count(), 0u);
  expect_sane(img, v);
  const image sliver = draw(
      v, {}, {make_splat(c, (c.normalized() + vec3f(1e-4f, 0, 0)) * 0.3f, vec3f(0, 0.3f, 0))}, {});
  EXPECT_LE(sliver.covered_count(), 30u);
  expect_sane(sliver, v);
}

// Points behind the eye, behind the near plane, beyond the far plane or off screen draw nothing;
// neither do NaN or infinite positions and sizes of primitives.
TEST(Degenerate, PointsOutsideTheViewAndNonFinite) {
  const view v(test_camera(64, 48), vec3d::Zero());
  const std::vector<point_prim<A>> pts = {
      make_point({0, 0, 1}, 1),         make_point({0, 0, 1}, 5),      // behind the eye
      make_point({0, 0, -0.2f}, 3),     make_point({0, 0, -60}, 3),    // near / far
      make_point({50, 0, -2}, 1),       make_point({-50, 30, -2}, 7),  // off screen
      make_point({0, 0, -1e-30f}, 1),   make_point({kNaN, 0, -2}, 1),
      make_point({0, kInf, -2}, 4),     make_point({0, 0, -2}, kNaN),  // NaN size: one pixel
      make_point({1e30f, 0, -2}, 1e30f)};
  const image img = draw(v, {}, {}, pts);
  EXPECT_EQ(img.covered_count(), 1u);  // only the NaN-sized point, as a single pixel
  expect_sane(img, v);
  const std::vector<splat_prim<A>> splats = {
      make_splat({kNaN, 0, -2}, vec3f(0.1f, 0, 0), vec3f(0, 0.1f, 0)),
      make_splat({0, 0, -2}, vec3f(kInf, 0, 0), vec3f(0, 0.1f, 0)),
      make_splat({0, 0, 3}, vec3f(0.1f, 0, 0), vec3f(0, 0.1f, 0)),  // behind the eye
  };
  const std::vector<triangle_prim<A>> tris = {
      make_triangle({kNaN, 0, -2}, {1, 0, -2}, {0, 1, -2}),
      make_triangle({kInf, 0, -2}, {1, 0, -2}, {0, 1, -2}),
      make_triangle({0, 0, 2}, {1, 0, 2}, {0, 1, 2}),  // behind the eye
  };
  const image img2 = draw(v, tris, splats, {});
  EXPECT_EQ(img2.covered_count(), 0u);
  expect_sane(img2, v);
}

// Huge primitives (far larger than the screen, vertices 10⁶ px off screen, some behind the eye)
// are clipped and cover the screen without overflow.
TEST(Degenerate, HugePrimitives) {
  const view v(test_camera(64, 48), vec3d::Zero());
  const image img =
      draw(v,
           {make_triangle({-1e6f, -1e6f, -3}, {1e6f, -1e6f, -3}, {0, 1e6f, -3}),
            make_triangle({-5, -1, 10}, {5, -1, 10}, {0, -1, -40})},
           {make_splat({0, -0.5f, -2.5f}, vec3f(1e5f, 0, 0), vec3f(0, 0, 1e5f), vec3f::UnitY())},
           {make_point({0, 0, -2}, 1e9f)});
  EXPECT_EQ(img.covered_count(), img.size());
  expect_sane(img, v);
}

// One-pixel and one-row viewports.
TEST(Degenerate, TinyViewports) {
  for (auto [w, h] : {std::pair{1, 1}, std::pair{1, 7}, std::pair{9, 1}}) {
    const view v(test_camera(w, h), vec3d::Zero());
    const image img = draw(v, {make_triangle({-100, -100, -2}, {100, -100, -2}, {0, 100, -2})},
                           {make_splat({0, 0, -3}, vec3f(0.5f, 0, 0), vec3f(0, 0.5f, 0))},
                           {make_point({0, 0, -1}, 1)});
    EXPECT_EQ(img.covered_count(), img.size());
    expect_sane(img, v);
  }
}

}  // namespace
}  // namespace pbr_lod
