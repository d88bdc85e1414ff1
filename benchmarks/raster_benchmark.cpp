// Throughput of the CPU reference rasteriser (raster/rasterizer.hpp): one-pixel points, square
// splats, small elliptical splats and triangles per second, and the cost of each effect on a
// fixed scene. Every benchmark renders whole frames through render_direct() (the rasteriser as
// the traversal's sink), so the figures include the per-frame work (clearing 512² buffers,
// converting depth) that a user pays; points_1px/*_buffered go through render(), which buffers
// the frame first (the difference is what the buffer costs). gaussians_150k renders a 3DGS-like
// scene with the Gaussian rasteriser (raster/gaussians.hpp) through render_gaussians().
//
// Scenes: a unit sphere seen from 3 radii (camera::orbit, 512×512, fovy 40°) covers ~190k
// pixels; primitives are emitted in a spatially coherent order (latitude bands), as a traversal
// of a spatial hierarchy would emit them, except where a benchmark says "shuffled".
#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>
#include <vector>

#include "pbr_lod/raster/gaussians.hpp"
#include "pbr_lod/raster/rasterizer.hpp"

namespace pbr_lod {
namespace {

view bench_view() {
  return view(camera::orbit(vec3d::Zero(), 1, 30, 20, 3, 1, {512, 512}), vec3d::Zero());
}

/// n points of the unit sphere on a Fibonacci lattice, in latitude order.
std::vector<vec3f> sphere_points(std::size_t n) {
  std::vector<vec3f> p(n);
  const double golden = std::numbers::pi * (3 - std::sqrt(5.0));
  for (std::size_t i = 0; i < n; ++i) {
    const double y = 1 - 2 * (double(i) + 0.5) / double(n), r = std::sqrt(1 - y * y);
    p[i] = vec3f(float(r * std::cos(golden * double(i))), float(y),
                 float(r * std::sin(golden * double(i))));
  }
  return p;
}

void set_rate(benchmark::State& state, std::size_t n, const char* name) {
  state.counters[name] =
      benchmark::Counter(double(n), benchmark::Counter::kIsIterationInvariantRate);
  state.SetItemsProcessed(std::int64_t(state.iterations()) * std::int64_t(n));
}

// --- one-pixel points --------------------------------------------------------------------------

template <attributes A, bool Shuffled>
void BM_points_1px(benchmark::State& state) {
  const std::size_t n = 1'000'000;
  std::vector<vec3f> pos = sphere_points(n);
  if constexpr (Shuffled) std::shuffle(pos.begin(), pos.end(), std::mt19937(1));
  std::vector<point_prim<A>> prims(n);
  for (std::size_t i = 0; i < n; ++i) {
    prims[i].position = pos[i];
    prims[i].size_px = 1;
    if constexpr (A.colour) prims[i].colour = {std::uint8_t(i), std::uint8_t(i >> 8), 128};
    if constexpr (A.normal) prims[i].normal = pos[i];
  }
  const view v = bench_view();
  render_options opt;
  opt.fx = effects{.colour = A.colour};
  for (auto _ : state) {
    image img = render_direct<A>(v, opt, [&](auto& sink) {
      for (const auto& p : prims) sink.point(p);
    });
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, n, "points_per_s");
}
template <attributes A>
void BM_points_1px_buffered(benchmark::State& state) {
  const std::size_t n = 1'000'000;
  const std::vector<vec3f> pos = sphere_points(n);
  std::vector<point_prim<A>> prims(n);
  for (std::size_t i = 0; i < n; ++i) prims[i] = {pos[i], 1};
  const view v = bench_view();
  for (auto _ : state) {
    image img = render<A>(v, render_options{}, [&](auto& sink) {
      for (const auto& p : prims) sink.point(p);
    });
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, n, "points_per_s");
}
BENCHMARK(BM_points_1px_buffered<positions_only>)
    ->Name("points_1px/positions_buffered")
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_points_1px<positions_only, false>)
    ->Name("points_1px/positions")
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_points_1px<attributes{.colour = true}, false>)
    ->Name("points_1px/colour")
    ->Unit(benchmark::kMillisecond);
