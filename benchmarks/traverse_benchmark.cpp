// Traversal throughput: nodes visited per second by the generic traversal over the reference
// sphere tree (a binary tree, leaf size 8) on a generated 1M-point surface, for each screen-size
// metric and tolerance. The sink only counts, so this measures the traversal alone.
#include <benchmark/benchmark.h>

#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/traverse/traverse.hpp"
#include "support/sphere_tree.hpp"

namespace {
using namespace pbr_lod;

const point_set<with_normals>& surface() {
  static const auto pts = point_set<with_normals>::from(make_wavy_surface(1'000'000, 1));
  return pts;
}
const test::sphere_tree<with_normals>& tree() {
  static const test::sphere_tree<with_normals> t(surface(), 8);
  return t;
}

void bm_traverse(benchmark::State& state) {
  const auto metric = static_cast<projection_metric>(state.range(0));
  const auto tol = static_cast<float>(state.range(1));
  const bool backface = state.range(2) != 0;
  const auto& t = tree();
  const view v(camera::orbit(vec3d::Zero(), 1.4, 30, 20, 2.5, 1, {1024, 1024}), t.origin());
  traverse_stats st;
  for (auto _ : state) {
    counting_sink<with_normals> sink;
    st = traverse(t, v, {.tolerance_px = tol, .metric = metric, .backface_cull = backface}, sink);
    benchmark::DoNotOptimize(sink.points);
  }
  state.counters["nodes/s"] =
      benchmark::Counter(static_cast<double>(st.visited) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["visited"] = static_cast<double>(st.visited);
  state.counters["emitted"] = static_cast<double>(st.primitives());
}
BENCHMARK(bm_traverse)
    ->ArgNames({"metric", "tol_px", "backface"})
    ->ArgsProduct({{0, 1, 2, 3}, {1, 4, 16}, {0}})
    ->Args({0, 1, 1})
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
