// Effects: an effect compiled out gives the same bytes as the effect switched off at run time,
// every effect is visible when on, and shading follows Lambert's law (two-sided, only with
// normals).
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>
#include <vector>

#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {
namespace {

constexpr attributes A = with_normals_colours;

/// A small scene that exercises every effect: a ground quad (triangles, vertex colours), a
/// sphere of splats floating above it (shadow on the ground), points, a quad and a splat patch
/// turned away from the eye (culling), and a sparse splat patch with gaps (hole filling).
struct scene {
  std::vector<triangle_prim<A>> tris;
  std::vector<splat_prim<A>> splats;
  std::vector<point_prim<A>> points;

  scene() {
    const auto quad = [&](vec3f a, vec3f b, vec3f c, vec3f d, vec3f n, rgb8 c0, rgb8 c1) {
      triangle_prim<A> t;
      t.p = {a, b, c};
      t.normal = {n, n, n};
      t.colour = {c0, c1, c1};
      tris.push_back(t);
      t.p = {a, c, d};
      t.colour = {c0, c1, c0};
      tris.push_back(t);
    };
    // Ground y = 0, counter-clockwise seen from above.
    quad({-2, 0, 2}, {2, 0, 2}, {2, 0, -2}, {-2, 0, -2}, vec3f::UnitY(), {180, 160, 120},
         {120, 170, 90});
    // A wall at x = −1.2 whose front (counter-clockwise side) faces −x, away from the eye (which
    // is at x = 0.5).
    quad({-1.2f, 0, -1}, {-1.2f, 0, 0.5f}, {-1.2f, 0.8f, 0.5f}, {-1.2f, 0.8f, -1}, -vec3f::UnitX(),
         {90, 90, 200}, {90, 200, 200});
    // Sphere of splats (Fibonacci lattice), centre (0, 0.8, 0), radius 0.45.
    const int n = 1500;
    const float golden = std::numbers::pi_v<float> * (3 - std::sqrt(5.0f));
    for (int i = 0; i < n; ++i) {
      const float y = 1 - 2 * (float(i) + 0.5f) / n, r = std::sqrt(1 - y * y);
      const vec3f dir(r * std::cos(golden * float(i)), y, r * std::sin(golden * float(i)));
      splat_prim<A> s;
      s.centre = vec3f(0, 0.8f, 0) + 0.45f * dir;
      s.u = any_orthogonal(dir) * 0.035f;
      s.v = dir.cross(s.u);
      s.normal = dir;
      s.colour = {uint8_t(150 + 100 * dir.x() * dir.x()), 60, uint8_t(100 + 100 * y * y)};
      splats.push_back(s);
    }
    // A sparse patch of splats on the plane z = −1.5 facing +z (the eye): gaps between them.
    for (int j = 0; j < 14; ++j)
      for (int i = 0; i < 14; ++i) {
        splat_prim<A> s;
        s.centre = vec3f(0.6f + 0.05f * float(i), 0.1f + 0.05f * float(j), -1.5f);
        s.u = vec3f(0.018f, 0, 0);
        s.v = vec3f(0, 0.018f, 0);
        s.normal = vec3f::UnitZ();
        s.colour = {220, 220, 60};
        splats.push_back(s);
        // The same patch's twin facing away from the eye, behind the wall.
        s.centre.x() -= 2.6f;
        s.normal = -vec3f::UnitZ();
        splats.push_back(s);
      }
    // A row of points with normals, half of them facing away.
    for (int i = 0; i < 40; ++i) {
      point_prim<A> p;
      p.position = vec3f(-1 + 0.05f * float(i), 0.05f, 1.2f);
      p.size_px = 2;
      p.normal = (i % 2) ? vec3f(vec3f::UnitZ()) : vec3f(-vec3f::UnitZ());
      p.colour = {255, 255, 255};
      points.push_back(p);
    }
  }