BENCHMARK(BM_points_1px<positions_only, true>)
    ->Name("points_1px/positions_shuffled")
    ->Unit(benchmark::kMillisecond);

// --- square splats -----------------------------------------------------------------------------

void BM_square_splats(benchmark::State& state) {
  const std::size_t n = 300'000;
  const float size = float(state.range(0));
  const std::vector<vec3f> pos = sphere_points(n);
  std::vector<point_prim<positions_only>> prims(n);
  for (std::size_t i = 0; i < n; ++i) prims[i] = {pos[i], size};
  const view v = bench_view();
  for (auto _ : state) {
    image img = render_direct<positions_only>(v, render_options{}, [&](auto& sink) {
      for (const auto& p : prims) sink.point(p);
    });
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, n, "splats_per_s");
}
BENCHMARK(BM_square_splats)
    ->Name("square_splats/size_px")
    ->Arg(2)
    ->Arg(3)
    ->Arg(5)
    ->Unit(benchmark::kMillisecond);

// --- elliptical splats -------------------------------------------------------------------------

/// n splats tangent to the sphere, random orientation, aspect 0.5–1, semi-major axis of
/// r_lo–r_hi pixels at their depth.
std::vector<splat_prim<with_normals>> sphere_splats(std::size_t n, float r_lo, float r_hi) {
  const std::vector<vec3f> pos = sphere_points(n);
  const view v = bench_view();
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> radius(r_lo, r_hi), aspect(0.5f, 1), angle(0, 6.2831853f);
  std::vector<splat_prim<with_normals>> s(n);
  for (std::size_t i = 0; i < n; ++i) {
    const vec3f nrm = pos[i];
    const vec3f t0 = any_orthogonal(nrm), t1 = nrm.cross(t0);
    const float a = angle(rng);
    const vec3f u = std::cos(a) * t0 + std::sin(a) * t1, w = nrm.cross(u);
    const float px = v.pixel_size_at_depth(std::max(v.to_eye(pos[i]).z(), 0.1f));
    const float r = radius(rng) * px;
    s[i].centre = pos[i];
    s[i].u = u * r;
    s[i].v = w * (r * aspect(rng));
    s[i].normal = nrm;
  }
  return s;
}

void BM_elliptical_splats(benchmark::State& state) {
  const std::size_t n = 300'000;
  const auto prims = sphere_splats(n, float(state.range(0)), float(state.range(1)));
  const view v = bench_view();
  for (auto _ : state) {
    image img = render_direct<with_normals>(v, render_options{}, [&](auto& sink) {
      for (const auto& s : prims) sink.splat(s);
    });
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, n, "splats_per_s");
}
BENCHMARK(BM_elliptical_splats)
    ->Name("elliptical_splats/radius_px")
    ->Args({2, 4})
    ->Args({1, 2})
    ->Args({4, 8})
    ->Unit(benchmark::kMillisecond);

// --- triangles ---------------------------------------------------------------------------------

std::vector<triangle_prim<with_normals>> sphere_triangles(int rings, int segments) {
  const auto at = [&](int i, int j) {
    const float th = std::numbers::pi_v<float> * float(i) / float(rings);
    const float ph = 2 * std::numbers::pi_v<float> * float(j) / float(segments);
    return vec3f(std::sin(th) * std::cos(ph), std::cos(th), -std::sin(th) * std::sin(ph));
  };
  std::vector<triangle_prim<with_normals>> t;
  for (int i = 0; i < rings; ++i)
    for (int j = 0; j < segments; ++j) {
      const vec3f a = at(i, j), b = at(i + 1, j), c = at(i + 1, j + 1), d = at(i, j + 1);
      triangle_prim<with_normals> x;
      x.p = {a, b, c};
      x.normal = {a, b, c};
      t.push_back(x);
      x.p = {a, c, d};
      x.normal = {a, c, d};
      t.push_back(x);
    }
  return t;
}

