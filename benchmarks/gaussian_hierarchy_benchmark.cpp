// Gaussian hierarchy (Kerbl et al. 2024) benchmarks: build throughput on generated scenes of the
// shape trained ones take (make_gaussian_scene: SH degree 3, flat Gaussians covering a surface)
// — the target is 2 M Gaussians/s at 10 M on 2 cores — and the cut and frame at
// tolerance 1 from 3 and 10 radii beside the full render (Gaussians drawn, PSNR, seconds).
// docs/gaussian-hierarchy.md quotes these numbers.
#include <benchmark/benchmark.h>

#include <map>

#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/gaussian_splats.hpp"
#include "pbr_lod/raster/gaussians.hpp"
#include "pbr_lod/raster/metrics.hpp"

namespace {
using namespace pbr_lod;

const gaussian_cloud& scene(std::size_t n) {
  static std::map<std::size_t, gaussian_cloud> cache;
  auto it = cache.find(n);
  if (it == cache.end()) it = cache.emplace(n, make_gaussian_scene(n, 3, 1)).first;
  return it->second;
}

void BM_Build(benchmark::State& state) {
  const gaussian_cloud& g = scene(static_cast<std::size_t>(state.range(0)));
  const auto threads = static_cast<unsigned>(state.range(1));
  for (auto _ : state) {
    auto h = build_gaussian_hierarchy(g, {.threads = threads});
    benchmark::DoNotOptimize(h);
  }
  state.counters["gaussians_per_s"] = benchmark::Counter(
      static_cast<double>(g.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Build)
    ->Args({1'000'000, 1})
    ->Args({1'000'000, 2})
    ->Args({10'000'000, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1)
    ->Repetitions(3);

camera orbit(double distance) {
  camera c;
  c.eye = vec3d(0.3, 0.4, 1).normalized() * distance;
  c.vp = {512, 512};
  c.z_near = 0.01;
  c.z_far = distance + 4;
  return c;
}

/// The cut at tolerance `range(1)` pixels from `range(0)` radii against every Gaussian drawn: the
/// frame's time, the fraction of Gaussians drawn and the PSNR against the full render.
void BM_CutFrame(benchmark::State& state) {
  const gaussian_cloud& g = scene(150'000);
  static const gaussian_hierarchy h = build_gaussian_hierarchy(g);
  const camera cam = orbit(static_cast<double>(state.range(0)));
  const view v(cam, h.origin());
  const image full = render_gaussians(g, cam, {});
  image img;
  std::size_t drawn = 0;
  for (auto _ : state) {
    gaussian_rasterizer r(v, {});
    const traverse_options t{.tolerance_px = static_cast<float>(state.range(1))};
    drawn = traverse(h, v, t, r, gaussian_policy{}).gaussians;
    img = r.finish();
  }
  state.counters["drawn_fraction"] = static_cast<double>(drawn) / static_cast<double>(g.size());
  state.counters["psnr_db"] = compare_images(full, img).psnr;
}
BENCHMARK(BM_CutFrame)
    ->ArgNames({"radii", "tolerance"})
    ->ArgsProduct({{3, 10}, {1, 2, 4, 8}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
