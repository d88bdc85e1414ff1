// Quantised normals (Pajarola 2003 §5): encode / decode throughput per q. Counter: normals/s.
// The k-NN estimation has its own binary (estimation_benchmark.cpp).
#include <benchmark/benchmark.h>

#include <random>
#include <vector>

#include "pbr_lod/core/normal_quantization.hpp"

namespace {

using pbr_lod::vec3f;

std::vector<vec3f> random_normals(std::size_t n) {
  std::mt19937_64 rng(42);
  std::normal_distribution<float> g;
  std::vector<vec3f> out(n);
  for (auto& v : out) v = vec3f(g(rng), g(rng), g(rng)).normalized();
  return out;
}

void rate(benchmark::State& state, std::size_t per_iteration, const char* name) {
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

}  // namespace

BENCHMARK_MAIN();