void BM_triangles(benchmark::State& state) {
  const auto prims = sphere_triangles(int(state.range(0)), 2 * int(state.range(0)));
  const view v = bench_view();
  for (auto _ : state) {
    image img = render_direct<with_normals>(v, render_options{}, [&](auto& sink) {
      for (const auto& t : prims) sink.triangle(t);
    });
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, prims.size(), "triangles_per_s");
}
// 2·rings² triangles: 256 → 131k (~3 px visible each), 64 → 8k (~45 px), 16 → 512 (~750 px).
BENCHMARK(BM_triangles)
    ->Name("triangles/rings")
    ->Arg(256)
    ->Arg(64)
    ->Arg(16)
    ->Unit(benchmark::kMillisecond);

// --- effects on a fixed scene ------------------------------------------------------------------

constexpr attributes kFx = with_normals_colours;

/// The effects scene: a ground quad of 2·64² triangles, 200k small splats on a sphere above it,
/// 100k one-pixel points on a second sphere, all with normals and colours.
struct effects_scene {
  std::vector<triangle_prim<kFx>> tris;
  std::vector<splat_prim<kFx>> splats;
  std::vector<point_prim<kFx>> points;

  effects_scene() {
    const int g = 64;
    for (int j = 0; j < g; ++j)
      for (int i = 0; i < g; ++i) {
        const auto p = [&](int a, int b) {
          return vec3f(-2 + 4 * float(a) / g, -1, 2 - 4 * float(b) / g);
        };
        triangle_prim<kFx> t;
        t.normal = {vec3f::UnitY(), vec3f::UnitY(), vec3f::UnitY()};
        const rgb8 c{std::uint8_t(100 + i), std::uint8_t(100 + j), 90};
        t.colour = {c, c, c};
        t.p = {p(i, j), p(i + 1, j), p(i + 1, j + 1)};
        tris.push_back(t);
        t.p = {p(i, j), p(i + 1, j + 1), p(i, j + 1)};
        tris.push_back(t);
      }
    for (const auto& s : sphere_splats(200'000, 2, 4)) {
      splat_prim<kFx> x;
      x.centre = 0.6f * s.centre + vec3f(-0.5f, 0, 0);
      x.u = 0.6f * s.u;
      x.v = 0.6f * s.v;
      x.normal = s.normal;
      x.colour = {200, std::uint8_t(128 + 100 * s.normal.y()), 60};
      splats.push_back(x);
    }
    for (const vec3f& p : sphere_points(100'000)) {
      point_prim<kFx> x;
      x.position = 0.4f * p + vec3f(0.7f, -0.4f, 0.3f);
      x.normal = p;
      x.colour = {60, 120, 220};
      points.push_back(x);
    }
  }
  template <class S>
  void operator()(S& sink) const {
    for (const auto& t : tris) sink.triangle(t);
    for (const auto& s : splats) sink.splat(s);
    for (const auto& p : points) sink.point(p);
  }
};

void BM_effects(benchmark::State& state, effects fx) {
  static const effects_scene scene;
  const view v = bench_view();
  render_options opt;
  opt.fx = fx;
  opt.sun.direction = vec3f(0.3f, 1, 0.2f);
  for (auto _ : state) {
    image img = render_direct<kFx>(v, opt, scene);
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, scene.tris.size() + scene.splats.size() + scene.points.size(),
           "primitives_per_s");
}
BENCHMARK_CAPTURE(BM_effects, none, no_effects)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, colour, effects{.colour = true})->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, shading, effects{.shading = true, .colour = false})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, shading_colour, effects{.shading = true, .colour = true})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, backface_cull, effects{.colour = false, .backface_cull = true})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, shadows, effects{.colour = false, .shadows = true})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, hole_filling, effects{.colour = false, .hole_filling = true})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, colour_blending, effects{.colour = true, .blending = true})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, shading_colour_blending,
                  effects{.shading = true, .colour = true, .blending = true})
    ->Unit(benchmark::kMillisecond);
