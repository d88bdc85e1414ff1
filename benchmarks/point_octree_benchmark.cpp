// Point-octree (Pajarola 2003) benchmarks: build throughput (Table 1), storage (Table 2), the
// fraction drawn at τ = 16 px (Fig. 1), a tolerance sweep (image error vs time vs splats) and
// the drift of the paper's covariance formulation far from the origin. docs/point-octree.md
// quotes these numbers.
#include <benchmark/benchmark.h>

#include <algorithm>
#include <map>
#include <numbers>

#include "pbr_lod/builders/point_octree.hpp"
#include "pbr_lod/core/synthetic.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/traverse/culling.hpp"
#include "support/data.hpp"
#include "support/policies.hpp"
#include "support/trig_culling.hpp"

namespace {
using namespace pbr_lod;

constexpr attributes disks{.normal = true, .colour = true, .ellipse = true};

point_set<disks> with_disks(point_cloud c, double total_area) {
  test::add_circular_splats(c, total_area);
  return point_set<disks>::from(c);
}

/// The wavy torus of make_wavy_surface: area ≈ 4π²·R·r with R = 1, r ≈ 0.35.
const point_set<disks>& surface(std::size_t n) {
  static std::map<std::size_t, point_set<disks>> cache;
  auto it = cache.find(n);
  if (it == cache.end())
    it = cache
             .emplace(n, with_disks(make_wavy_surface(n, 1),
                                    4 * std::numbers::pi * std::numbers::pi * 0.35))
             .first;
  return it->second;
}

const point_cloud& scan(const std::string& name) {
  static std::map<std::string, point_cloud> cache;
  auto it = cache.find(name);
  if (it == cache.end()) it = cache.emplace(name, read_points(test::data_file(name))).first;
  return it->second;
}

void report(benchmark::State& state, const auto& t, std::size_t n) {
  state.counters["points/s"] =
      benchmark::Counter(static_cast<double>(n) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["nodes/point"] = static_cast<double>(t.nodes().size()) / static_cast<double>(n);
  state.counters["B/point_file"] = static_cast<double>(t.file_bytes()) / static_cast<double>(n);
  state.counters["B/point_mem"] = static_cast<double>(t.memory_bytes()) / static_cast<double>(n);
}

// Tree build (octree, covariances, ellipses, quantisation) on a generated surface with splats.
void bm_build_surface(benchmark::State& state) {
  const auto& pts = surface(static_cast<std::size_t>(state.range(0)));
  const point_octree_options opt{.normal_bits = static_cast<int>(state.range(1)),
                                 .threads = static_cast<unsigned>(state.range(2))};
  point_octree<point_octree_attributes(disks)> t;
  for (auto _ : state) {
    t = build_point_octree(pts, opt);
    benchmark::DoNotOptimize(t.nodes().data());
  }
  report(state, t, pts.size());
}
BENCHMARK(bm_build_surface)
    ->ArgNames({"points", "normal_bits", "threads"})
    ->Args({1'000'000, 16, 1})
    ->Args({1'000'000, 16, 2})
    ->Args({1'000'000, 0, 2})
    ->Args({5'000'000, 16, 2})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Whole build from a real scan with positions only: k-NN normals + orientation + ellipses + tree.
void bm_build_scan(benchmark::State& state, const std::string& name) {
  const auto pts = point_set<positions_only>::from(scan(name));
  point_octree<point_octree_attributes(positions_only)> t;
  for (auto _ : state) {
    t = build_point_octree(pts);
    benchmark::DoNotOptimize(t.nodes().data());
  }
  report(state, t, pts.size());
  state.counters["estimation_s"] = t.stats().estimation_seconds;
  state.counters["tree_s"] = t.stats().tree_seconds;
}
BENCHMARK_CAPTURE(bm_build_scan, bunny, std::string("bun_zipper.ply"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_CAPTURE(bm_build_scan, happy_buddha, std::string("happy_vrip_res3.ply"))
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// Tolerance sweep (Fig. 1 / §6) on a 1M-point surface seen at 1024²: traversal + rasterisation
// time, splats drawn, and the image error against the full-detail render (τ = 0).
void bm_tolerance(benchmark::State& state) {
  static const auto t = build_point_octree(surface(1'000'000));
  using tree = std::decay_t<decltype(t)>;
  const auto tol = static_cast<float>(state.range(0));
  const camera cam = camera::orbit(t.origin(), 1.4, 30, 35, 2.2, 1, {1024, 1024});
  const view v(cam, t.origin());
  render_options ro;
  ro.fx = effects{.shading = true, .colour = true};
  const traverse_options o{.tolerance_px = tol,
                           .backface_cull = true,
                           .cull_volume = traverse_options::volume::view_cone};
  static const image full = render_direct<tree::attrs>(v, ro, [&](auto& s) {
    traverse(t, v, {.tolerance_px = 0, .backface_cull = true}, s, point_octree_policy{});
  });
  image img;
  for (auto _ : state) {
    img = render_direct<tree::attrs>(v, ro,
                                     [&](auto& s) { traverse(t, v, o, s, point_octree_policy{}); });
    benchmark::DoNotOptimize(img.colour.data());
  }
  counting_sink<tree::attrs> c;
  const auto st = traverse(t, v, o, c, point_octree_policy{});
  const auto err = compare_images(full, img);
  state.counters["splats"] = static_cast<double>(c.splats);
  state.counters["fraction_drawn"] =
      static_cast<double>(c.splats) / static_cast<double>(t.samples().size());
  state.counters["visited"] = static_cast<double>(st.visited);
  state.counters["psnr_db"] = err.psnr;
  state.counters["hole_fraction"] = err.hole_fraction;
}
BENCHMARK(bm_tolerance)
    ->ArgName("tau_px")
    ->Arg(1)
    ->Arg(2)
    ->Arg(4)
    ->Arg(8)
    ->Arg(16)
    ->Unit(benchmark::kMillisecond);

// §6 culling with the angles taken literally (atan, acos, asin per view-cone test; acos, asin
// per back-face test: what the library did before its trigonometry-free tests), or with the
// library's tests through the same visit() hook, so the two differ only in the tests.
template <bool Trig>
struct visit_culling_policy : point_octree_policy {
  template <class H, class State>
  [[nodiscard]] visit_result visit(const H& h, const typename H::node_id& n, const State&,
                                   const view& v, const traverse_options& o) const {
    const sphere s = h.bounding_sphere(n);
    const bool culled = Trig
                            ? test::outside_view_cone_trig(v, s) ||
                                  test::back_facing_trig(s, h.normal_cone(n), v.eye)
                            : outside_view_cone(v, s) || back_facing(s, h.normal_cone_cs(n), v.eye);
    if (culled) return {visit_result::verdict::cull, 0};
    const float size = screen_size(h, n, s, v, o);
    return {refine(h, n, size, o) ? visit_result::verdict::refine : visit_result::verdict::emit,
            size};
  }
};

// Traversal alone (LOD selection of §6: view-cone and normal-cone culling, the tilted screen
// area) on the same surface, from the sweep's distance (2.2 radii: everything in view) and from
// close up (0.9 radii: much of the surface outside the view cone or facing away).
template <class Policy>
void bm_select(benchmark::State& state) {
  static const auto t = build_point_octree(surface(1'000'000));
  using tree = std::decay_t<decltype(t)>;
  const double dist = static_cast<double>(state.range(1)) / 10;
  const view v(camera::orbit(t.origin(), 1.4, 30, 35, dist, 1, {1024, 1024}), t.origin());
  const traverse_options o{.tolerance_px = static_cast<float>(state.range(0)),
                           .backface_cull = true,
                           .cull_volume = traverse_options::volume::view_cone};
  traverse_stats st;
  for (auto _ : state) {
    counting_sink<tree::attrs> c;
    st = traverse(t, v, o, c, Policy{});
    benchmark::DoNotOptimize(c.splats);
  }
  state.counters["nodes/s"] =
      benchmark::Counter(static_cast<double>(st.visited) * static_cast<double>(state.iterations()),
                         benchmark::Counter::kIsRate);
  state.counters["visited"] = static_cast<double>(st.visited);
  state.counters["culled"] = static_cast<double>(st.culled_frustum + st.culled_backface);
}
void select_args(benchmark::internal::Benchmark* b) {
  b->ArgNames({"tau_px", "dist_x10"})->Unit(benchmark::kMillisecond);
  for (const int tau : {1, 16})
    for (const int dist : {22, 9}) b->Args({tau, dist});
}
BENCHMARK_TEMPLATE(bm_select, point_octree_policy)->Apply(select_args);
BENCHMARK_TEMPLATE(bm_select, visit_culling_policy<false>)->Apply(select_args);
BENCHMARK_TEMPLATE(bm_select, visit_culling_policy<true>)->Apply(select_args);

// How far the node ellipses drift when the same cloud lies far from the origin: the paper's
// world-coordinate homogeneous sums in float and double vs the stable merge (relative error of
// the ellipse axes against the at-origin build; max over nodes, and median).
void bm_covariance_drift(benchmark::State& state) {
  const auto method = static_cast<covariance_method>(state.range(0));
  const double offset = std::pow(10.0, static_cast<double>(state.range(1)));
  const auto cloud = sample_surface(make_demo_scene(16), 50000, 3);
  const point_octree_options ref_opt{.normal_bits = 0, .threads = 1};
  const auto ref = build_point_octree(point_set<with_normals>::from(cloud), ref_opt);
  point_cloud moved = cloud;
  moved.origin += vec3d(0.5, 0.4, 0.01) * offset;
  point_octree_options opt = ref_opt;
  opt.covariance = method;
  point_octree<point_octree_attributes(with_normals)> t;
  for (auto _ : state) t = build_point_octree(point_set<with_normals>::from(moved), opt);
  auto rel = test::ellipse_drifts(ref, t);
  std::sort(rel.begin(), rel.end());
  state.counters["max_rel_drift"] = rel.back();
  state.counters["median_rel_drift"] = rel[rel.size() / 2];
  // Ellipse area relative to the at-origin build (inflation when the axes lose their shape).
  double a0 = 0, a1 = 0;
  for (std::size_t i = 0; i < t.nodes().size(); ++i) {
    a0 += ref.nodes()[i].axis_u.norm() * ref.nodes()[i].axis_v.norm();
    a1 += t.nodes()[i].axis_u.norm() * t.nodes()[i].axis_v.norm();
  }
  state.counters["area_ratio"] = a1 / a0;
}
BENCHMARK(bm_covariance_drift)
    ->ArgNames({"method", "log10_offset"})
    ->ArgsProduct({{0, 1, 2}, {0, 3, 5, 6, 7}})
    ->Iterations(1)
    ->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
