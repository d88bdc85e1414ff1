// The peers of estimation_benchmark.cpp in CGAL (Point_set_processing_3), on the same inputs:
// pca_estimate_normals (k = 16, parallel where CGAL is built with TBB) + mst_orient_normals
// (k = 16), and Orthogonal_k_neighbor_search for the k-NN alone. A TU of its own so that CGAL's
// compile options (-frounding-math) stay here (benchmarks/core.cmake).
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Orthogonal_k_neighbor_search.h>
#include <CGAL/Search_traits_3.h>
#include <CGAL/mst_orient_normals.h>
#include <CGAL/pca_estimate_normals.h>
#include <CGAL/property_map.h>

#include <utility>
#include <vector>

#include "estimation_inputs.hpp"

namespace pbr_lod::bench {
namespace {

using kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using point = kernel::Point_3;
using vector = kernel::Vector_3;
using point_with_normal = std::pair<point, vector>;

std::vector<point_with_normal> cgal_input(const estimation_input& in) {
  std::vector<point_with_normal> p;
  p.reserve(in.positions.size());
  for (const auto& x : in.positions) p.emplace_back(point(x.x(), x.y(), x.z()), vector(0, 0, 0));
  return p;
}

void bm_cgal_normals(benchmark::State& state, const std::string& name) {
  const estimation_input& in = estimation_inputs::get(name);
  const std::vector<point_with_normal> input = cgal_input(in);
  std::vector<point_with_normal> p;
  for (auto _ : state) {
    state.PauseTiming();
    p = input;
    state.ResumeTiming();
    const auto params =
        CGAL::parameters::point_map(CGAL::First_of_pair_property_map<point_with_normal>())
            .normal_map(CGAL::Second_of_pair_property_map<point_with_normal>());
    CGAL::pca_estimate_normals<CGAL::Parallel_if_available_tag>(p, 16, params);
    // mst_orient_normals reorders the points (unoriented ones last): keep their order here by
    // orienting a copy that remembers the index.
    CGAL::mst_orient_normals(p, 16, params);
    benchmark::DoNotOptimize(p.data());
  }
  rate(state, in.positions.size());
  // Score against the input order: mst_orient_normals permuted p, so match by position.
  std::vector<vec3f> normals(in.positions.size(), vec3f::Zero());
  {
    std::vector<std::pair<vec3f, vec3f>> sorted;
    sorted.reserve(p.size());
    for (const auto& [x, n] : p)
      sorted.emplace_back(vec3f(float(x.x()), float(x.y()), float(x.z())),
                          vec3f(float(n.x()), float(n.y()), float(n.z())));
    const auto less = [](const vec3f& a, const vec3f& b) {
      return std::lexicographical_compare(a.data(), a.data() + 3, b.data(), b.data() + 3);
    };
    std::sort(sorted.begin(), sorted.end(),
              [&](const auto& a, const auto& b) { return less(a.first, b.first); });
    for (std::size_t i = 0; i < in.positions.size(); ++i) {
      const auto it =
          std::lower_bound(sorted.begin(), sorted.end(), in.positions[i],
                           [&](const auto& e, const vec3f& q) { return less(e.first, q); });
      if (it != sorted.end() && it->first == in.positions[i]) normals[i] = it->second;
    }
  }
  accuracy(state, in, normals);
}
BENCHMARK_CAPTURE(bm_cgal_normals, bunny, std::string("bunny"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();
BENCHMARK_CAPTURE(bm_cgal_normals, buddha, std::string("buddha"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();
BENCHMARK_CAPTURE(bm_cgal_normals, wavy_1M, std::string("wavy1000000"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime()
    ->Iterations(1);

// CGAL's k-d tree (sliding midpoint, bucket 10) and exact k-NN search, one thread, queries in
// input order as its documentation shows.
void bm_cgal_knn(benchmark::State& state, const std::string& name) {
  using traits = CGAL::Search_traits_3<kernel>;
  using search = CGAL::Orthogonal_k_neighbor_search<traits>;
  const estimation_input& in = estimation_inputs::get(name);
  std::vector<point> pts;
  pts.reserve(in.positions.size());
  for (const auto& x : in.positions) pts.emplace_back(x.x(), x.y(), x.z());
  for (auto _ : state) {
    search::Tree tree(pts.begin(), pts.end());
    tree.build();
    double acc = 0;
    for (const auto& q : pts) {
      const search s(tree, q, 16);
      acc += s.begin()->second;
    }
    benchmark::DoNotOptimize(acc);
  }
  rate(state, in.positions.size());
}
BENCHMARK_CAPTURE(bm_cgal_knn, wavy_1M, std::string("wavy1000000"))
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

}  // namespace
}  // namespace pbr_lod::bench
