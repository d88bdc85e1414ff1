// Splat blending (effects::blending): overlapping splats average with weight 1 − r², a splat
// more than ε behind another stays hidden, blending off leaves today's bytes, and on a sampled
// surface with smooth colour the blended splats come closer to the mesh they were sampled from.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"

namespace pbr_lod {
namespace {

constexpr attributes C = attributes{.colour = true};

// --- random scene (begin): also compiled against the rasteriser before blending existed, to
// record the hashes below.

/// Seeded random mix of every primitive kind with normals and colours: splats (elliptical and
/// circular, at random orientations), points of 1–4 px and triangles, in a box in front of the
/// camera. Random input is fine: the test compares two renders of the same primitives.
buffer_sink<with_normals_colours> random_scene() {
  constexpr attributes A = with_normals_colours;
  std::mt19937 rng(42);
  std::uniform_real_distribution<float> pos(-1, 1), size(0.02f, 0.15f), unit(0, 1);
  const auto colour = [&] {
    return rgb8{std::uint8_t(rng() % 256), std::uint8_t(rng() % 256), std::uint8_t(rng() % 256)};
  };
  const auto direction = [&] {
    vec3f d(pos(rng), pos(rng), pos(rng));
    return d.squaredNorm() > 1e-4f ? vec3f(d.normalized()) : vec3f(vec3f::UnitZ());
  };
  buffer_sink<A> s;
  for (int i = 0; i < 600; ++i) {
    const int kind = static_cast<int>(rng() % 3);
    if (kind == 0) {
      splat_prim<A> p;
      p.centre = vec3f(pos(rng), pos(rng), pos(rng));
      p.normal = direction();
      p.u = any_orthogonal(p.normal) * size(rng);
      p.v = p.normal.cross(p.u).normalized() * (unit(rng) < 0.5f ? p.u.norm() : size(rng));
      p.colour = colour();
      s.splat(p);
    } else if (kind == 1) {
      point_prim<A> p;
      p.position = vec3f(pos(rng), pos(rng), pos(rng));
      p.size_px = 1 + 3 * unit(rng);
      p.normal = direction();
      p.colour = colour();
      s.point(p);
    } else {
      triangle_prim<A> t;
      const vec3f c(pos(rng), pos(rng), pos(rng));
      for (std::size_t k = 0; k < 3; ++k) {
        t.p[k] = c + 0.2f * vec3f(pos(rng), pos(rng), pos(rng));
        t.normal[k] = direction();
        t.colour[k] = colour();
      }
      s.triangle(t);
    }
  }
  return s;
}

view scene_view(int w = 96, int h = 80) {
  camera c;
  c.eye = vec3d(0.4, 0.9, 3.2);
  c.target = vec3d::Zero();
  c.vp = {w, h};
  c.z_near = 0.5;
  c.z_far = 20;
  return view(c, vec3d::Zero());
}

render_options scene_options(effects fx) {
  render_options opt;
  opt.fx = fx;
  opt.sun.direction = vec3f(0.3f, 1.0f, 0.2f);
  opt.background = {10, 20, 30};
  opt.shadow_map_size = 256;
  return opt;
}

/// FNV-1a over the colours and the depth bits.
std::uint64_t image_hash(const image& img) {
  std::uint64_t h = 1469598103934665603ull;
  const auto add = [&](const void* p, std::size_t n) {
    const auto* b = static_cast<const unsigned char*>(p);
    for (std::size_t i = 0; i < n; ++i) h = (h ^ b[i]) * 1099511628211ull;
  };
  for (const rgb8& c : img.colour) add(&c, sizeof c);
  for (const float d : img.depth) {
    std::uint32_t bits;
    std::memcpy(&bits, &d, sizeof bits);
    add(&bits, sizeof bits);
  }
  return h;
}

// --- random scene (end)

camera front_camera(int size) {
  camera c;
  c.eye = vec3d(0, 0, 5);
  c.target = vec3d::Zero();
  c.vp = {size, size};
  c.z_near = 1;
  c.z_far = 20;
  return c;
}

/// A disk of radius r centred at (x, y, z) facing the camera (+z).
splat_prim<C> disk(float x, float y, float z, float r, rgb8 colour) {
  splat_prim<C> s;
  s.centre = vec3f(x, y, z);
  s.u = vec3f(r, 0, 0);
  s.v = vec3f(0, r, 0);
  s.colour = colour;
  return s;
}

image draw_disks(const std::vector<splat_prim<C>>& disks, bool blend, int size = 65) {
  render_options opt;
  opt.fx = effects{.colour = true, .blending = blend};
  const view v(front_camera(size), vec3d::Zero());
  return render<C>(v, opt, [&](auto& sink) {
    for (const auto& d : disks) sink.splat(d);
  });
}

/// The point of the plane z = z0 seen through the centre of pixel (i, j): the ray eye + z·(forward
/// + right·(x − cx)/f − up·(y − cy)/f) of the rasteriser's projection, for the camera at
/// (0, 0, 5) looking down −z (right = +x, up = +y).
vec3d plane_point(const view& v, int i, int j, double z0) {
  const double f = v.focal_px, cx = 0.5 * v.width, cy = 0.5 * v.height;
  const double depth = 5 - z0;
  return {depth * (i + 0.5 - cx) / f, -depth * (j + 0.5 - cy) / f, z0};
}

/// 1 − |p − c|²/r²: the weight the rasteriser gives a disk at the plane point p.
double weight(const vec3d& p, double cx, double cy, double r) {
  const double dx = p.x() - cx, dy = p.y() - cy;
  return 1 - (dx * dx + dy * dy) / (r * r);
}

// Two disks of radius 0.5 at x = ∓0.2, both in the plane z = 0: at a pixel both cover, the
// colour is (w_A·A + w_B·B)/(w_A + w_B) with w = 1 − r²/R². At the centre pixel (65 px: its
// ray is the axis) r_A = r_B = 0.2, so both weights are 1 − 0.16/0.25 = 0.36 and the colour is
// the plain mean (100, 50, 125). Elsewhere the weights come from the pixel's plane point.
TEST(Blending, OverlapIsWeightedMean) {
  const rgb8 a{200, 0, 0}, b{0, 100, 250};
  const std::vector<splat_prim<C>> disks = {disk(-0.2f, 0, 0, 0.5f, a), disk(0.2f, 0, 0, 0.5f, b)};
  const image img = draw_disks(disks, true);
  const view v(front_camera(65), vec3d::Zero());
  const auto at = [&](int i, int j) { return img.colour[std::size_t(j) * 65 + std::size_t(i)]; };
  EXPECT_EQ(at(32, 32), (rgb8{100, 50, 125}));
  int checked = 0;
  for (int j = 20; j <= 44; j += 2)
    for (int i = 16; i <= 48; ++i) {
      const vec3d p = plane_point(v, i, j, 0);
      const double wa = weight(p, -0.2, 0, 0.5), wb = weight(p, 0.2, 0, 0.5);
      if (!(wa > 0.01 && wb > 0.01)) continue;  // both disks must cover it, well inside
      const double s = wa + wb;
      const rgb8 got = at(i, j);
      EXPECT_NEAR(got.r, (wa * a.r + wb * b.r) / s, 0.51) << i << "," << j;
      EXPECT_NEAR(got.g, (wa * a.g + wb * b.g) / s, 0.51) << i << "," << j;
      EXPECT_NEAR(got.b, (wa * a.b + wb * b.b) / s, 0.51) << i << "," << j;
      ++checked;
    }
  EXPECT_GT(checked, 40);
  // Pixels only one disk covers keep its colour: left of the overlap.
  const vec3d p = plane_point(v, 26, 32, 0);
  ASSERT_LT(weight(p, 0.2, 0, 0.5), 0);
  EXPECT_EQ(at(26, 32), a);
  // Without blending one disk wins where both are at the same depth: the test scene does tell
  // blending from no blending.
  const rgb8 unblended = draw_disks(disks, false).colour[32 * 65 + 32];
  EXPECT_TRUE(unblended == a || unblended == b);
}

// Occlusion is kept: with ε = 1 radius (0.5), a disk 0.6 behind another is hidden wherever the
// front one covers; one 0.3 behind lies within ε of the front surface and is blended. Both draw
// orders give the same image: the accumulation does not depend on order beyond float sums, and
// here the weights are exact.
TEST(Blending, SplatBeyondEpsilonIsHidden) {
  const rgb8 a{200, 0, 0}, b{0, 100, 250};
  const view v(front_camera(65), vec3d::Zero());
  for (const bool front_first : {true, false}) {
    const splat_prim<C> front = disk(0, 0, 0, 0.5f, a);
    const splat_prim<C> far = disk(0, 0, -0.6f, 0.5f, b), near = disk(0, 0, -0.3f, 0.5f, b);
    const auto order = [&](const splat_prim<C>& back) {
      return front_first ? std::vector{front, back} : std::vector{back, front};
    };
    const image hidden = draw_disks(order(far), true);
    const image blended = draw_disks(order(near), true);
    // Every pixel the front disk covers is exactly A when the other is beyond ε.
    std::size_t front_pixels = 0;
    for (int j = 0; j < 65; ++j)
      for (int i = 0; i < 65; ++i) {
        if (weight(plane_point(v, i, j, 0), 0, 0, 0.5) <= 0.02) continue;
        ++front_pixels;
        EXPECT_EQ(hidden.colour[std::size_t(j) * 65 + std::size_t(i)], a) << i << "," << j;
      }
    EXPECT_GT(front_pixels, 200u);  // a disk of ≈ 9 px radius
    // Within ε: the centre pixel sees both disks' centres (w = 1 each): the plain mean.
    EXPECT_EQ(blended.colour[32 * 65 + 32], (rgb8{100, 50, 125})) << front_first;
    // The depth is the front disk's (5 from the eye), not the offset visibility depth.
    EXPECT_NEAR(blended.depth[32 * 65 + 32], 5.0f, 1e-4f);
  }
}

// The two sides of a part thinner than ε are not averaged: a disk facing the eye and one 0.01
// behind it facing away (a fin, a thin slab) give the front colour; seen from behind (the normals
// flipped), the other one. Without the facing rule the centre pixel would be the mean.
TEST(Blending, FacingSideWinsOverBackSide) {
  constexpr attributes N = with_normals_colours;
  const rgb8 a{200, 0, 0}, b{0, 100, 250};
  const auto make = [](float z, vec3f n, rgb8 c) {
    splat_prim<N> s;
    s.centre = vec3f(0, 0, z);
    s.u = vec3f(0.5f, 0, 0);
    s.v = vec3f(0, 0.5f, 0);
    s.normal = n;
    s.colour = c;
    return s;
  };
  render_options opt;
  opt.fx = effects{.colour = true, .blending = true};
  const view v(front_camera(65), vec3d::Zero());
  for (const float facing : {1.0f, -1.0f}) {
    const splat_prim<N> front = make(0, facing * vec3f::UnitZ(), a);
    const splat_prim<N> back = make(-0.01f, -facing * vec3f::UnitZ(), b);
    const image img = render<N>(v, opt, [&](auto& sink) {
      sink.splat(back);
      sink.splat(front);
    });
    EXPECT_EQ(img.colour[32 * 65 + 32], facing > 0 ? a : b) << facing;
  }
}

// Blending off is today's rasteriser: the random scene hashes to the values recorded with the
// rasteriser before blending existed (commit 62f0d39; checked on x86-64, where they were
// recorded: the build turns FMA contraction off, but another target's libm or SIMD path is not
// ours to promise), and compiling blending in but switching it off gives the same bytes as
// compiling it out, for every other effect set tried.
TEST(Blending, OffIsBitIdentical) {
  constexpr attributes A = with_normals_colours;
  const buffer_sink<A> s = random_scene();
  const view v = scene_view();
  struct expected {
    effects fx;
    std::uint64_t hash;
  };
  const expected cases[] = {
      {effects{.colour = false}, 0x5c85ea1bc76cc1a5ull},
      {effects{.colour = true}, 0xc2c097c4ca6fd13aull},
      {effects{.shading = true, .colour = true}, 0x998e92b9bc620c0bull},
      {effects{.shading = true,
               .colour = true,
               .backface_cull = true,
               .shadows = true,
               .hole_filling = true},
       0x22a88f4ec710de13ull},
  };
  constexpr effects without = all_effects - effects{.colour = false, .blending = true};
  for (const expected& e : cases) {
    const image compiled_in = render_buffered<A, all_effects>(v, scene_options(e.fx), s);
    const image compiled_out = render_buffered<A, without>(v, scene_options(e.fx), s);
    EXPECT_GT(compiled_in.covered_count(), 1000u);
    EXPECT_EQ(compiled_in, compiled_out) << e.fx.to_string();
#if defined(__x86_64__)
    EXPECT_EQ(image_hash(compiled_in), e.hash) << e.fx.to_string();
#endif
  }
  // And blending on does change this scene.
  effects on = cases[3].fx;
  on.blending = true;
  EXPECT_NE(render_buffered<A>(v, scene_options(on), s),
            render_buffered<A>(v, scene_options(cases[3].fx), s));
}

/// UV sphere of radius 1 about the origin with radial normals and a smooth colour gradient
/// (each channel affine in one coordinate): nothing in it is sharper than the sampling, so the
/// error of a splat render is the splats' own (their flat colour and facets).
triangle_mesh gradient_sphere(int rings, int segments) {
  triangle_mesh m;
  auto& p = m.vertices.positions;
  const auto add = [&](const vec3f& q) {
    p.push_back(q);
    m.vertices.normals.push_back(q);
    m.vertices.colours.push_back({std::uint8_t(128 + 110 * q.x()), std::uint8_t(128 + 110 * q.y()),
                                  std::uint8_t(128 + 110 * q.z())});
  };
  add(vec3f(0, 1, 0));
  for (int i = 1; i < rings; ++i) {
    const float th = std::numbers::pi_v<float> * float(i) / float(rings);
    for (int j = 0; j < segments; ++j) {
      const float ph = 2 * std::numbers::pi_v<float> * float(j) / float(segments);
      add(vec3f(std::sin(th) * std::cos(ph), std::cos(th), -std::sin(th) * std::sin(ph)));
    }
  }
  add(vec3f(0, -1, 0));
  const auto ring = [&](int i, int j) {
    return std::uint32_t(1 + (i - 1) * segments + (j % segments));
  };
  const auto last = std::uint32_t(p.size() - 1);
  for (int j = 0; j < segments; ++j) {
    m.faces.push_back({0, ring(1, j), ring(1, j + 1)});
    m.faces.push_back({last, ring(rings - 1, j + 1), ring(rings - 1, j)});
    for (int i = 1; i + 1 < rings; ++i) {
      m.faces.push_back({ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)});
      m.faces.push_back({ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)});
    }
  }
  return m;
}

