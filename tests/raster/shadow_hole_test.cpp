// Shadows (two-pass shadow map, one-pass sink adapter) and hole filling (screen-space
// reconstruction).
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "pbr_lod/raster/one_pass_shadows.hpp"
#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {
namespace {

// --- shadows -----------------------------------------------------------------------------------

constexpr attributes N = with_normals;

void quad(auto& sink, vec3f a, vec3f b, vec3f c, vec3f d, vec3f n) {
  triangle_prim<N> t;
  t.normal = {n, n, n};
  t.p = {a, b, c};
  sink.triangle(t);
  t.p = {a, c, d};
  sink.triangle(t);
}

/// World point seen through pixel (x, y) at the depth the image stores.
vec3f world_at(const view& v, const image& img, int x, int y) {
  const float z = img.depth[img.index(x, y)];
  const float ex = (x + 0.5f - 0.5f * v.width) * z / v.focal_px;
  const float ey = (0.5f * v.height - (y + 0.5f)) * z / v.focal_px;
  return v.eye + v.right * ex + v.up * ey + v.forward * z;
}

// A ground plane y = 0 under a small square occluder (side 0.5 at height 0.5), lit along an
// oblique direction l: the shadow on the ground is the occluder's square shifted by
// −0.5·(l.x, l.z)/l.y. Ground points clearly inside it show ambient light only (200·0.15 = 30);
// ground points clearly outside are fully lit: 200·(0.15 + 0.85·n·l) — which also shows there is
// no self-shadowing ("acne") on the lit ground.
TEST(Shadows, OccluderCastsShadowWhereExpected) {
  for (const vec3f& light : {vec3f(0, 1, 0), vec3f(0.4f, 1, 0.25f)}) {
    camera c;
    c.eye = vec3d(0.3, 3, 2.5);
    c.target = vec3d(0, 0, 0);
    c.vp = {200, 160};
    c.z_near = 0.5;
    c.z_far = 20;
    const view v(c, vec3d::Zero());
    render_options opt;
    opt.fx = effects{.shading = true, .colour = false, .shadows = true};
    opt.sun.direction = light;
    opt.flat_colour = {200, 200, 200};
    const image img = render<N>(v, opt, [](auto& sink) {
      quad(sink, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, {-2, 0, -2}, vec3f::UnitY());
      quad(sink, {-0.25f, 0.5f, 0.25f}, {0.25f, 0.5f, 0.25f}, {0.25f, 0.5f, -0.25f},
           {-0.25f, 0.5f, -0.25f}, vec3f::UnitY());
    });
    const vec3f l = light.normalized();
    const vec2f shift = -0.5f / l.y() * vec2f(l.x(), l.z());
    const auto lit = static_cast<std::uint8_t>(200 * (0.15f + 0.85f * l.y()) + 0.5f);
    int in_shadow = 0, in_light = 0;
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x) {
        if (!img.covered(x, y)) continue;
        const vec3f p = world_at(v, img, x, y);
        if (std::abs(p.y()) > 1e-3f) continue;  // the occluder itself
        const float dx = std::abs(p.x() - shift.x()), dz = std::abs(p.z() - shift.y());
        const float m = 0.03f;  // texels of the 512² map are 0.008 wide; pixels ~0.02
        if (dx < 0.25f - m && dz < 0.25f - m) {
          ++in_shadow;
          EXPECT_EQ(img.at(x, y), (rgb8{30, 30, 30})) << x << "," << y;
        } else if (dx > 0.25f + m || dz > 0.25f + m) {
          ++in_light;
          EXPECT_EQ(img.at(x, y), (rgb8{lit, lit, lit})) << x << "," << y;
        }
      }
    EXPECT_GT(in_shadow, 200);
    EXPECT_GT(in_light, 5000);
  }
}

