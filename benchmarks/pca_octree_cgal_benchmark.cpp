// CGAL's hierarchy_simplify_point_set (Pauly, Gross & Kobbelt 2002: recursive PCA splits of
// clusters until a cluster holds at most `size` points and its surface variation is below
// `maximum_variation`) on the inputs of pca_octree_benchmark.cpp — the closest thing a user has
// today to the PCA octree's §3 hierarchy. A TU of its own so that CGAL's compile options stay
// here (benchmarks/builders.cmake).
#include <benchmark/benchmark.h>

#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/hierarchy_simplify_point_set.h>

#include <vector>

#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "support/data.hpp"

namespace {
using kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using point = kernel::Point_3;

std::vector<point> cgal_points(const std::string& name) {
  const pbr_lod::point_cloud c = name.starts_with("wavy")
                                     ? pbr_lod::make_wavy_surface(std::stoul(name.substr(4)), 1)
                                     : pbr_lod::read_points(pbr_lod::test::data_file(name));
  std::vector<point> p;
  p.reserve(c.size());
  for (std::size_t i = 0; i < c.size(); ++i) {
    const pbr_lod::vec3d w = c.world(i);
    p.emplace_back(w.x(), w.y(), w.z());
  }
  return p;
}

// size = 8 (our leaf_size), maximum_variation = 1/3 (CGAL's default): clusters split by PCA
// until small; the output is one point per cluster.
void bm_cgal_hierarchy(benchmark::State& state, const std::string& name) {
  const std::vector<point> input = cgal_points(name);
  std::size_t kept = 0;
  for (auto _ : state) {
    state.PauseTiming();
    std::vector<point> p = input;
    state.ResumeTiming();
    const auto end =
        CGAL::hierarchy_simplify_point_set(p, CGAL::parameters::size(8).maximum_variation(1. / 3.));
    kept = static_cast<std::size_t>(end - p.begin());
    benchmark::DoNotOptimize(kept);
  }
  state.counters["points/s"] = benchmark::Counter(
      static_cast<double>(input.size()) * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate);
  state.counters["clusters"] = static_cast<double>(kept);
}
BENCHMARK_CAPTURE(bm_cgal_hierarchy, bunny, std::string("bun_zipper.ply"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(bm_cgal_hierarchy, happy_buddha, std::string("happy_vrip_res3.ply"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(bm_cgal_hierarchy, wavy_1M, std::string("wavy1000000"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
