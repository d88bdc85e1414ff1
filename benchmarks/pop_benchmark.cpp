// POP (Chen & Nguyen 2001) benchmarks: build throughput (§4: 52 s for the 1.09 M-triangle
// Buddha on an 800 MHz P3), the paper's inner spheres against exact ones (radius ratio and what
// it costs in primitives drawn), points and triangles drawn against the splat-size threshold
// with image error and time (Figure 6), eye-space-z vs exact splat size (§3.3), texture-mapped
// leaves with the hybrid antialiasing (Figure 5), frame coherence (§3.2) and storage (§3.5).
// docs/pop.md quotes these numbers.
#include <benchmark/benchmark.h>

#include <cmath>
#include <filesystem>
#include <map>
#include <tuple>

#include "pbr_lod/builders/pop.hpp"
#include "pbr_lod/builders/pop_flags.hpp"
#include "pbr_lod/io/read.hpp"
#include "pbr_lod/raster/metrics.hpp"
#include "pbr_lod/raster/rasterizer.hpp"
#include "pbr_lod/raster/reference.hpp"
#include "support/data.hpp"
#include "support/spot_cow.hpp"

namespace {
using namespace pbr_lod;
using tree = pop_tree<with_normals>;

/// A (n+1)² vertex grid on a wavy height field, 2n² triangles (n = 1000: 2 M triangles).
triangle_mesh wavy_grid(int n) {
  triangle_mesh m;
  m.vertices.positions.reserve(static_cast<std::size_t>(n + 1) * static_cast<std::size_t>(n + 1));
  for (int y = 0; y <= n; ++y)
    for (int x = 0; x <= n; ++x) {
      const float fx = static_cast<float>(x) / static_cast<float>(n),
                  fy = static_cast<float>(y) / static_cast<float>(n);
      m.vertices.positions.emplace_back(fx, fy, 0.05f * std::sin(20 * fx) * std::cos(17 * fy));
    }
  const auto id = [n](int x, int y) { return static_cast<std::uint32_t>(y * (n + 1) + x); };
  m.faces.reserve(2 * static_cast<std::size_t>(n) * static_cast<std::size_t>(n));
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      m.faces.push_back({id(x, y), id(x + 1, y), id(x + 1, y + 1)});
      m.faces.push_back({id(x, y), id(x + 1, y + 1), id(x, y + 1)});
    }
  return m;
}

const triangle_mesh& mesh(int which) {
  static std::map<int, triangle_mesh> cache;
  auto it = cache.find(which);
  if (it == cache.end()) {
    triangle_mesh m = which == 0   ? read_mesh(test::data_file("bun_zipper.ply"))
                      : which == 1 ? read_mesh(test::data_file("happy_vrip_res3.ply"))
                                   : wavy_grid(1000);
    it = cache.emplace(which, std::move(m)).first;
  }
  return it->second;
}
const char* mesh_name(int which) {
  return which == 0 ? "bunny" : which == 1 ? "buddha_res3" : "grid_2M";
}

/// quantised: QSplat-style node records (the default); false: float spheres and cones.
const tree& built(int which, pop_sphere_rule rule, bool quantised = true) {
  static std::map<std::tuple<int, int, bool>, tree> cache;
  const auto key = std::make_tuple(which, static_cast<int>(rule), quantised);
  auto it = cache.find(key);
  if (it == cache.end())
    it = cache
             .emplace(key, build_pop<with_normals>(mesh(which),
                                                   {.spheres = rule, .quantise_nodes = quantised}))
             .first;
  return it->second;
}

camera model_camera(const tree& t, double az, double dist, int size) {
  const sphere b = bounding_sphere_about_box_centre(t.positions());
  return camera::orbit(t.origin() + b.centre.cast<double>(), b.radius, az, 20, dist, 1,
                       {size, size});
}

/// The scans at the tool's default view (30°, 20°, 3 radii) at 512²; the 2 M-triangle grid
/// filling a 1024² frame (≈ 0.5 triangles per pixel, like the paper's Buddha on screen).
camera sweep_camera(int which, const tree& t) {
  return which == 2 ? model_camera(t, 30, 1.6, 1024) : model_camera(t, 30, 3, 512);
}