// Splats and points cast shadows too: a disk of splats above the ground darkens the ground
// right under it (light straight down).
TEST(Shadows, SplatsAndPointsCastShadows) {
  camera c;
  c.eye = vec3d(0, 3, 2);
  c.target = vec3d(0, 0, 0);
  c.vp = {120, 100};
  c.z_near = 0.5;
  c.z_far = 20;
  const view v(c, vec3d::Zero());
  render_options opt;
  opt.fx = effects{.shading = false, .colour = false, .shadows = true};
  opt.sun.direction = vec3f::UnitY();
  opt.flat_colour = {200, 200, 200};
  const image img = render<N>(v, opt, [](auto& sink) {
    quad(sink, {-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, {-2, 0, -2}, vec3f::UnitY());
    splat_prim<N> s{vec3f(-0.6f, 0.6f, 0), vec3f(0.3f, 0, 0), vec3f(0, 0, 0.3f)};
    s.normal = vec3f::UnitY();
    sink.splat(s);
    point_prim<N> p{vec3f(0.6f, 0.6f, 0), 12};
    p.normal = vec3f::UnitY();
    sink.point(p);
  });
  // Shadows without shading: lit pixels keep the flat colour, shadowed ones get ambient only.
  // The splat's shadow is its disk (radius 0.3) straight below: every ground pixel within 0.2 of
  // its centre is dark, and every one beyond 0.4 (and clear of the point's shadow) is lit. The
  // point's footprint in the shadow map is not a world-space size, so of its shadow only the
  // pixels nearest its centre are asked for, and only that some are dark.
  std::size_t under_splat = 0, dark_under_splat = 0, clear = 0;
  bool point_shadow = false;
  for (int y = 0; y < v.height; ++y)
    for (int x = 0; x < v.width; ++x) {
      if (!img.covered(x, y)) continue;
      const vec3f p = world_at(v, img, x, y);
      if (std::abs(p.y()) > 1e-3f) continue;
      const bool dark = img.at(x, y) == rgb8{30, 30, 30};
      const float to_splat = (p - vec3f(-0.6f, 0, 0)).norm();
      if (to_splat < 0.2f) {
        ++under_splat;
        dark_under_splat += dark;
      }
      if ((p - vec3f(0.6f, 0, 0)).norm() < 0.06f) point_shadow |= dark;
      if (to_splat > 0.4f && p.x() < 0.2f) {
        ++clear;
        EXPECT_EQ(img.at(x, y), (rgb8{200, 200, 200})) << x << "," << y;
      }
      if (std::abs(p.x()) > 1.2f) {
        EXPECT_EQ(img.at(x, y), (rgb8{200, 200, 200}));
      }
    }
  EXPECT_GT(under_splat, 50u);
  EXPECT_EQ(dark_under_splat, under_splat);
  EXPECT_GT(clear, 1000u);
  EXPECT_TRUE(point_shadow);
}

// --- one-pass shadows (raster/one_pass_shadows.hpp) ----------------------------------------------

/// Receives the shaded points: position and colour, in order.
struct shaded_points {
  std::vector<point_prim<attributes{.colour = true}>> out;
  void point(const point_prim<attributes{.colour = true}>& p) { out.push_back(p); }
  void splat(const splat_prim<attributes{.colour = true}>&) {}
  void triangle(const triangle_prim<attributes{.colour = true}>&) {}
};

/// Points on a grid of spacing h over [-half, half]² at height y, normal +y.
void plane_points(auto& sink, float y, float half, float h) {
  for (float x = -half; x <= half + 1e-4f; x += h)
    for (float z = -half; z <= half + 1e-4f; z += h) {
      point_prim<N> p{vec3f(x, y, z), 1.0f};
      p.normal = vec3f(0, 1, 0);
      sink.point(p);
    }
}

// A small square above a large one, light straight above. Sent front to back from the light (the
// small square first), the large square's points under the small one are shadowed — exactly
// those within the small square's extent, up to one footprint — and every other point is lit:
// shaded white × ambient or white × Lambert (1, the normal faces the light). Sent back to front,
// nothing can be shadowed yet when the large square arrives: the adapter depends on the order, as
// the method does.
TEST(OnePassShadows, SquareShadowsThePlaneBelowWhenDrawnFirst) {
  const view v(camera::orbit(vec3d::Zero(), 2, 0, 60, 3, 1, {64, 64}), vec3d::Zero());
  render_options o;
  o.flat_colour = {200, 200, 200};
  o.sun = {vec3f(0, 1, 0), 0.25f};
  o.shadow_map_size = 512;
  const float h = 0.05f, r = h * 1.3f;  // footprint r/√3 ≈ 0.75 h: the points close the surface
  const sphere bounds{vec3f::Zero(), 2};
  for (const bool front_to_back : {true, false}) {
    shaded_points inner;
    one_pass_shadow_sink<N, shaded_points> shade(v, o, vec3f(0, 1, 0), bounds, inner);
    shade.node_radius(r);
    if (front_to_back) plane_points(shade, 1, 0.5f, h);
    plane_points(shade, 0, 1, h);
    if (!front_to_back) plane_points(shade, 1, 0.5f, h);
    std::size_t checked = 0;
    for (const auto& p : inner.out) {
      const bool under = p.position.y() < 0.5f && std::abs(p.position.x()) < 0.5f - r &&
                         std::abs(p.position.z()) < 0.5f - r;
      const bool clear = p.position.y() > 0.5f || std::abs(p.position.x()) > 0.5f + r ||
                         std::abs(p.position.z()) > 0.5f + r;
      const std::uint8_t lit = 200, dark = 50;  // 200 × 1, 200 × 0.25
      if (under && front_to_back) {
        EXPECT_EQ(p.colour.r, dark) << p.position.transpose();
        ++checked;
      } else if (clear || !front_to_back) {
        EXPECT_EQ(p.colour.r, lit) << p.position.transpose();
        ++checked;
      }
    }
    EXPECT_GT(checked, 800u);
    EXPECT_EQ(shade.stats().lit + shade.stats().shadowed, inner.out.size());
    EXPECT_EQ(shade.stats().shadowed > 0, front_to_back);
  }
}

// --- hole filling ------------------------------------------------------------------------------

camera front_camera() {
  camera c;
  c.eye = vec3d::Zero();
  c.target = vec3d(0, 0, -1);
  c.vp = {96, 80};
  c.z_near = 0.1;
  c.z_far = 10;
  return c;
}

/// A square point of side `side` px whose projection is pixel position (sx, sy), at depth z.
point_prim<positions_only> square_at(const view& v, float sx, float sy, float z, float side) {
  const float x = (sx - 0.5f * v.width) * z / v.focal_px,
              y = (0.5f * v.height - sy) * z / v.focal_px;
  return {vec3f(x, y, -z), side};
}

/// A plane at depth 2 splatted with 4-px squares over columns [20, 48) and, when `gap`, [49, 77)
/// (column 48 left empty), else [48, 76); rows [20, 60).
image splatted_plane(bool gap, effects fx, int radius = 3) {
  const view v(front_camera(), vec3d::Zero());
  render_options opt;
  opt.fx = fx;
  opt.hole_filling_radius = radius;
  return render<positions_only>(v, opt, [&](auto& sink) {
    for (int j = 0; j < 10; ++j) {
      for (int i = 0; i < 7; ++i) sink.point(square_at(v, 22.0f + 4 * i, 22.0f + 4 * j, 2, 4));
      for (int i = 0; i < 7; ++i)
        sink.point(square_at(v, (gap ? 51.0f : 50.0f) + 4 * i, 22.0f + 4 * j, 2, 4));
    }
  });
}

// A one-pixel column missing in a splatted plane is filled from both sides (all 8 sectors see
// covered pixels), with the plane's colour and depth — except at its two ends, which look like
// a notch in the silhouette (5 sectors) and stay open.
TEST(HoleFilling, FillsOnePixelGap) {
  const effects holes{.colour = false, .hole_filling = true};
  const image before = splatted_plane(true, no_effects);
  const image after = splatted_plane(true, holes);
  for (int y = 20; y < 60; ++y) ASSERT_FALSE(before.covered(48, y)) << y;
  for (int y = 21; y < 59; ++y) {
    ASSERT_TRUE(after.covered(48, y)) << y;
    EXPECT_EQ(after.at(48, y), before.at(47, y));
    EXPECT_NEAR(after.depth[after.index(48, y)], before.depth[before.index(47, y)], 1e-6f);
  }
  EXPECT_FALSE(after.covered(48, 20));
  EXPECT_FALSE(after.covered(48, 59));
  EXPECT_EQ(after.covered_count(), before.covered_count() + 38);
}

// Hole filling does not grow silhouettes: a closed rectangle (straight edges), and a large
// ellipse and a triangle (curved and diagonal edges: a pixel outside a convex shape sees it within
// less than 180°, so in at most 5 of the 8 sectors), come out exactly as without it.
TEST(HoleFilling, DoesNotGrowSilhouettes) {
  const effects holes{.colour = false, .hole_filling = true};
  EXPECT_EQ(splatted_plane(false, holes), splatted_plane(false, no_effects));
  const view v(front_camera(), vec3d::Zero());
  const auto shapes = [&](effects fx, int radius) {
    render_options opt;
    opt.fx = fx;
    opt.hole_filling_radius = radius;
    return render<positions_only>(v, opt, [&](auto& sink) {
      // Far enough apart (≥ 15 px) that no background pixel sees both within radius 6.
      sink.splat(splat_prim<positions_only>{vec3f(-0.5f, 0.1f, -2), vec3f(0.3f, 0.2f, 0),
                                            vec3f(-0.1f, 0.15f, 0.1f)});
      triangle_prim<positions_only> t;
      t.p = {vec3f(0.35f, -0.5f, -2), vec3f(0.95f, -0.3f, -2.5f), vec3f(0.5f, 0.6f, -2.2f)};
      sink.triangle(t);
    });
  };
  for (int radius : {1, 3, 6})
    EXPECT_EQ(shapes(holes, radius), shapes(no_effects, radius)) << radius;
}

// Geometry far behind a hole does not fill it: only neighbours near the front-most depth count.
// A gap in a plane at depth 2 with, within the window, a far plane at depth 6 visible below the
// near one: the gap is filled with the near plane's colour, never the far one's.
TEST(HoleFilling, BackgroundGeometryDoesNotBleed) {
  constexpr attributes C{.colour = true};
  const view v(front_camera(), vec3d::Zero());
  render_options opt;
  opt.fx = effects{.colour = true, .hole_filling = true};
  const auto square = [&](float sx, float sy, float z, rgb8 col) {
    const auto p = square_at(v, sx, sy, z, 4);
    point_prim<C> q{p.position, p.size_px};
    q.colour = col;
    return q;
  };
  const image img = render<C>(v, opt, [&](auto& sink) {
    for (int j = 0; j < 5; ++j) {
      for (int i = 0; i < 4; ++i) sink.point(square(22.0f + 4 * i, 22.0f + 4 * j, 2, {255, 0, 0}));
      for (int i = 0; i < 4; ++i) sink.point(square(39.0f + 4 * i, 22.0f + 4 * j, 2, {255, 0, 0}));
      // The far plane right below, rows [40, 60).
      for (int i = 0; i < 9; ++i) sink.point(square(22.0f + 4 * i, 42.0f + 4 * j, 6, {0, 0, 255}));
    }
  });
  for (int y = 21; y < 40; ++y)
    if (img.covered(36, y)) {
      EXPECT_EQ(img.at(36, y), (rgb8{255, 0, 0})) << y;
    }
  EXPECT_TRUE(img.covered(36, 30));
}

}  // namespace
}  // namespace pbr_lod