// Every effect but blending: the effect set `all` was before blending existed.
BENCHMARK_CAPTURE(BM_effects, all_but_blending,
                  all_effects - effects{.colour = false, .blending = true})
    ->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_effects, all, all_effects)->Unit(benchmark::kMillisecond);

// --- 3-D Gaussians (raster/gaussians.hpp) ------------------------------------------------------

/// n flat Gaussians on the unit sphere, about what a trained 3DGS scene of a surface holds: each
/// a disc in the tangent plane (third scale a tenth of the others) of σ ≈ 1–1.5 × the lattice
/// spacing (2–5 px at 512² from 3 radii), anisotropic in the plane, opacities 0.3–1, SH degree 3
/// with small view-dependent bands. Latitude order, as the other scenes.
gaussian_cloud gaussian_sphere(std::size_t n) {
  gaussian_cloud c;
  c.sh_degree = 3;
  c.positions = sphere_points(n);
  c.sh.resize(n * c.sh_stride());
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);
  const float spacing = std::sqrt(4 * float(std::numbers::pi) / float(n));
  for (std::size_t i = 0; i < n; ++i) {
    const vec3f nrm = c.positions[i];
    // The rotation taking local z to the normal, then a random spin about it.
    const vec4f q = nrm.z() > -0.999f ? vec4f(1 + nrm.z(), -nrm.y(), nrm.x(), 0).normalized()
                                      : vec4f(0, 1, 0, 0);
    const float spin = 2 * float(std::numbers::pi) * u(rng);
    const Eigen::Quaternionf qs = Eigen::Quaternionf(q[0], q[1], q[2], q[3]) *
                                  Eigen::Quaternionf(Eigen::AngleAxisf(spin, vec3f::UnitZ()));
    c.rotations.push_back(vec4f(qs.w(), qs.x(), qs.y(), qs.z()));
    const float s = spacing * (1 + 0.5f * u(rng));
    c.scales.push_back(vec3f(s * (0.6f + 0.8f * u(rng)), s * (0.6f + 0.8f * u(rng)), 0.1f * s));
    c.opacities.push_back(0.3f + 0.7f * u(rng));
    const float dc[3] = {nrm.x(), nrm.y(), nrm.z()};  // colour from the normal, as a test image
    for (int ch = 0; ch < 3; ++ch) c.sh[c.sh_index(i, 0, ch)] = 1.2f * dc[ch];
    for (int k = 1; k < 16; ++k)
      for (int ch = 0; ch < 3; ++ch) c.sh[c.sh_index(i, k, ch)] = 0.1f * (2 * u(rng) - 1);
  }
  return c;
}

// The whole reference render: covariances from scale and rotation, projection, SH colour, sort,
// binning and compositing, at 512². Threads = the benchmark's argument; real time.
void BM_gaussians(benchmark::State& state) {
  const std::size_t n = 150'000;
  const gaussian_cloud cloud = gaussian_sphere(n);
  const camera cam = camera::orbit(vec3d::Zero(), 1, 30, 20, 3, 1, {512, 512});
  const gaussian_render_options opt{.threads = unsigned(state.range(0))};
  for (auto _ : state) {
    image img = render_gaussians(cloud, cam, opt);
    benchmark::DoNotOptimize(img.colour.data());
  }
  set_rate(state, n, "gaussians_per_s");
}
BENCHMARK(BM_gaussians)
    ->Name("gaussians_150k/threads")
    ->Arg(1)
    ->Arg(2)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace pbr_lod

BENCHMARK_MAIN();
