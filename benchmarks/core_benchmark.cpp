// Quantised normals (Pajarola 2003 §5): encode / decode throughput per q.
// k-NN estimation (§4 end): normals (PCA only, and PCA + CGAL MST orientation) and splat
// ellipses on make_wavy_surface. Counter: points/s (normals/s for the quantiser).
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "pbr_lod/core/estimation.hpp"
#include "pbr_lod/core/normal_quantization.hpp"
#include "pbr_lod/core/synthetic.hpp"

namespace {

using pbr_lod::vec3f;

std::vector<vec3f> random_normals(std::size_t n) {
  std::mt19937_64 rng(42);
  std::normal_distribution<float> g;
  std::vector<vec3f> out(n);
  for (auto& v : out) v = vec3f(g(rng), g(rng), g(rng)).normalized();
  return out;
}

void rate(benchmark::State& state, std::size_t per_iteration, const char* name = "points/s") {
  state.counters[name] = benchmark::Counter(
      static_cast<double>(per_iteration) * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate);
}

void BM_Encode(benchmark::State& state) {
  const pbr_lod::normal_quantizer nq(static_cast<int>(state.range(0)));
  const auto normals = random_normals(1 << 16);
  for (auto _ : state) {
    std::uint32_t acc = 0;
    for (const auto& n : normals) acc += nq.encode(n);
    benchmark::DoNotOptimize(acc);
  }
  rate(state, normals.size(), "normals/s");
}
BENCHMARK(BM_Encode)->Arg(9)->Arg(12)->Arg(13)->Arg(16)->Arg(24);

// The same normals through encode(span, span), which loads the candidate cells of a run of
// normals before searching any (same codes).
void BM_EncodeMany(benchmark::State& state) {
  const pbr_lod::normal_quantizer nq(static_cast<int>(state.range(0)));
  const auto normals = random_normals(1 << 16);
  std::vector<std::uint32_t> codes(normals.size());
  for (auto _ : state) {
    nq.encode(normals, codes);
    benchmark::DoNotOptimize(codes.data());
    benchmark::ClobberMemory();
  }
  rate(state, normals.size(), "normals/s");
}
BENCHMARK(BM_EncodeMany)->Arg(9)->Arg(12)->Arg(13)->Arg(16)->Arg(24);

// Each encode's input depends on the previous code (a perturbation of 1e-30 that changes no
// code): the latency a builder sees when an encode's result feeds the next step, as in a
// bottom-up pass (BM_Encode measures throughput, where independent encodes overlap).
void BM_EncodeLatency(benchmark::State& state) {
  const pbr_lod::normal_quantizer nq(static_cast<int>(state.range(0)));
  const auto normals = random_normals(1 << 16);
  for (auto _ : state) {
    std::uint32_t c = 0;
    for (const auto& n : normals) {
      pbr_lod::vec3f m = n;
      m.x() += static_cast<float>(c & 1u) * 1e-30f;
      c = nq.encode(m);
    }
    benchmark::DoNotOptimize(c);
  }
  rate(state, normals.size(), "normals/s");
}
BENCHMARK(BM_EncodeLatency)->Arg(12)->Arg(16);

void BM_Decode(benchmark::State& state) {
  const pbr_lod::normal_quantizer nq(static_cast<int>(state.range(0)));
  std::vector<std::uint32_t> codes;
  for (const auto& n : random_normals(1 << 16)) codes.push_back(nq.encode(n));
  for (auto _ : state) {
    vec3f acc = vec3f::Zero();
    for (const auto c : codes) acc += nq.decode(c);
    benchmark::DoNotOptimize(acc);
  }
  rate(state, codes.size(), "normals/s");
}
BENCHMARK(BM_Decode)->Arg(9)->Arg(12)->Arg(13)->Arg(16)->Arg(24);

const pbr_lod::point_cloud& surface(std::size_t n) {
  static std::size_t cached_n = 0;
  static pbr_lod::point_cloud cloud;
  if (cached_n != n) {
    cloud = pbr_lod::make_wavy_surface(n, 1);
    cached_n = n;
  }
  return cloud;
}

// range(0) = points, range(1) = 1 to orient with CGAL's MST, 0 for PCA only.
void BM_EstimateNormals(benchmark::State& state) {
  const auto& cloud = surface(static_cast<std::size_t>(state.range(0)));
  for (auto _ : state) {
    auto n = pbr_lod::estimate_normals(cloud.positions, 16, state.range(1) != 0);
    benchmark::DoNotOptimize(n.data());
  }
  rate(state, cloud.size());
}
BENCHMARK(BM_EstimateNormals)
    ->Args({1'000'000, 0})
    ->Args({1'000'000, 1})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()  // multi-threaded: the main thread's CPU time would overstate the rate
    ->Iterations(1);

void BM_EstimateSplatEllipses(benchmark::State& state) {
  const auto& cloud = surface(static_cast<std::size_t>(state.range(0)));
  for (auto _ : state) {
    auto e = pbr_lod::estimate_splat_ellipses(cloud.positions, cloud.normals, 16);
    benchmark::DoNotOptimize(e.u.data());
  }
  rate(state, cloud.size());
}
BENCHMARK(BM_EstimateSplatEllipses)
    ->Arg(1'000'000)
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

// Both steps: arg 1 = 0 as two calls (two k-NN searches), 1 in one pass over one k-NN search
// (estimate_normals_and_ellipses, what the point-octree builder runs).
void BM_NormalsAndEllipses(benchmark::State& state) {
  const auto& cloud = surface(static_cast<std::size_t>(state.range(0)));
  for (auto _ : state) {
    if (state.range(1) == 0) {
      const auto n = pbr_lod::estimate_normals(cloud.positions, 16, true);
      auto e = pbr_lod::estimate_splat_ellipses(cloud.positions, n, 16);
      benchmark::DoNotOptimize(e.u.data());
    } else {
      auto both = pbr_lod::estimate_normals_and_ellipses(cloud.positions, 16, 16, true);
      benchmark::DoNotOptimize(both.axes.u.data());
    }
  }
  rate(state, cloud.size());
}
BENCHMARK(BM_NormalsAndEllipses)
    ->Args({1'000'000, 0})
    ->Args({1'000'000, 1})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