// ---- build (§4) -----------------------------------------------------------------------------
void bm_build(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const auto rule = static_cast<pop_sphere_rule>(state.range(1));
  const auto adjacency = static_cast<pop_adjacency>(state.range(2));
  const auto& m = mesh(which);
  state.SetLabel(mesh_name(which));
  pop_build_stats st;
  for (auto _ : state) {
    const auto t =
        build_pop<with_normals>(m, {.spheres = rule, .threads = 2, .adjacency = adjacency});
    st = t.stats();
    benchmark::DoNotOptimize(t.nodes().data());
  }
  state.counters["triangles"] = static_cast<double>(st.triangles);
  state.counters["Mtri/s"] = benchmark::Counter(
      1e-6 * static_cast<double>(st.triangles) * static_cast<double>(state.iterations()),
      benchmark::Counter::kIsRate);
  state.counters["prepare_s"] = st.prepare_seconds;
  state.counters["adjacency_s"] = st.adjacency_seconds;
  state.counters["tree_s"] = st.tree_seconds;
  state.counters["leaves/vertex"] =
      static_cast<double>(st.leaves) / static_cast<double>(st.vertices);
  state.counters["tri/leaf"] = static_cast<double>(st.triangles) / static_cast<double>(st.leaves);
  state.counters["nodes"] = static_cast<double>(st.nodes);
  state.counters["isolated"] = static_cast<double>(st.isolated_faces);
  state.counters["B/vertex"] = st.bytes_per_vertex;
  state.counters["B/triangle"] = st.bytes_per_triangle;
}
BENCHMARK(bm_build)
    ->ArgsProduct({{0, 1, 2}, {0, 1}, {0, 1}})
    ->ArgNames({"mesh", "exact", "openmesh"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// ---- paper vs exact spheres (§3.1 and beyond) -----------------------------------------------
// Same tree shape under both rules (the split uses the leaves' corner means), so radii compare
// node by node. Primitives drawn at a 1-pixel threshold over a fixed view.
void bm_sphere_ratio(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const auto& p = built(which, pop_sphere_rule::paper, false);
  const auto& e = built(which, pop_sphere_rule::exact, false);
  state.SetLabel(mesh_name(which));
  double sum = 0, worst = 0, sum_inner = 0, worst_inner = 0;
  std::size_t n_inner = 0;
  for (std::uint32_t i = 0; i < p.nodes().size(); ++i) {
    const double q = p.at(i).radius / std::max(e.at(i).radius, 1e-30f);
    sum += q;
    worst = std::max(worst, q);
    if (!p.is_leaf(i)) {
      sum_inner += q;
      worst_inner = std::max(worst_inner, q);
      ++n_inner;
    }
  }
  const view v(sweep_camera(which, p), p.origin());
  const traverse_options o{.tolerance_px = static_cast<float>(state.range(1)) / 10,
                           .metric = projection_metric::eye_z,
                           .backface_cull = true};
  traverse_stats sp, se;
  for (auto _ : state) {
    counting_sink<with_normals> a, b;
    sp = traverse(p, v, o, a, pop_policy{});
    se = traverse(e, v, o, b, pop_policy{});
  }
  state.counters["ratio_mean"] = sum / static_cast<double>(p.nodes().size());
  state.counters["ratio_worst"] = worst;
  state.counters["inner_ratio_mean"] =
      sum_inner / static_cast<double>(std::max<std::size_t>(1, n_inner));
  state.counters["inner_ratio_worst"] = worst_inner;
  state.counters["contained_inner"] = static_cast<double>(p.stats().contained_inner) /
                                      static_cast<double>(std::max<std::size_t>(1, n_inner));
  state.counters["paper_pts"] = static_cast<double>(sp.points);
  state.counters["paper_tris"] = static_cast<double>(sp.triangles);
  state.counters["exact_pts"] = static_cast<double>(se.points);
  state.counters["exact_tris"] = static_cast<double>(se.triangles);
  state.counters["paper_visited"] = static_cast<double>(sp.visited);
  state.counters["exact_visited"] = static_cast<double>(se.visited);
}
BENCHMARK(bm_sphere_ratio)
    ->ArgsProduct({{0, 1, 2}, {10, 34}})
    ->ArgNames({"mesh", "tol_x10"})
    ->Unit(benchmark::kMillisecond);

// ---- QSplat-style quantised node records (§3.5) vs float ----------------------------------
// Same tree shape and exact spheres before quantisation: radius ratio quantised / float per
// node, and what the enlarged spheres cost at a threshold (primitives drawn, PSNR against every
// triangle, same view as the sweep, the paper's mode 0).
void bm_quantised(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const float tol = static_cast<float>(state.range(1)) / 10;
  const auto& q = built(which, pop_sphere_rule::paper, true);
  const auto& f = built(which, pop_sphere_rule::paper, false);
  state.SetLabel(mesh_name(which));
  double sum = 0, worst = 0;
  for (std::uint32_t i = 0; i < q.nodes().size(); ++i) {
    const double r = q.at(i).radius / std::max(f.at(i).radius, 1e-30f);
    sum += r;
    worst = std::max(worst, r);
  }
  const camera cam = sweep_camera(which, f);
  const view v(cam, f.origin());
  const render_options ro{.fx = {.shading = true, .colour = false}};
  static std::map<int, image> refs;
  if (!refs.count(which)) refs.emplace(which, render_reference(mesh(which), cam, ro));
  const traverse_options o{
      .tolerance_px = tol, .metric = projection_metric::eye_z, .backface_cull = true};
  traverse_stats sq, sf;
  image iq, iff;
  for (auto _ : state) {
    iq = render_direct<with_normals>(v, ro,
                                     [&](auto& s) { sq = traverse(q, v, o, s, pop_policy{}); });
    iff = render_direct<with_normals>(v, ro,
                                      [&](auto& s) { sf = traverse(f, v, o, s, pop_policy{}); });
  }
  state.counters["radius_ratio_mean"] = sum / static_cast<double>(q.nodes().size());
  state.counters["radius_ratio_worst"] = worst;
  state.counters["q_pts"] = static_cast<double>(sq.points);
  state.counters["q_tris"] = static_cast<double>(sq.triangles);
  state.counters["f_pts"] = static_cast<double>(sf.points);
  state.counters["f_tris"] = static_cast<double>(sf.triangles);
  state.counters["q_culled_bf"] = static_cast<double>(sq.culled_backface);
  state.counters["f_culled_bf"] = static_cast<double>(sf.culled_backface);
  state.counters["q_psnr"] = compare_images(refs.at(which), iq).psnr;
  state.counters["f_psnr"] = compare_images(refs.at(which), iff).psnr;
  state.counters["q_B/vertex"] = q.stats().bytes_per_vertex;
  state.counters["f_B/vertex"] = f.stats().bytes_per_vertex;
  state.counters["q_B/triangle"] = q.stats().bytes_per_triangle;
  state.counters["f_B/triangle"] = f.stats().bytes_per_triangle;
  state.counters["q_node_share"] =
      static_cast<double>(q.stats().node_file_bytes) / static_cast<double>(q.stats().file_bytes);
  state.counters["q_face_share"] =
      static_cast<double>(q.stats().face_file_bytes) / static_cast<double>(q.stats().file_bytes);
  state.counters["q_vertex_share"] =
      static_cast<double>(q.stats().vertex_file_bytes) / static_cast<double>(q.stats().file_bytes);
}
BENCHMARK(bm_quantised)
    ->ArgsProduct({{0, 1, 2}, {10, 34}})
    ->ArgNames({"mesh", "tol_x10"})
    ->Unit(benchmark::kMillisecond);

// ---- threshold sweep (Figure 6; §3.3 metric; §3.4 hole filling) -----------------------------
// Views: sweep_camera; the reference is every triangle. mode 0: simplified splatting with the
// eye-space-z splat size and back-face culling (the paper); 1: the same with the exact size; 2:
// visibility splatting (one-pixel points) + the rasteriser's hole filling, filter radius =
// threshold; 3: mode 0 without back-face culling; 4: mode 2 with §3.4's first pass (each point
// also drawn as a full-size occluder; pop_point_mode::visibility_two_pass).
void bm_threshold(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const float tol = static_cast<float>(state.range(1)) / 10;
  const int mode = static_cast<int>(state.range(2));
  const auto& t = built(which, pop_sphere_rule::paper);
  state.SetLabel(mesh_name(which));
  const camera cam = sweep_camera(which, t);
  const view v(cam, t.origin());
  render_options ro{
      .fx = {.shading = true, .colour = false, .hole_filling = mode == 2 || mode == 4}};
  ro.hole_filling_radius = std::max(1, static_cast<int>(std::ceil(tol)));
  static std::map<int, image> refs;
  if (!refs.count(which)) {
    render_options rr{.fx = {.shading = true, .colour = false}};
    refs.emplace(which, render_reference(mesh(which), cam, rr));
  }
  const traverse_options o{
      .tolerance_px = tol,
      .metric = mode == 1 ? projection_metric::exact : projection_metric::eye_z,
      .backface_cull = mode != 3};
  pop_policy pol;
  pol.points = mode == 2   ? pop_point_mode::visibility
               : mode == 4 ? pop_point_mode::visibility_two_pass
                           : pop_point_mode::simplified;
  traverse_stats st;
  image img;
  for (auto _ : state) {
    img = render_direct<with_normals>(v, ro, [&](auto& s) { st = traverse(t, v, o, s, pol); });
    benchmark::DoNotOptimize(img.colour.data());
  }
  const image_error err = compare_images(refs.at(which), img);
  state.counters["points"] = static_cast<double>(st.points);
  state.counters["triangles"] = static_cast<double>(st.triangles);
  state.counters["visited"] = static_cast<double>(st.visited);
  state.counters["psnr_db"] = err.psnr;
  state.counters["holes"] = err.hole_fraction;
}
BENCHMARK(bm_threshold)
    ->ArgsProduct({{0, 1, 2}, {10, 20, 34, 50}, {0, 1, 2, 3, 4}})
    ->ArgNames({"mesh", "tol_x10", "mode"})
    ->Unit(benchmark::kMillisecond);

// The full mesh through the same rasteriser: the time every threshold is compared with.
void bm_reference(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const auto& t = built(which, pop_sphere_rule::paper);
  state.SetLabel(mesh_name(which));
  const camera cam = sweep_camera(which, t);
  const render_options rr{.fx = {.shading = true, .colour = false}};
  for (auto _ : state) {
    const image img = render_reference(mesh(which), cam, rr);
    benchmark::DoNotOptimize(img.colour.data());
  }
  state.counters["triangles"] = static_cast<double>(mesh(which).faces.size());
}
BENCHMARK(bm_reference)->ArgNames({"mesh"})->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

// ---- texture-mapped leaves and hybrid antialiasing (Figure 5, §3.4) --------------------------
// The textured Spot cow at 256², colour only, at `dist` radii. mode 0: 1 px threshold, simplified
// splatting (5b); 1: 2 px, visibility splatting with its first pass + image reconstruction of
// radius 2 (5a). ss: render_options::supersample (the paper's "supersampling as in Surfel"), the
// same cut drawn at ss × ss and box-filtered. Error against the full mesh, every triangle
// texture-mapped, at 4 × 4 supersampling.
void bm_textured(benchmark::State& state) {
  const auto& c = test::spot_cow::get();
  const double dist = static_cast<double>(state.range(0)) / 10;
  const int mode = static_cast<int>(state.range(1));
  const int ss = static_cast<int>(state.range(2));
  state.SetLabel("cow");
  render_options ro{.fx = {.shading = false, .colour = true}};
  static std::map<long, image> refs;
  if (!refs.count(state.range(0))) refs.emplace(state.range(0), c.reference(dist, 256, 4, ro));
  ro.supersample = ss;
  ro.fx.hole_filling = mode == 1;
  ro.hole_filling_radius = 2;
  pop_policy pol;
  pol.points = mode == 1 ? pop_point_mode::visibility_two_pass : pop_point_mode::simplified;
  const traverse_options o{.tolerance_px = (mode == 1 ? 2.0f : 1.0f) * static_cast<float>(ss),
                           .metric = projection_metric::eye_z};
  const view v(c.cam(dist, 256), c.tree.origin());
  traverse_stats st;
  image img;
  for (auto _ : state) {
    img = render<with_normals_colours>(
        v, ro, [&](auto& s, const view& dv) { st = traverse(c.tree, dv, o, s, pol); });
    benchmark::DoNotOptimize(img.colour.data());
  }
  state.counters["points"] = static_cast<double>(st.points);
  state.counters["triangles"] = static_cast<double>(st.triangles);
  state.counters["psnr_db"] = compare_images(refs.at(state.range(0)), img).psnr;
}
BENCHMARK(bm_textured)
    ->ArgsProduct({{12, 20, 120, 240}, {0, 1}, {1, 2, 4}})
    ->ArgNames({"dist_x10", "mode", "ss"})
    ->Unit(benchmark::kMillisecond);

// ---- frame coherence (§3.2) -----------------------------------------------------------------
// 48 frames orbiting and zooming; nodes evaluated per frame: coherent 0 = plain traverse(),
// 1 = the kept cut (pop_coherent_traversal), 2 = the paper's two flags (pop_flag_traversal).
void bm_coherence(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const int mode = static_cast<int>(state.range(1));
  const float tol = static_cast<float>(state.range(2)) / 10;
  const auto& t = built(which, pop_sphere_rule::paper);
  state.SetLabel(mesh_name(which));
  std::vector<view> path;
  for (int f = 0; f < 48; ++f)
    path.emplace_back(model_camera(t, 2.0 * f, 2.0 + 4.0 * f / 47.0, 1024), t.origin());
  const traverse_options o{
      .tolerance_px = tol, .metric = projection_metric::eye_z, .backface_cull = true};
  std::size_t visited = 0, drawn = 0;
  for (auto _ : state) {
    visited = drawn = 0;
    pop_coherent_traversal<with_normals> coh(t);
    pop_flag_traversal<with_normals> flags(t);
    for (const auto& v : path) {
      counting_sink<with_normals> s;
      const traverse_stats st = mode == 1   ? coh.frame(v, o, s)
                                : mode == 2 ? flags.frame(v, o, s)
                                            : traverse(t, v, o, s, pop_policy{});
      visited += st.visited;
      drawn += st.emitted_nodes + st.emitted_leaves;
    }
  }
  state.counters["visited/frame"] = static_cast<double>(visited) / 48;
  state.counters["drawn/frame"] = static_cast<double>(drawn) / 48;
}
BENCHMARK(bm_coherence)
    ->ArgsProduct({{0, 1}, {0, 1, 2}, {10, 50}})
    ->ArgNames({"mesh", "coherent", "tol_x10"})
    ->Unit(benchmark::kMillisecond);

// ---- storage (§3.5) -------------------------------------------------------------------------
void bm_save_load(benchmark::State& state) {
  const int which = static_cast<int>(state.range(0));
  const auto& t = built(which, pop_sphere_rule::paper);
  state.SetLabel(mesh_name(which));
  const auto path = (std::filesystem::temp_directory_path() / "pbr_lod_pop_bench.lod").string();
  for (auto _ : state) {
    t.save(path);
    const tree back = tree::load(path);
    benchmark::DoNotOptimize(back.nodes().data());
  }
  std::filesystem::remove(path);
  const auto& st = t.stats();
  state.counters["B/vertex"] = st.bytes_per_vertex;
  state.counters["B/triangle"] = st.bytes_per_triangle;
  state.counters["nodes/vertex"] = static_cast<double>(st.nodes) / static_cast<double>(st.vertices);
  state.counters["MB"] = static_cast<double>(st.file_bytes) / 1e6;
}
BENCHMARK(bm_save_load)->ArgNames({"mesh"})->Arg(0)->Arg(1)->Arg(2)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