  template <class S>
  void operator()(S& sink) const {
    for (const auto& t : tris) sink.triangle(t);
    for (const auto& s : splats) sink.splat(s);
    for (const auto& p : points) sink.point(p);
  }
};

view test_view(int w = 160, int h = 120) {
  camera c;
  c.eye = vec3d(0.5, 2.2, 3.6);
  c.target = vec3d(0, 0.4, 0);
  c.vp = {w, h};
  c.z_near = 0.5;
  c.z_far = 20;
  return view(c, vec3d::Zero());
}

render_options test_options(effects fx) {
  render_options opt;
  opt.fx = fx;
  opt.sun.direction = vec3f(0.3f, 1.0f, 0.2f);
  opt.background = {10, 20, 30};
  opt.shadow_map_size = 512;
  return opt;
}

/// X compiled out ≡ X switched off at run time, and X on changes the image.
template <effects X>
void check_effect(const char* name) {
  const view v = test_view();
  const scene s;
  constexpr effects without = all_effects - X;
  const image runtime_off = render<A, all_effects>(v, test_options(without), s);
  const image compiled_out = render<A, without>(v, test_options(all_effects), s);
  EXPECT_EQ(runtime_off, compiled_out) << name;
  const image on = render<A, all_effects>(v, test_options(all_effects), s);
  EXPECT_NE(on, runtime_off) << name << " has no visible effect in the test scene";
  // The effect alone: compiled as the only effect, or selected at run time among all.
  const image only = render<A, X>(v, test_options(all_effects), s);
  EXPECT_EQ(only, (render<A, all_effects>(v, test_options(X), s))) << name;
  EXPECT_NE(only, (render<A, all_effects>(v, test_options(no_effects), s))) << name;
}

// Each effect, one at a time (with all the others on): byte-for-byte equality of the two ways of
// turning it off. This is the "an unused effect costs nothing and changes nothing" contract.
TEST(Effects, CompiledOutEqualsSwitchedOffShading) {
  check_effect<effects{.shading = true, .colour = false}>("shading");
}
TEST(Effects, CompiledOutEqualsSwitchedOffColour) {
  check_effect<effects{.shading = false, .colour = true}>("colour");
}
TEST(Effects, CompiledOutEqualsSwitchedOffBackfaceCull) {
  check_effect<effects{.colour = false, .backface_cull = true}>("backface_cull");
}
TEST(Effects, CompiledOutEqualsSwitchedOffShadows) {
  check_effect<effects{.colour = false, .shadows = true}>("shadows");
}
TEST(Effects, CompiledOutEqualsSwitchedOffHoleFilling) {
  check_effect<effects{.colour = false, .hole_filling = true}>("hole_filling");
}

// Blending needs colour or shading to have anything to average, so the "alone" half of
// check_effect is done with colour: blending + colour differs from colour alone.
TEST(Effects, CompiledOutEqualsSwitchedOffBlending) {
  const view v = test_view();
  const scene s;
  constexpr effects X{.colour = false, .blending = true};
  constexpr effects without = all_effects - X;
  const image runtime_off = render<A, all_effects>(v, test_options(without), s);
  EXPECT_EQ(runtime_off, (render<A, without>(v, test_options(all_effects), s)));
  EXPECT_NE((render<A, all_effects>(v, test_options(all_effects), s)), runtime_off);
  constexpr effects colour_blend{.colour = true, .blending = true};
  const image only = render<A, colour_blend>(v, test_options(all_effects), s);
  EXPECT_EQ(only, (render<A, all_effects>(v, test_options(colour_blend), s)));
  EXPECT_NE(only, (render<A, all_effects>(v, test_options(effects{.colour = true}), s)));
  // Without colour and shading there is nothing to blend: the effect is dropped, not run.
  static_assert(!rasterizer<positions_only, X>::fx.blending);
}

// Nothing compiled in ignores every run-time request.
TEST(Effects, NothingCompiledIgnoresRequests) {
  const view v = test_view();
  const scene s;
  EXPECT_EQ((render<A, no_effects>(v, test_options(all_effects), s)),
            (render<A, all_effects>(v, test_options(no_effects), s)));
}

// Lambert with a directional light: a triangle facing +y under a light along (1, 1, 0) gets
// ambient + (1 − ambient)·cos 45° of its colour: 200·(0.15 + 0.85·0.7071) = 150.2 → 150.
TEST(Effects, LambertShadingValue) {
  constexpr attributes B = with_normals;
  const view v = test_view(64, 48);
  render_options opt = test_options(effects{.shading = true});
  opt.sun.direction = vec3f(1, 1, 0);
  opt.flat_colour = {200, 200, 200};
  const image img = render<B>(v, opt, [&](auto& sink) {
    triangle_prim<B> t;
    t.p = {vec3f(-3, 0, 3), vec3f(3, 0, 3), vec3f(0, 0, -3)};
    t.normal = {vec3f::UnitY(), vec3f::UnitY(), vec3f::UnitY()};
    sink.triangle(t);
  });
  const rgb8 c = img.at(32, 36);
  ASSERT_TRUE(img.covered(32, 36));
  EXPECT_EQ(c, (rgb8{150, 150, 150}));
}

// Two-sided: a splat seen from the side its normal points away from is lit like the same splat
// with the normal flipped (the side the eye sees is the lit one). Equality alone would also hold
// for a rasteriser that lit the hidden side both times, so the value is checked too: the normal
// u × v = (0, 1, 1)/√2 faces the eye at (0.5, 2.2, 3.6), and with the light along (0.3, 1, 0.2)
// the lit side gets 200·(0.15 + 0.85·(1.2/√2)/√1.13) = 200·0.8285 = 165.7 → 166; the hidden side
// would get ambient only (n·l < 0): 30.
TEST(Effects, TwoSidedSplatShading) {
  constexpr attributes B = with_normals;
  const view v = test_view(64, 48);
  render_options opt = test_options(effects{.shading = true});
  opt.flat_colour = {200, 200, 200};
  const auto draw = [&](vec3f n) {
    return render<B>(v, opt, [&](auto& sink) {
      splat_prim<B> s{vec3f(0, 0.4f, 0), vec3f(0.5f, 0, 0), vec3f(0, 0.3f, -0.3f)};
      s.normal = n;
      sink.splat(s);
    });
  };
  const vec3f n = vec3f(0.5f, 0, 0).cross(vec3f(0, 0.3f, -0.3f)).normalized();
  ASSERT_GT(n.dot(v.eye - vec3f(0, 0.4f, 0)), 0) << "n is the side the eye sees";
  const image img = draw(n);
  EXPECT_EQ(img, draw(-n));
  EXPECT_GT(img.covered_count(), 100u);
  for (std::size_t i = 0; i < img.size(); ++i)
    if (img.covered(i)) {
      ASSERT_EQ(img.colour[i], (rgb8{166, 166, 166})) << i;
    }
}

// Shading needs normals: with positions and colours only, asking for shading changes nothing,
// and colours come through unmodified.
TEST(Effects, NoShadingWithoutNormals) {
  constexpr attributes B{.colour = true};
  const view v = test_view(64, 48);
  const auto draw = [&](effects fx) {
    return render<B>(v, test_options(fx), [&](auto& sink) {
      triangle_prim<B> t;
      t.p = {vec3f(-3, 0, 3), vec3f(3, 0, 3), vec3f(0, 0, -3)};
      t.colour = {rgb8{90, 100, 110}, rgb8{90, 100, 110}, rgb8{90, 100, 110}};
      sink.triangle(t);
    });
  };
  const image lit = draw(effects{.shading = true, .colour = true});
  EXPECT_EQ(lit, draw(effects{.shading = false, .colour = true}));
  EXPECT_EQ(lit.at(32, 36), (rgb8{90, 100, 110}));
}

// Without the colour effect every primitive takes flat_colour; with it, its own colour.
TEST(Effects, FlatColourWhenColourOff) {
  constexpr attributes B{.colour = true};
  const view v = test_view(64, 48);
  const auto draw = [&](effects fx) {
    render_options opt = test_options(fx);
    opt.flat_colour = {1, 2, 3};
    return render<B>(v, opt, [&](auto& sink) {
      point_prim<B> p{vec3f(0, 0.4f, 0), 5};
      p.colour = {200, 100, 50};
      sink.point(p);
    });
  };
  const image on = draw(effects{.colour = true}), off = draw(no_effects);
  ASSERT_EQ(on.covered_count(), 25u);
  for (std::size_t i = 0; i < on.size(); ++i)
    if (on.covered(i)) {
      EXPECT_EQ(on.colour[i], (rgb8{200, 100, 50}));
      EXPECT_EQ(off.colour[i], (rgb8{1, 2, 3}));
    }
}

// Back-face culling of points and splats uses their normals: n·(p − eye) > 0 is culled.
TEST(Effects, BackfaceCullingOfSplatsAndPoints) {
  constexpr attributes B = with_normals;
  const view v = test_view(64, 48);
  const vec3f to_eye = (v.eye - vec3f(0, 0.4f, 0)).normalized();
  const auto draw = [&](vec3f n, effects fx) {
    return render<B>(v, test_options(fx), [&](auto& sink) {
      point_prim<B> p{vec3f(0, 0.4f, 0), 3};
      p.normal = n;
      sink.point(p);
      splat_prim<B> s{vec3f(0.5f, 0.4f, 0), any_orthogonal(n) * 0.2f,
                      n.cross(any_orthogonal(n)) * 0.2f};
      s.normal = n;
      sink.splat(s);
    });
  };
  const effects cull{.colour = false, .backface_cull = true};
  EXPECT_EQ(draw(-to_eye, cull).covered_count(), 0u);
  EXPECT_GT(draw(to_eye, cull).covered_count(), 9u);
  EXPECT_EQ(draw(-to_eye, no_effects), draw(to_eye, no_effects));
}

// parse_effects understands the tool's --effects list.
TEST(Effects, Parse) {
  EXPECT_EQ(parse_effects("shading,shadows"),
            (effects{.shading = true, .colour = false, .shadows = true}));
  EXPECT_EQ(parse_effects("all"), all_effects);
  EXPECT_EQ(parse_effects("none"), no_effects);
  EXPECT_EQ(parse_effects("colour+holes").to_string(), "colour+hole_filling");
  EXPECT_EQ(parse_effects("colour,blend"), (effects{.colour = true, .blending = true}));
  EXPECT_EQ(parse_effects("blending").to_string(), "blending");
  EXPECT_THROW((void)parse_effects("sparkles"), InvalidArgument);
}

}  // namespace
}  // namespace pbr_lod
