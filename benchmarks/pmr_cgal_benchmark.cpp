// The peer of pmr_benchmark.cpp's bm_build on the generated 500k surface (issue 43): CGAL's
// Delaunay_triangulation_3 of the whole cloud in one go, sequential and parallel (TBB,
// Parallel_tag with a lock grid), on the same points. PMR's floor is one such triangulation plus
// the vertex removals of its decimation; docs/pmr.md quotes the two side by side. A TU of its
// own so that CGAL's compile options (-frounding-math) stay here (benchmarks/builders.cmake).
#include <benchmark/benchmark.h>

#include <CGAL/Delaunay_triangulation_3.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>

#include <vector>

#include "pbr_lod/core/point_source.hpp"

namespace {
using K = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point = K::Point_3;
using sequential_dt = CGAL::Delaunay_triangulation_3<K>;
using parallel_tds =
    CGAL::Triangulation_data_structure_3<CGAL::Triangulation_vertex_base_3<K>,
                                         CGAL::Delaunay_triangulation_cell_base_3<K>,
                                         CGAL::Parallel_tag>;
using parallel_dt = CGAL::Delaunay_triangulation_3<K, parallel_tds>;

/// The input of pmr_benchmark.cpp's bm_build "generated_500k" (`pbrlod build
/// generated-points:500000:normals`), in world coordinates.
const std::vector<Point>& points() {
  static const std::vector<Point> p = [] {
    const pbr_lod::point_cloud c =
        pbr_lod::read_all(pbr_lod::generated_point_source(500000, 1, true, true));
    std::vector<Point> out;
    out.reserve(c.size());
    for (std::size_t i = 0; i < c.size(); ++i) {
      const pbr_lod::vec3d w = c.world(i);
      out.emplace_back(w.x(), w.y(), w.z());
    }
    return out;
  }();
  return p;
}

/// range(0): 0 sequential, 1 parallel (TBB's default arena: every core).
void bm_cgal_delaunay(benchmark::State& state) {
  const std::vector<Point>& p = points();
  const bool parallel = state.range(0) != 0;
  std::size_t cells = 0;
  for (auto _ : state) {
    if (parallel) {
      const CGAL::Bbox_3 box = CGAL::bbox_3(p.begin(), p.end());
      parallel_dt::Lock_data_structure locks(box, 50);
      const parallel_dt dt(p.begin(), p.end(), &locks);
      cells = dt.number_of_finite_cells();
    } else {
      const sequential_dt dt(p.begin(), p.end());
      cells = dt.number_of_finite_cells();
    }
    benchmark::DoNotOptimize(cells);
  }
  state.counters["vertices"] = static_cast<double>(p.size());
  state.counters["cells"] = static_cast<double>(cells);
  state.SetLabel(parallel ? "generated_500k, parallel (TBB)" : "generated_500k, sequential");
}
BENCHMARK(bm_cgal_delaunay)->Arg(0)->Arg(1)->Iterations(1)->Unit(benchmark::kSecond)->UseRealTime();

}  // namespace
