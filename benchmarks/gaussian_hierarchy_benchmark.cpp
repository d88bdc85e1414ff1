// Gaussian hierarchy (Kerbl et al. 2024) benchmarks: build throughput on generated scenes of the
// shape trained ones take (make_gaussian_scene: SH degree 3, flat Gaussians covering a surface)
// — the target is 2 M Gaussians/s at 10 M on 2 cores; leaves of 1 (the paper's) and 2
// (the default) — and the cut and frame at tolerance 1 from 3 and 10 radii beside the full
// render (Gaussians drawn, PSNR, seconds).
// docs/gaussian-hierarchy.md quotes these numbers.
#include <benchmark/benchmark.h>

#include <filesystem>
#include <map>

#include "pbr_lod/builders/chunked_gaussian_hierarchy.hpp"
#include "pbr_lod/builders/gaussian_hierarchy.hpp"
#include "pbr_lod/core/gaussian_source.hpp"
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
  const auto leaf = static_cast<int>(state.range(2));
  for (auto _ : state) {
    auto h = build_gaussian_hierarchy(g, {.leaf_size = leaf, .threads = threads});
    benchmark::DoNotOptimize(h);
  }
  state.counters["gaussians_per_s"] = benchmark::Counter(
      static_cast<double>(g.size()), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Build)
    ->Args({1'000'000, 1, 1})
    ->Args({1'000'000, 1, 2})
    ->Args({1'000'000, 2, 1})
    ->Args({1'000'000, 2, 2})
    ->Args({10'000'000, 2, 1})
    ->Args({10'000'000, 2, 2})
    ->ArgNames({"n", "threads", "leaf"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1)
    ->Repetitions(3);

/// The out-of-core build (builders/chunked_gaussian_hierarchy.hpp) of a generated scene made
/// block by block, into a temporary folder, with `range(1)` MiB of memory: the in-memory build's
/// work plus two passes and the chunk files' writes and reads (the page cache holds them here).
void BM_BuildChunked(benchmark::State& state) {
  const auto n = static_cast<std::uint64_t>(state.range(0));
  const generated_gaussian_source src(n, 3, 1);
  chunked_gaussian_hierarchy_options o;
  o.memory_bytes = static_cast<std::uint64_t>(state.range(1)) << 20;
  const std::string dir =
      (std::filesystem::temp_directory_path() / "pbr_lod_bench_gaussian_chunked").string();
  chunked_build_report r;
  for (auto _ : state) r = build_gaussian_hierarchy_chunked(src, dir, o);
  std::filesystem::remove_all(dir);
  state.counters["gaussians_per_s"] =
      benchmark::Counter(static_cast<double>(n), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["chunks"] = static_cast<double>(r.chunks);
  state.counters["pass_s"] = r.pass_seconds;
  state.counters["chunk_build_s"] = r.chunk_build_seconds;
}
BENCHMARK(BM_BuildChunked)
    ->Args({1'000'000, 256})
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