// Samples of a smoothly coloured, shaded sphere drawn as splats come closer to the mesh render
// with blending than without: each unblended splat shows its own flat colour and shade, so the
// image is a mosaic with steps at every splat boundary; blending interpolates across them.
TEST(Blending, SampledSphereCloserToMesh) {
  const triangle_mesh m = gradient_sphere(90, 180);
  const point_cloud pts = sample_surface(m, 6000, 7);
  const camera cam = camera::orbit(vec3d::Zero(), 1, 30, 20, 3, 1, {256, 256});
  render_options opt;
  opt.fx = effects{.shading = true, .colour = true};
  const image mesh_img = render_reference(m, cam, opt);
  const image plain = render_reference(pts, cam, opt);
  opt.fx.blending = true;
  const image blended = render_reference(pts, cam, opt);
  const image_error e_plain = compare_images(mesh_img, plain);
  const image_error e_blend = compare_images(mesh_img, blended);
  RecordProperty("psnr_plain", std::to_string(e_plain.psnr));
  RecordProperty("psnr_blended", std::to_string(e_blend.psnr));
  std::printf("sampled sphere vs mesh: %.2f dB plain, %.2f dB blended\n", e_plain.psnr,
              e_blend.psnr);
  EXPECT_GT(e_blend.psnr, e_plain.psnr + 1.0);  // measured: 28.97 → 30.43 dB
  // Blending moves no silhouette: the same pixels are covered (up to rounding on the rims).
  EXPECT_NEAR(double(blended.covered_count()), double(plain.covered_count()),
              0.002 * double(plain.covered_count()));
}

}  // namespace
}  // namespace pbr_lod
