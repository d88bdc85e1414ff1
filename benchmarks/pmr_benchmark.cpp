// PMR (Dey & Hudson, IEEE Vis 2002) benchmarks: the paper's Table 1 (vertices, preprocessing
// time, hierarchy size) for our scans and a generated surface of the Dragon's size (437,645
// points: 3 h 53 min and 97 MB on the paper's 1.7 GHz Pentium 4), with peak memory; and the
// Table 2 / Figure 6 analogue: points and triangles drawn and time per frame against the factor
// (1, 3, 5) and the viewing distance, with the image error against the full-detail cut (level 0,
// every sample as its umbrella). docs/pmr.md quotes these numbers. bm_build on "generated_500k"
// (`pbrlod build generated-points:500000:normals`) has its peer in pmr_cgal_benchmark.cpp, CGAL's
// triangulation of the same points, run in the same process (issue 43: PMR against one parallel
// triangulation of its input):
//   bench_pmr --benchmark_filter='generated_500k|cgal' --benchmark_repetitions=5
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <map>

#include "pbr_lod/builders/pmr.hpp"
#include "pbr_lod/core/point_source.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "support/data.hpp"

namespace {
using namespace pbr_lod;

const char* input_name(int which) {
  switch (which) {
    case 0:
      return "bunny";
    case 1:
      return "buddha_res3";
    case 2:
      return "milk_carton_pcd";
    case 4:
      return "generated_500k";
    default:
      return "wavy_437645";
  }
}

const point_cloud& input(int which) {
  static std::map<int, point_cloud> cache;
  auto it = cache.find(which);
  if (it == cache.end()) {
    point_cloud c = which == 0   ? read_mesh(test::data_file("bun_zipper.ply")).vertices
                    : which == 1 ? read_mesh(test::data_file("happy_vrip_res3.ply")).vertices
                    : which == 2 ? read_points(test::data_file("milk_cartoon_all_small_clorox.pcd"))
                    : which == 4 ? read_all(generated_point_source(500000, 1, true, true))
                                 : make_wavy_surface(437645, 1);
    it = cache.emplace(which, std::move(c)).first;
  }
  return it->second;
}

/// CPU seconds of every thread of the process so far (user + system): on a shared machine the
/// wall time depends on the neighbours' load, this does not.
double cpu_seconds() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_utime.tv_sec + u.ru_stime.tv_sec) +
         1e-6 * static_cast<double>(u.ru_utime.tv_usec + u.ru_stime.tv_usec);
}

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return static_cast<double>(u.ru_maxrss) / 1024.0;  // kB on Linux
}

/// Table 1: build time, hierarchy size, peak memory of the process (run one input per process,
/// --benchmark_filter, for a per-input peak).
void bm_build(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const point_cloud& c = input(which);
  pmr_options o;
  o.max_leaf_points = static_cast<std::uint32_t>(state.range(1));
  o.neighbour_margin = static_cast<float>(state.range(2)) / 100;
  for (auto _ : state) {
    const double cpu0 = cpu_seconds();
    const pmr_hierarchy h = build_pmr(c, o);
    state.counters["cpu_s_all_threads"] = cpu_seconds() - cpu0;
    benchmark::DoNotOptimize(h.nodes().data());
    state.counters["vertices"] = static_cast<double>(c.size());
    state.counters["leaves"] = static_cast<double>(h.leaf_count());
    state.counters["triangulated"] = static_cast<double>(h.stats().triangulated_points);
    state.counters["removals"] = static_cast<double>(h.stats().removals);
    state.counters["file_MB"] = static_cast<double>(h.file_bytes()) / 1e6;
    state.counters["B/point"] = static_cast<double>(h.file_bytes()) / static_cast<double>(c.size());
    state.counters["top_level_pts"] = static_cast<double>(h.points_at_level(h.levels() - 1));
  }
  state.counters["peak_RSS_MB"] = peak_rss_mb();
  state.SetLabel(input_name(which));
}
BENCHMARK(bm_build)
    ->ArgsProduct({{0, 1, 2}, {10000}, {10}})
    ->Args({3, 10000, 10})
    ->Args({3, 10000, 25})
    ->Args({4, 10000, 10})
    ->Iterations(1)
    ->Unit(benchmark::kSecond)
    ->UseRealTime();

/// Draws every leaf at level 0 with every sample as its umbrella: the full-detail cut.
struct full_detail_policy : pmr_policy {
  template <class H, class S>
  void emit(const H& h, const typename H::node_id& n, const view&, float, const traverse_options&,
            S& sink) const {
    h.emit_level(h.nodes()[n].first, 0, 0.0f, sink);
  }
};

const pmr_hierarchy& built_bunny() {
  static const pmr_hierarchy h = build_pmr(input(0), {});
  return h;
}

/// Table 2 / Figure 6: factor × distance (in bounding radii) → primitives, time, image error.
void bm_frame(benchmark::State& state) {
  const pmr_hierarchy& h = built_bunny();
  const float factor = static_cast<float>(state.range(0));
  const double dist = static_cast<double>(state.range(1)) / 2;
  const vec3d centre = 0.5 * (h.input_min() + h.input_max());
  const double radius = 0.5 * (h.input_max() - h.input_min()).norm();
  camera cam = camera::orbit(centre, radius, 30, 20, dist, 1);
  cam.vp = {512, 512};
  const view v(cam, h.origin());
  render_options ro;
  ro.fx.shading = true;
  traverse_options o;
  o.tolerance_px = factor;
  traverse_stats st;
  for (auto _ : state) {
    counting_sink<pmr_hierarchy::attrs> sink;
    st = traverse(h, v, o, sink, pmr_policy{});
    benchmark::DoNotOptimize(sink.points);
  }
  const image img =
      render<pmr_hierarchy::attrs>(v, ro, [&](auto& s) { traverse(h, v, o, s, pmr_policy{}); });
  const image ref = render<pmr_hierarchy::attrs>(
      v, ro, [&](auto& s) { traverse(h, v, o, s, full_detail_policy{}); });
  const image_error e = compare_images(ref, img);
  state.counters["points"] = static_cast<double>(st.points);
  state.counters["triangles"] = static_cast<double>(st.triangles);
  state.counters["psnr_dB"] = e.psnr;
  state.counters["holes"] = e.hole_fraction;
  const auto t0 = std::chrono::steady_clock::now();
  (void)render<pmr_hierarchy::attrs>(v, ro, [&](auto& s) { traverse(h, v, o, s, pmr_policy{}); });
  state.counters["raster_ms"] =
      1e3 * std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}
BENCHMARK(bm_frame)->ArgsProduct({{1, 3, 5}, {3, 8, 16, 80}})->Unit(benchmark::kMillisecond);

}  // namespace
BENCHMARK_MAIN();
